"""Scenario benchmark: what the synthetic scenes contain, how fast they are made, and metric sanity.

One run, side by side:
* docking scenes (several seeds, 640x480 and 1280x720): image growth, turn, frames with part of the
  aircraft hidden, weather, render frames/s, and the whole make_scenario bag (render + write) time;
* UAV scenes (several seeds, nadir and oblique): vehicles, box sizes, hidden episodes and the
  longest, crossings, entries/exits, render frames/s;
* evaluation sanity: synthesised detections at a set miss rate and clutter rate come out of
  ``evaluate`` with the detection and false-alarm rates those settings imply.

Writes bench/results/scenarios.json and .md.  ``--quick``: fewer seeds, 120 frames.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from aircraft_docking_tracker.evaluation.evaluate import evaluate_bags
from aircraft_docking_tracker.geometry import box_iou
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
from aircraft_docking_tracker.scenarios.make_scenario import write_docking_bag, write_uav_bag
from aircraft_docking_tracker.scenarios.uav import STATE_HIDDEN, UavScene, UavSceneConfig

RESULTS = Path(__file__).resolve().parent / "results"


def docking_stats(seed: int, frames: int, size=(640, 480)) -> dict:
    scene = DockingScene(DockingSceneConfig(width=size[0], height=size[1], frames=frames), seed)
    started = time.perf_counter()
    quads, occluded = [], []
    for f in scene.frames():
        quads.append(f.quad)
        occluded.append(f.occluded_fraction)
    seconds = time.perf_counter() - started
    q = np.array(quads)
    width = np.linalg.norm(q[:, 1] - q[:, 0], axis=1)
    angle = np.degrees(np.arctan2(q[:, 1, 1] - q[:, 0, 1], q[:, 1, 0] - q[:, 0, 0]))
    occluded = np.array(occluded)
    return {"seed": seed, "size": f"{size[0]}x{size[1]}", "weather": scene.weather, "occluder": scene.occluder,
            "growth": float(width[-1] / width[0]), "turn_deg": float(abs(angle[-1] - angle[0])),
            "frames_partly_hidden": int((occluded > 0.02).sum()), "max_hidden": float(occluded.max()),
            "render_fps": frames / seconds}


def uav_stats(seed: int, frames: int, view: str, difficulty: int) -> dict:
    scene = UavScene(UavSceneConfig(frames=frames, view=view, difficulty=difficulty), seed)
    started = time.perf_counter()
    tables = [f.ground_truth for f in scene.frames()]
    seconds = time.perf_counter() - started
    sizes = np.concatenate([np.maximum(t["w"], t["h"]) for t in tables if len(t)])
    spans, hidden_runs, episodes = {}, {}, 0
    crossings = set()
    for k, t in enumerate(tables):
        for r in t:
            a, b = spans.get(int(r["id"]), (k, k))
            spans[int(r["id"])] = (min(a, k), max(b, k))
            if r["state"] == STATE_HIDDEN:
                episodes += r["misses"] == 1
                hidden_runs[int(r["id"])] = max(hidden_runs.get(int(r["id"]), 0), int(r["misses"]))
        boxes = np.stack([t["x"], t["y"], t["w"], t["h"]], axis=1) if len(t) else np.zeros((0, 4))
        iou = box_iou(boxes[:, None], boxes[None])
        for i, j in zip(*np.nonzero(np.triu(iou, 1) > 0)):
            crossings.add((int(t["id"][i]), int(t["id"][j])))
    return {"seed": seed, "view": view, "difficulty": difficulty, "vehicles": scene.n_vehicles,
            "size_p5": float(np.percentile(sizes, 5)), "size_p50": float(np.median(sizes)),
            "size_p95": float(np.percentile(sizes, 95)), "hidden_episodes": int(episodes),
            "longest_hidden": max(hidden_runs.values(), default=0), "touching_pairs": len(crossings),
            "enter_or_leave": sum(1 for a, b in spans.values() if a > 0 or b < frames - 1),
            "render_fps": frames / seconds}


def bag_timing(tmp: Path, frames: int) -> dict:
    out = {}
    started = time.perf_counter()
    write_docking_bag(DockingScene(DockingSceneConfig(frames=frames), 1), tmp / "d.mcap", progress=False)
    out["docking_640x480"] = time.perf_counter() - started
    started = time.perf_counter()
    write_uav_bag(UavScene(UavSceneConfig(frames=frames), 1), tmp / "u.mcap", detections=True, progress=False)
    out["uav_640x480"] = time.perf_counter() - started
    return out


def detection_sanity(tmp: Path, frames: int) -> list[dict]:
    rows = []
    for miss, clutter in ((0.0, 0.0), (0.1, 0.0), (0.05, 1.0)):
        path = tmp / f"s{miss}_{clutter}.mcap"
        scene = UavScene(UavSceneConfig(frames=frames, difficulty=1), 2)
        write_uav_bag(scene, path, detections=True, miss_rate=miss, clutter_rate=clutter, jitter_px=1.0,
                      progress=False)
        d = evaluate_bags(path)["detection"]
        rows.append({"miss_rate": miss, "clutter_per_frame": clutter, "detection_rate": d["detection_rate"],
                     "false_alarm_rate": d["false_alarm_rate"], "average_precision": d["average_precision"],
                     "detections": d["detections"]})
    return rows


def markdown(result: dict) -> str:
    lines = ["## Scenarios: synthetic scenes and evaluation sanity", "",
             "Docking scenes (image growth and turn of the ground-truth quadrilateral, frames with > 2 % of "
             "the aircraft hidden):", "",
             "| seed | size | weather | occluder | growth | turn deg | frames partly hidden | max hidden | render fps |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in result["docking"]:
        lines.append(f"| {r['seed']} | {r['size']} | {r['weather']} | {r['occluder']} | {r['growth']:.1f}x | "
                     f"{r['turn_deg']:.0f} | {r['frames_partly_hidden']} | {r['max_hidden']:.0%} | {r['render_fps']:.0f} |")
    lines += ["", "UAV scenes (box size = max(w, h) in px; hidden = visible fraction < 0.3):", "",
              "| seed | view | difficulty | vehicles | size p5/p50/p95 | hidden episodes | longest hidden | "
              "touching pairs | enter/leave | render fps |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["uav"]:
        lines.append(f"| {r['seed']} | {r['view']} | {r['difficulty']} | {r['vehicles']} | {r['size_p5']:.0f}/"
                     f"{r['size_p50']:.0f}/{r['size_p95']:.0f} | {r['hidden_episodes']} | {r['longest_hidden']} | "
                     f"{r['touching_pairs']} | {r['enter_or_leave']} | {r['render_fps']:.0f} |")
    n = result["frames"]
    lines += ["", f"make_scenario bag, {n} frames 640x480 (render + write): docking "
              f"{result['bag_seconds']['docking_640x480']:.1f} s, uav with detections "
              f"{result['bag_seconds']['uav_640x480']:.1f} s.", "",
              "Evaluation sanity: synthesised detections (1 px jitter) scored by `evaluate` "
              "(expected: detection rate about 1 - miss rate, false alarms about clutter / detections):", "",
              "| miss rate | clutter / frame | detections | detection rate | false-alarm rate | AP |",
              "|---|---|---|---|---|---|"]
    for r in result["detection_sanity"]:
        lines.append(f"| {r['miss_rate']} | {r['clutter_per_frame']} | {r['detections']} | {r['detection_rate']:.3f} | "
                     f"{r['false_alarm_rate']:.3f} | {r['average_precision']:.3f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    frames = 120 if args.quick else 300
    seeds = [1, 2] if args.quick else [1, 2, 3, 4]
    result = {"frames": frames}
    result["docking"] = [docking_stats(s, frames) for s in seeds] + [docking_stats(seeds[0], frames, (1280, 720))]
    result["uav"] = [uav_stats(s, frames, view, d) for s in seeds for view, d in (("nadir", 2), ("oblique", 1))]
    with tempfile.TemporaryDirectory() as tmp:
        result["bag_seconds"] = bag_timing(Path(tmp), frames)
        result["detection_sanity"] = detection_sanity(Path(tmp), frames)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "scenarios.json").write_text(json.dumps(result, indent=1))
    (RESULTS / "scenarios.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
