"""Per-run trace of the docking tracker started from the stand camera cascade (issue 11, session 13).

``python bench/_docking_trace.py [--seeds 2] [--set KEY=VALUE ...] [--tag NAME] [--held-out]`` runs the stand
cascade start of ``bench/docking.py --diagnose`` (the same approaches, stand rules and rows every frame) with
``DockingTracker`` driven frame by frame, and records per run: the frame of the cascade's first aircraft row and
of the start; the start box against the truth (box IoU with the true axis-aligned box, polygon IoU, log of its
w/h over the true bounding box's, the true rotation); every restart (re-acquisition while lost or the
override) with its frame, kind and polygon IoU; frames declared lost; the start re-fit's counts; the polygon IoU
by phase and the frames under 0.5. Writes results/docking_trace_<tag>.{json,md}. Evaluation only: nothing in
the tracker reads it.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import docking as bench  # noqa: E402


#: Frames after the start over which the trace reports the median errors.
SEGMENTS = ((0, 5), (5, 15), (15, 40), (40, 10000))


def trace_run(seq: dict, overrides: dict, seed: int) -> dict:
    """One stand-cascade-started run, frame by frame (``bench.run_ours``'s loop with the events kept)."""
    from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir  # noqa: PLC0415
    from aircraft_docking_tracker.docking import affine_group as ag  # noqa: PLC0415
    from aircraft_docking_tracker.docking.tracker import LOST, DockingConfig, DockingTracker  # noqa: PLC0415
    from aircraft_docking_tracker.evaluation.sot_metrics import polygon_iou, score_sequence  # noqa: PLC0415
    from aircraft_docking_tracker.geometry import box_iou  # noqa: PLC0415

    stand = load_yaml_parameters(package_config_dir() / "stand_camera.yaml", "docking_tracker")
    config = DockingConfig(**{**stand, **overrides, "seed": seed})
    tracker = DockingTracker(config)
    tables = bench.stand_detections(seq)
    gt_q, gt_b = seq["gt_quads"], seq["gt_boxes"]
    n = len(seq["files"])
    quads = np.full((n, 4, 2), np.nan)
    first_row, events, lost_frames, counts = None, [], 0, {}
    filt = None
    for i, path in enumerate(seq["files"]):
        frame = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        table = tables[i]
        if first_row is None and len(table) and (config.detection_class < 0 or
                                                 (table["class_id"] == config.detection_class).any()):
            first_row = i
        before = tracker.state
        r = tracker.step(frame, table)
        if tracker.filter is not filt:              # a (re)start: collect the old filter's start counts
            if filt is not None:
                for k, v in getattr(filt, "start_counts", {}).items():
                    counts[k] = counts.get(k, 0) + v
            filt = tracker.filter
        if r.started:
            box = ag.to_box(r.matrix)
            true_u = np.linalg.norm(gt_q[i][1] - gt_q[i][0])
            true_v = np.linalg.norm(gt_q[i][3] - gt_q[i][0])
            rot = np.rad2deg(np.arctan2(*(gt_q[i][1] - gt_q[i][0])[::-1]))
            events.append({"frame": i, "kind": {2: "start", 1: "re-acquired", 0: "override"}[before],
                           "box_iou": float(box_iou(box, gt_b[i])),
                           "poly_iou": float(polygon_iou(r.quad[None], gt_q[i][None])[0]),
                           "log_aspect_vs_bbox": float(np.log((box[2] / box[3]) / (gt_b[i][2] / gt_b[i][3]))),
                           "log_area_vs_bbox": float(np.log(box[2] * box[3] / (gt_b[i][2] * gt_b[i][3]))),
                           "log_area_vs_poly": float(np.log(box[2] * box[3] / (true_u * true_v))),
                           "true_rotation_deg": float(rot)})
        if r.quad is not None:
            quads[i] = r.quad
        if r.state == LOST:
            lost_frames += 1
    for k, v in getattr(filt, "start_counts", {}).items():
        counts[k] = counts.get(k, 0) + v
    ok = np.isfinite(quads).all(axis=(1, 2))
    iou = np.zeros(n)
    iou[ok] = polygon_iou(quads[ok], gt_q[ok])
    auc = score_sequence(quads, gt_q)["success_auc"]
    started = events[0]["frame"] if events else None
    errors = bench.frame_errors(quads, gt_q)
    segments = {}
    for lo, hi in SEGMENTS:                     # frames after the start: median signed errors
        if started is None or started + lo >= n:
            continue
        part = slice(started + lo, min(started + hi, n))
        segments[f"{lo}-{hi}"] = {"iou": float(iou[part].mean()),
                                  **{k: float(np.nanmedian(errors[k][part])) for k in ("log_scale", "log_aspect")},
                                  "abs_rotation_deg": float(np.nanmedian(np.abs(errors["rotation_deg"][part])))}
    after = iou[started:] if started is not None else iou[:0]
    return {"scene": seq["name"], "seed": seed, "auc": float(auc), "frames": n, "first_row": first_row,
            "started": started, "events": events, "lost_frames": lost_frames, "start_counts": counts,
            "iou_phases": [float(iou[int(lo * n):max(int(hi * n), int(lo * n) + 1)].mean()) for lo, hi in bench.PHASES],
            "tracked_mean_iou": float(after.mean()) if len(after) else 0.0,
            "tracked_low_share": float((after < 0.5).mean()) if len(after) else 1.0,
            "segments": segments, "iou": [round(float(v), 3) for v in iou]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--set", action="append", default=[])
    parser.add_argument("--tag", default="")
    parser.add_argument("--held-out", action="store_true")
    parser.add_argument("--only", default="", help="comma-separated scene seeds (scratch)")
    args = parser.parse_args()
    overrides = bench.parse_overrides(args.set)
    sets = ({"150 f held out": (bench.REPORT_SEED0, 20, 150), "60 f held out": (bench.FAST_SEED0, 10, bench.FAST_FRAMES)}
            if args.held_out else {"150 f": (bench.TUNE_SEED0, 20, 150), "60 f": (bench.TUNE_FAST_SEED0, 10, bench.FAST_FRAMES)})
    only = {int(s) for s in args.only.split(",") if s}
    runs, started = [], time.time()
    with tempfile.TemporaryDirectory(prefix="bench_trace_") as tmp:
        for set_name, (seed0, count, frames) in sets.items():
            for seq in bench.docking_sequences(Path(tmp), count, frames, seed0):
                if only and int(seq["name"].split()[1]) not in only:
                    continue
                for s in range(args.seeds):
                    row = {"set": set_name, **trace_run(seq, overrides, s)}
                    runs.append(row)
                    ev = " ".join(f"{e['kind'][:3]}@{e['frame']}(b{e['box_iou']:.2f},p{e['poly_iou']:.2f})"
                                  for e in row["events"])
                    print(f"{row['scene']:44s} s{s} auc {row['auc']:.3f} row@{row['first_row']} lost {row['lost_frames']} "
                          f"{ev} refit {row['start_counts']} [{time.time() - started:.0f} s]", flush=True)
    stem = "docking_trace" + (f"_{args.tag}" if args.tag else "")
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / f"{stem}.json").write_text(json.dumps({"overrides": overrides, "held_out": args.held_out,
                                                               "runs": runs}, indent=1))
    md = [f"## Stand cascade start, per run ({'held out' if args.held_out else 'tuning'}, overrides "
          f"{json.dumps(overrides)})", ""]
    for set_name in sets:
        a = np.array([r["auc"] for r in runs if r["set"] == set_name])
        if len(a):
            md.append(f"- {set_name}: {len(a)} runs, {np.mean(a >= 0.5):.0%} >= 0.5, median {np.median(a):.3f}, "
                      f"mean {a.mean():.3f}, worst {a.min():.3f}")
    md += ["", "| run | AUC | first row | start | start box IoU / poly IoU / log area vs bbox | restarts | lost frames | "
           "re-fit | IoU by phase |", "|---|---:|---:|---:|---|---|---:|---|---|"]
    for r in runs:
        e0 = r["events"][0] if r["events"] else None
        md.append(f"| {r['scene']} s{r['seed']} | {r['auc']:.3f} | {r['first_row']} | {r['started']} | "
                  + (f"{e0['box_iou']:.2f} / {e0['poly_iou']:.2f} / {e0['log_area_vs_bbox']:+.2f}" if e0 else "-")
                  + " | " + ", ".join(f"{e['kind']}@{e['frame']} p{e['poly_iou']:.2f}" for e in r["events"][1:])
                  + f" | {r['lost_frames']} | {r['start_counts'].get('refitted', 0)} | "
                  + " ".join(f"{v:.2f}" for v in r["iou_phases"]) + " |")
    (HERE / "results" / f"{stem}.md").write_text("\n".join(md) + "\n")
    print("\n".join(md[:4]))


if __name__ == "__main__":
    main()
