"""Write the README's parameter tables from the nodes' config dataclasses (one source of truth).

    python tools/readme_tables.py          # rewrite the section between the README markers
    python tools/readme_tables.py --check  # exit 1 when the README is out of date (a test runs this)
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from aircraft_docking_tracker.config import spec_of
from aircraft_docking_tracker.offline import NODE_MODULES, processor_spec

README = Path(__file__).resolve().parent.parent / "README.md"
BEGIN, END = "<!-- parameters:begin (tools/readme_tables.py) -->", "<!-- parameters:end -->"


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    return str(value).lower() if isinstance(value, bool) else str(value)


def _range(spec) -> str:
    if spec.choices is not None:
        return " \\| ".join(_fmt(c) for c in spec.choices)
    if spec.low is None and spec.high is None:
        return ""
    low = _fmt(spec.low) if spec.low is not None else "-∞"
    high = _fmt(spec.high) if spec.high is not None else "∞"
    return f"[{low}, {high}]"


def tables() -> str:
    lines = []
    for node in NODE_MODULES:
        spec = processor_spec(node)
        lines += [f"#### `{node}` (`config/{node}.yaml`)", "", "| parameter | default | range | meaning |",
                  "|---|---|---|---|"]
        for prefix, cls in spec.configs.items():
            defaults = cls()
            for f in dataclasses.fields(cls):
                s = spec_of(f)
                desc = s.description.replace("|", "\\|")
                lines.append(f"| `{prefix}{f.name}` | `{_fmt(getattr(defaults, f.name))}` | {_range(s)} | {desc} |")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def render(text: str) -> str:
    if BEGIN not in text or END not in text:
        raise SystemExit(f"README has no {BEGIN} ... {END} section")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{tables()}{END}{tail}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true")
    args = parser.parse_args()
    current = README.read_text()
    wanted = render(current)
    if args.check:
        return 0 if current == wanted else 1
    README.write_text(wanted)
    return 0


if __name__ == "__main__":
    sys.exit(main())
