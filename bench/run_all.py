"""`make bench`: run every benchmark script, then gather their Markdown tables into bench/README.md.

Each bench/<area>.py writes bench/results/<area>.json and .md and plots under bench/plots/.
Usage: python bench/run_all.py [--quick] [--only area ...]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ORDER = ["foundation", "scenarios", "docking", "detector", "association", "pipeline", "multihost"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs (each area in a minute or two)")
    parser.add_argument("--only", nargs="+", default=None, help="areas to run (default: all)")
    parser.add_argument("--gather", action="store_true", help="run nothing: rebuild bench/README.md from the results")
    args = parser.parse_args()
    areas = [a for a in ORDER if (BENCH / f"{a}.py").exists()]
    areas += sorted(p.stem for p in BENCH.glob("*.py") if p.stem not in ORDER and p.stem != "run_all" and not p.stem.startswith("_"))
    if args.only:
        areas = [a for a in areas if a in args.only]
    failed = []
    for area in ([] if args.gather else areas):
        started = time.monotonic()
        print(f"=== bench/{area}.py", flush=True)
        cmd = [sys.executable, str(BENCH / f"{area}.py")] + (["--quick"] if args.quick else [])
        if subprocess.run(cmd).returncode != 0:
            failed.append(area)
        print(f"=== bench/{area}.py done in {time.monotonic() - started:.0f} s", flush=True)
    sections = ["# Benchmark results", "",
                "Made by `make bench` (`python bench/run_all.py`); each table compares methods side by "
                "side in one run on this machine (2 cores, shared). Plots are in `bench/plots/`.", ""]
    for area in ORDER + sorted(set(areas) - set(ORDER)):
        md = BENCH / "results" / f"{area}.md"
        if md.exists():
            sections += [md.read_text().strip(), ""]
    (BENCH / "README.md").write_text("\n".join(sections))
    if failed:
        print(f"benchmarks that failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
