"""Benchmark of the bounds on work (issue 16): what each bound saves, and what its check costs.

    python bench/hardening.py [--quick]

Side by side in one run:

* a detections message of 10,000 rows into the association processor, capped at the default
  ``node.max_detections`` (1000, best scores kept) against uncapped (10,000): time per frame and
  peak Python memory (tracemalloc), over frames 2..n (tracks exist), three seeds;
* a PNG decompression bomb (grey zeros, 6000x6000 = 36 MP in some ten kB): refused from its
  header against decoded by ``cv2.imdecode`` (what the node did before), time and peak RSS growth;
* the header checks on ordinary frames (1280x720 JPEG and PNG): their time against the decode's.

Writes ``bench/results/hardening.json`` and ``.md``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import tracemalloc
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from aircraft_docking_tracker.io.bag import ns_to_stamp  # noqa: E402
from aircraft_docking_tracker.images import _check_png_chunks, compressed_dimensions  # noqa: E402
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, table_to_cloud  # noqa: E402
from aircraft_docking_tracker.ros.processing import ProcessingStats, process_guarded  # noqa: E402
from aircraft_docking_tracker.scenarios.faults import png_bomb  # noqa: E402
from multi_target_tracker.association_node import AssociationNodeConfig, AssociationProcessor  # noqa: E402


def detections(n: int, k: int, rng) -> object:
    from std_msgs.msg import Header  # noqa: PLC0415

    table = np.zeros(n, DETECTION_DTYPE)
    table["x"], table["y"] = rng.uniform(0, 4000, n), rng.uniform(0, 3000, n)
    table["w"] = table["h"] = 24
    table["score"] = rng.uniform(0, 1, n)
    return table_to_cloud(table, Header(stamp=ns_to_stamp(int(1e9 + k * 1e8))))


def association_case(limit: int, frames: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    messages = [detections(10000, k, rng) for k in range(frames)]
    processor = AssociationProcessor(node=AssociationNodeConfig(max_detections=limit))
    stats = ProcessingStats()
    processor.on_rejected = stats.reject
    process_guarded(processor, "detections", messages[0], stats)      # frame 1: tracks start
    tracemalloc.start()
    started = time.perf_counter()
    for msg in messages[1:]:
        process_guarded(processor, "detections", msg, stats)
    per_frame = (time.perf_counter() - started) / (frames - 1)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"limit": limit, "seed": seed, "s_per_frame": per_frame, "peak_mb": peak / 1e6,
            "tracks": int(processor.tracker.states.size)}




def rss_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024.0


def peak_since_reset_mb() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) / 1024.0


def reset_peak() -> None:
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def best_time(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        started = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - started)
    return best


def header_checks(data: bytes) -> None:
    kind, w, h = compressed_dimensions(data)
    if kind == "png":
        _check_png_chunks(data)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    frames = 3 if args.quick else 5
    seeds = (0, 1) if args.quick else (0, 1, 2)
    results: dict = {"association": [], "bomb": {}, "header_cost": []}

    for seed in seeds:
        for limit in (1000, 10000):
            results["association"].append(association_case(limit, frames, seed))
            print(results["association"][-1], flush=True)

    bomb = png_bomb(6000, 6000)
    reset_peak()
    base = rss_mb()
    started = time.perf_counter()
    header_checks(bomb)
    refuse_s = time.perf_counter() - started
    refuse_mb = peak_since_reset_mb() - base
    reset_peak()
    base = rss_mb()
    started = time.perf_counter()
    decoded = cv2.imdecode(np.frombuffer(bomb, np.uint8), cv2.IMREAD_UNCHANGED)
    decode_s = time.perf_counter() - started
    decode_mb = peak_since_reset_mb() - base
    del decoded
    results["bomb"] = {"file_kb": len(bomb) / 1e3, "refuse_s": refuse_s, "refuse_mb": refuse_mb,
                       "decode_s": decode_s, "decode_mb": decode_mb}
    print(results["bomb"], flush=True)

    rng = np.random.default_rng(3)
    frame = cv2.GaussianBlur(rng.integers(0, 256, (720, 1280, 3), dtype=np.uint8), (0, 0), 3)
    repeats = 5 if args.quick else 20
    for ext in (".jpg", ".png"):
        data = cv2.imencode(ext, frame)[1].tobytes()
        array = np.frombuffer(data, np.uint8)
        check = best_time(lambda: header_checks(data), repeats)
        decode = best_time(lambda: cv2.imdecode(array, cv2.IMREAD_UNCHANGED), repeats)
        results["header_cost"].append({"format": ext[1:], "check_ms": check * 1e3, "decode_ms": decode * 1e3})
        print(results["header_cost"][-1], flush=True)

    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / "hardening.json").write_text(json.dumps(results, indent=1))
    lines = ["## Hardening: bounds on work (issue 16)", "",
             f"A detections message of 10,000 rows into the association node's processor, frames 2-{frames} "
             f"(seeds {', '.join(map(str, seeds))}; mean and worst):", "",
             "| rows kept | s/frame mean | s/frame worst | peak MB mean | peak MB worst |", "|---|---|---|---|---|"]
    for limit in (1000, 10000):
        rows = [r for r in results["association"] if r["limit"] == limit]
        t = [r["s_per_frame"] for r in rows]
        m = [r["peak_mb"] for r in rows]
        label = f"{limit} (node.max_detections default)" if limit == 1000 else f"{limit} (no cap)"
        lines.append(f"| {label} | {np.mean(t):.2f} | {max(t):.2f} | {np.mean(m):.0f} | {max(m):.0f} |")
    b = results["bomb"]
    lines += ["", f"A {b['file_kb']:.0f} kB PNG that decodes to 6000x6000 (36 MP):", "",
              "| | time ms | peak RSS growth MB |", "|---|---|---|",
              f"| refused from its header (ours) | {b['refuse_s'] * 1e3:.2f} | {b['refuse_mb']:.0f} |",
              f"| cv2.imdecode (before) | {b['decode_s'] * 1e3:.0f} | {b['decode_mb']:.0f} |",
              "", "What the header checks cost on an ordinary 1280x720 frame (best of "
              f"{repeats}):", "", "| format | header check ms | decode ms | check / decode |", "|---|---|---|---|"]
    for r in results["header_cost"]:
        lines.append(f"| {r['format']} | {r['check_ms']:.3f} | {r['decode_ms']:.2f} | "
                     f"{100 * r['check_ms'] / r['decode_ms']:.2f} % |")
    (HERE / "results" / "hardening.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
