"""Read setup.py's CONSOLE_SCRIPTS without running setup()."""
import ast
from pathlib import Path


def console_scripts() -> dict[str, str]:
    tree = ast.parse((Path(__file__).resolve().parent.parent / "setup.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "CONSOLE_SCRIPTS":
            return ast.literal_eval(node.value)
    raise AssertionError("setup.py has no CONSOLE_SCRIPTS")
