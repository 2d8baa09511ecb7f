"""The README is part of the product: its parameter tables match the code, its commands exist."""
import re
import subprocess
import sys
from pathlib import Path

from setup_entry_points import console_scripts  # noqa: F401  (see below)

REPO = Path(__file__).resolve().parent.parent


def test_parameter_tables_are_current():
    result = subprocess.run([sys.executable, str(REPO / "tools" / "readme_tables.py"), "--check"])
    assert result.returncode == 0, "README parameter tables are stale: run python tools/readme_tables.py"


def test_readme_opens_with_the_two_commands():
    head = "\n".join((REPO / "README.md").read_text().splitlines()[:8])
    assert "make demo" in head and "make test" in head


def test_every_tool_named_in_the_readme_is_installed():
    text = (REPO / "README.md").read_text()
    scripts = console_scripts()
    named = set(re.findall(r"^\| `([a-z_]+) ", text, flags=re.M)) | set(re.findall(r"ros2 run aircraft_docking_tracker ([a-z_]+)", text))
    assert named and named <= set(scripts), sorted(named - set(scripts))
