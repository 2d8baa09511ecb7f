"""What holds the UAV camera's MOTA down (issue 12 item 3): the detector + association offline, scored as the demo.

    python bench/uav_tracking.py [--seeds tuning|held-out|demo|all] [--set NAME=key:value,...] [--busy 1.25 2]

Every frame of each scene (80 frames at 10 Hz, the demo's length and camera height) through the set-up's
detector (``config/uav_camera.yaml``, ``Detector.detect``) and the association core with the same file's
parameters, scored by ``evaluate.score_mot`` exactly as ``make demo`` scores its recording (every vehicle at
least ``hidden_below`` 30 % visible counted, border-cut ones included; hypotheses on hidden vehicles dropped).
Unlike the live demo no frame is skipped, so the figures are the set-up's, not the machine load's. ``--busy N``
adds the live case: a keep-newest detector input that takes N frame intervals a frame gets no detections for the
frames it cannot keep up with (1.25: one frame in five skipped, as ``make demo`` beside the stand camera; 2: every
other frame), scored without and with the association's ``output.fill_skipped_frames``.

MOTA = 1 - (misses + false positives + identity switches) / counted vehicles; each term is reported as its share
of the counted vehicles (MOTA points), the misses split by cause, each in the first class that fits:

* **detected, not published**: a detection (not one flagged ``low_confidence``) of that frame lies on the vehicle at IoU >= 0.5, yet no published
  track does (a tentative track not yet confirmed, a track elsewhere, or none): the association's share;
* **not detected**, by how the vehicle shows: **cut by the frame border**, **30-70 % visible** (partly hidden),
  **>= 70 % visible and uncut** (what the detector bench counts).

Seeds: tuning seeds (``UAV_TUNING_SEEDS``: 2000-2005 difficulty 1, 2100-2101 difficulty 2) to choose on; held-out
seeds as ``bench/uav_detector.py`` (3000-3007, 3100-3103) and the demo's seed 106, used for nothing else.
Detections are cached per detector parameters (the set-up file's and the overrides) and seed in
``out/uav_tracking_cache`` (delete it after changing a model file).
Writes ``bench/results/uav_tracking.json`` and ``.md``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy.special import expit

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir  # noqa: E402
from aircraft_docking_tracker.evaluation.detection_metrics import DetectionAccumulator  # noqa: E402
from aircraft_docking_tracker.evaluation.evaluate import (  # noqa: E402
    EvaluateConfig, hidden_rows, on_hidden_targets, score_mot)
from aircraft_docking_tracker.geometry import box_iou  # noqa: E402
from aircraft_docking_tracker.object_table import TRACK_DTYPE, confident_rows, low_confidence, table_boxes  # noqa: E402
from aircraft_docking_tracker.offline import build_processor  # noqa: E402
from aircraft_docking_tracker.scenarios.uav import (  # noqa: E402
    UAV_EVAL_SEEDS, UAV_SETUP_GROUND_RESOLUTION, UAV_TUNING_SEEDS, UavScene, UavSceneConfig, detection_truth)
from multi_target_tracker.association import CONFIRMED, TENTATIVE, clip_to_frame  # noqa: E402
from multi_target_tracker.association_node import tracks_to_table  # noqa: E402
from multi_target_tracker.train_cascade import truncated  # noqa: E402

SETUP = package_config_dir() / "uav_camera.yaml"
DEMO_SEED = 106
CACHE = REPO / "out" / "uav_tracking_cache"
ORACLE = " oracle boxes"
BUSY, FILLED = " busy ", " filled"      # --busy runs' names: a live keep-newest detector, its skipped frames filled
WIDE_BAND = 4.0   # low_confidence_band the detector runs with when a variant asks for a narrower one
SEEDS = {"tuning": [(UAV_TUNING_SEEDS.start + k, 1) for k in range(6)] + [(UAV_TUNING_SEEDS.start + 100 + k, 2)
                                                                           for k in range(2)],
         "held-out": [(UAV_EVAL_SEEDS.start + k, 1) for k in range(8)] + [(UAV_EVAL_SEEDS.start + 100 + k, 2)
                                                                           for k in range(4)],
         "demo": [(DEMO_SEED, 1)]}
MISS_CLASSES = ("detected, not published", "not detected, cut by the frame border", "not detected, 30-70 % visible",
                "not detected, >= 70 % visible and uncut")
FULLY_VISIBLE = 0.7
# misses (any class) with, in that frame: a track of any state (tentative, unpublished coasting too) on the
# vehicle at IoU >= 0.5; a published track whose box, clipped to the frame, is on it at IoU >= 0.5
NEAR_CLASSES = ("a track of any state on it", "a published track on it once clipped to the frame")
# misses by what the pipeline had on the vehicle in that frame, each in the first class that fits ("on it": IoU >= 0.5;
# groups: the detector's groups down to WIDE_BAND below its verifier threshold, rejected ones included)
CAUSES = ("track on it, tentative (not confirmed yet)", "track on it, coasting unpublished",
          "track on it, published but matched elsewhere", "detection on it, no track",
          "group on it rejected by the verifier", "mislocalised: only a detection at IoU 0.1-0.5",
          "mislocalised: only a rejected group at IoU 0.1-0.5", "no group at all")
# false positives (published tracks matched to no counted vehicle) by where they lie
FP_CAUSES = ("mislocalised on a counted vehicle (IoU 0.1-0.5), confirmed",
             "mislocalised on a counted vehicle (IoU 0.1-0.5), coasting", "on a hidden vehicle (IoU >= 0.1)",
             "elsewhere")



def scene(seed: int, difficulty: int):
    """The demo's UAV scene for ``seed``: (stamps [s], images, ground-truth tables)."""
    frames = list(UavScene(UavSceneConfig(frames=80, fps=10.0, width=640, height=480, difficulty=difficulty,
                                          ground_resolution=UAV_SETUP_GROUND_RESOLUTION), seed=seed).frames())
    return [f.stamp_ns * 1e-9 for f in frames], [f.image for f in frames], [f.ground_truth for f in frames]


def detections(name: str, detector_overrides: dict, seed: int, difficulty: int, images) -> list[np.ndarray]:
    """The set-up's detections of every frame (``DETECTION_DTYPE``-like tables), cached by set-up and seed.

    With ``low_confidence_band`` > 0 (the set-up's or an override) the frames are detected once with the band
    :data:`WIDE_BAND` and the rows flagged low-confidence below the asked band dropped: the same tables as detected
    with that band (containment keeps the better score first, so groups below a threshold never drop one above it),
    and variants of the band cost one detector run."""
    band = detector_overrides.get("low_confidence_band", load_yaml_parameters(SETUP, "detector").get(
        "low_confidence_band", 0.0))
    if 0 < band < WIDE_BAND:
        threshold = detector_overrides.get("verifier_threshold",
                                           load_yaml_parameters(SETUP, "detector")["verifier_threshold"])
        tables = detections(name, {**detector_overrides, "low_confidence_band": WIDE_BAND}, seed, difficulty, images)
        return [t[~low_confidence(t) | (t["score"] >= np.float32(expit(threshold - band)))] for t in tables]
    parameters = {**load_yaml_parameters(SETUP, "detector"), **detector_overrides}   # the association's do not matter
    key = hashlib.sha1(json.dumps(parameters, sort_keys=True).encode()).hexdigest()[:10]
    path = CACHE / f"{name}_{key}_{seed}_{difficulty}.npz"
    if path.exists():
        stored = np.load(path)
        return [stored[f"f{k}"] for k in range(len(images))]
    processor = build_processor("detector", SETUP, detector_overrides)
    tables = [processor.detector.detect(image) for image in images]
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **{f"f{k}": t for k, t in enumerate(tables)})
    return tables


def rejected_too(detector_overrides: dict, seed: int, difficulty: int, images, tables) -> list[np.ndarray]:
    """The detections with the groups the verifier rejected down to :data:`WIDE_BAND` below its threshold, flagged
    ``low_confidence`` (what :func:`miss_cause` reads); ``tables`` itself for a set-up without a band (no extra run)."""
    band = detector_overrides.get("low_confidence_band", load_yaml_parameters(SETUP, "detector").get(
        "low_confidence_band", 0.0))
    if band <= 0:
        return tables
    return detections("uav", {**detector_overrides, "low_confidence_band": WIDE_BAND}, seed, difficulty, images)


def oracle_boxes(truth, tables, floor: float) -> list[np.ndarray]:
    """The detections (flagged groups too) lying on a counted vehicle at IoU ``floor``-0.5 moved onto its box: the MOTA
    a perfect box regressor of the same groups would give (``--oracle-boxes``; a bound, never a set-up)."""
    out = []
    for t, table in zip(truth, tables):
        table, counted = table.copy(), t[~hidden_rows(t, EvaluateConfig())]
        if len(table) and len(counted):
            iou = box_iou(table_boxes(table)[:, None], table_boxes(counted)[None])
            fix = (iou.max(axis=1) >= floor) & (iou.max(axis=1) < 0.5)
            for field in ("x", "y", "w", "h"):
                table[field][fix] = counted[field][iou.argmax(axis=1)[fix]]
        out.append(table)
    return out


def track(stamps, tables, association_overrides: dict, processed=None, fill: bool = False) -> list[np.ndarray]:
    """Every frame's tracks (all states, ``TRACK_DTYPE``) from the association core with the set-up's parameters.

    ``processed``: the frames the detector got to (:func:`keep_newest`); the others have no tracks, or with ``fill``
    the tracks predicted to their stamp when a later frame was detected (what ``association_node`` publishes with
    ``output.fill_skipped_frames``: ``MultiTargetTracker.predicted`` before the next step)."""
    tracker = build_processor("association", SETUP, association_overrides).tracker
    out = []
    last = max(processed) if processed is not None and len(processed) else len(stamps) - 1
    for k, (stamp, table) in enumerate(zip(stamps, tables)):
        if processed is not None and k not in processed:
            tracks = tracker.predicted(stamp) if fill and k < last else None
            out.append(tracks_to_table(tracks) if tracks is not None else np.zeros(0, TRACK_DTYPE))
            continue
        result = tracker.step(stamp, table_boxes(table), table["score"], table["class_id"], low_confidence(table))
        out.append(tracks_to_table(result.tracks))
    return out


def keep_newest(frames: int, busy: float) -> set[int]:
    """The frames a live detector with a keep-newest input processes when each frame takes it ``busy`` frame intervals
    (frames arrive one interval apart; when it is free it takes the newest frame that has arrived, else waits)."""
    done, free, last = set(), 0.0, -1
    while last < frames - 1:
        newest = min(frames - 1, int(np.floor(free + 1e-9)))
        if newest <= last:                      # nothing new has arrived: wait for the next frame
            newest = last + 1
            free = float(newest)
        done.add(newest)
        last, free = newest, free + busy
    return done


def _best_iou(boxes: np.ndarray, box: np.ndarray) -> np.ndarray:
    return box_iou(boxes, box) if len(boxes) else np.zeros(0)


def miss_cause(box: np.ndarray, tracks: np.ndarray, groups: np.ndarray, published_states) -> str:
    """The :data:`CAUSES` class of a missed vehicle (``box`` (1, 4)) from that frame's tracks (every state) and
    ``groups`` (the detections with the rejected groups flagged ``low_confidence``), the first that fits."""
    on_track = _best_iou(table_boxes(tracks), box)
    if len(on_track) and on_track.max() >= 0.5:
        state = int(tracks["state"][on_track.argmax()])
        return CAUSES[0] if state == TENTATIVE else CAUSES[2] if state in published_states else CAUSES[1]
    iou, rejected = _best_iou(table_boxes(groups), box), low_confidence(groups)
    for cause, rows, floor in ((CAUSES[3], ~rejected, 0.5), (CAUSES[4], rejected, 0.5), (CAUSES[5], ~rejected, 0.1),
                               (CAUSES[6], rejected, 0.1)):
        if (iou[rows] >= floor).any():
            return cause
    return CAUSES[7]


def false_positive_causes(truth: np.ndarray, tracks: np.ndarray, matched: set, cfg: EvaluateConfig) -> dict:
    """:data:`FP_CAUSES` counts of one frame: published tracks not in ``matched`` (ids matched this frame), less
    those ``score_mot`` drops as sitting on a hidden vehicle (its rule: IoU >= the threshold, above any counted)."""
    out = dict.fromkeys(FP_CAUSES, 0)
    hyp = tracks[np.isin(tracks["state"], cfg.states())]
    hidden = hidden_rows(truth, cfg)
    hyp = hyp[~on_hidden_targets(hyp, truth, hidden, cfg)]
    for row in hyp[~np.isin(hyp["id"], list(matched))]:
        box = table_boxes(row[None])
        counted = _best_iou(table_boxes(truth[~hidden]), box).max(initial=0.0)
        on_hidden = _best_iou(table_boxes(truth[hidden]), box).max(initial=0.0)
        out[FP_CAUSES[0 if row["state"] == CONFIRMED else 1] if counted >= 0.1 else
            FP_CAUSES[2] if on_hidden >= 0.1 else FP_CAUSES[3]] += 1
    return out


def breakdown(truth, tables, tracks, size=(640, 480), groups=None) -> dict:
    """MOTA as the demo scores it and its terms, the misses split by :data:`MISS_CLASSES` and :data:`CAUSES`
    (``groups``: each frame's detections with the rejected groups flagged; default ``tables``), the false positives
    by :data:`FP_CAUSES`."""
    cfg = EvaluateConfig()
    groups = tables if groups is None else groups
    gt = {k: t for k, t in enumerate(truth)}
    mot = score_mot(gt, {k: t for k, t in enumerate(tracks)}, cfg)
    misses = dict.fromkeys(MISS_CLASSES, 0)
    causes = dict.fromkeys(CAUSES, 0)
    near = dict.fromkeys(NEAR_CLASSES, 0)
    after_first_match = 0
    matched: dict[int, set] = {}
    rows = {}
    for k, t in enumerate(truth):
        for i, row in enumerate(t):
            rows[(k + 1, int(row["id"]))] = (k, i)
    for gt_id, events in mot["timeline"].items():
        seen = False
        for frame, hyp in events:
            if hyp is not None:
                seen = True
                matched.setdefault(frame - 1, set()).add(hyp)
                continue
            after_first_match += seen
            k, i = rows[(frame, int(gt_id))]
            box = table_boxes(truth[k][i:i + 1])
            causes[miss_cause(box, tracks[k], groups[k], cfg.states())] += 1
            dets = table_boxes(confident_rows(tables[k]))
            everything = table_boxes(tracks[k])
            published = table_boxes(tracks[k][np.isin(tracks[k]["state"], cfg.states())])
            for name, boxes in zip(NEAR_CLASSES, (everything, clip_to_frame(published, *size)[0])):
                near[name] += int(len(boxes) > 0 and box_iou(boxes, box).max() >= cfg.iou_threshold)
            if len(dets) and box_iou(dets, box).max() >= cfg.iou_threshold:
                misses[MISS_CLASSES[0]] += 1
            elif truncated(box, size)[0]:
                misses[MISS_CLASSES[1]] += 1
            elif truth[k][i]["score"] < FULLY_VISIBLE:
                misses[MISS_CLASSES[2]] += 1
            else:
                misses[MISS_CLASSES[3]] += 1
    fps = dict.fromkeys(FP_CAUSES, 0)
    for k, t in enumerate(truth):
        for c, v in false_positive_causes(t, tracks[k], matched.get(k, set()), cfg).items():
            fps[c] += v
    if sum(fps.values()) != mot["num_false_positives"]:     # the split must add up to the metric's own count
        raise AssertionError(f"false positives {mot['num_false_positives']}, split {fps}")
    n = max(mot["num_objects"], 1)
    return {"mota": mot["mota"], "idf1": mot["idf1"], "counted": mot["num_objects"], "misses": mot["num_misses"],
            "false_positives": mot["num_false_positives"], "id_switches": mot["num_switches"],
            "miss_causes": misses, "misses_near": near, "miss_detail": causes, "fp_causes": fps,
            "misses_after_first_match": after_first_match,
            "mota_points": {"misses": mot["num_misses"] / n, "false positives": mot["num_false_positives"] / n,
                            "identity switches": mot["num_switches"] / n,
                            **{c: v / n for c, v in misses.items()}}}


def detector_counts(truth, tables, every: int = 4) -> DetectionAccumulator:
    """The detector alone as ``bench/uav_detector.py`` counts it (every 4th frame, vehicles >= 70 % visible; the
    detections proper, without those flagged ``low_confidence``)."""
    acc = DetectionAccumulator()
    for k, (t, table) in enumerate(zip(truth, tables)):
        if k % every == every // 2:
            boxes, ignore = detection_truth(t)
            table = confident_rows(table)
            acc.add_frame(table_boxes(table), table["score"], boxes, ignore)
    return acc


def pooled(per_seed: list[dict]) -> dict:
    counted = sum(r["counted"] for r in per_seed)
    terms = {k: sum(r[k] for r in per_seed) for k in ("misses", "false_positives", "id_switches")}
    causes = {c: sum(r["miss_causes"][c] for r in per_seed) for c in MISS_CLASSES}
    near = {c: sum(r["misses_near"][c] for r in per_seed) for c in NEAR_CLASSES}
    detail = {c: sum(r["miss_detail"][c] for r in per_seed) for c in CAUSES}
    fps = {c: sum(r["fp_causes"][c] for r in per_seed) for c in FP_CAUSES}
    mota = [r["mota"] for r in per_seed]
    tp, gt_boxes, fp, found = (sum(r["detector"][k] for r in per_seed)
                               for k in ("true_positives", "ground_truth", "false_positives", "detections"))
    return {"mota_pooled": 1.0 - sum(terms.values()) / max(counted, 1), "mota_mean": float(np.mean(mota)),
            "mota_worst": float(np.min(mota)), "counted": counted, **terms, "miss_causes": causes,
            "misses_near": near, "miss_detail": detail, "fp_causes": fps,
            "misses_after_first_match": sum(r["misses_after_first_match"] for r in per_seed),
            "detector": {"detection_rate": tp / max(gt_boxes, 1), "false_alarm_rate": fp / max(found, 1),
                         "seed_detection_mean": float(np.mean([r["detector"]["detection_rate"] for r in per_seed])),
                         "seed_detection_worst": float(np.min([r["detector"]["detection_rate"] for r in per_seed])),
                         "seed_false_alarms_mean": float(np.mean([r["detector"]["false_alarm_rate"] for r in per_seed])),
                         "seed_false_alarms_worst": float(np.max([r["detector"]["false_alarm_rate"] for r in per_seed]))},
            "mota_points": {**{k: v / max(counted, 1) for k, v in terms.items()},
                            **{c: v / max(counted, 1) for c, v in {**causes, **detail, **fps}.items()}}}


def parse_variants(specs: list[str]) -> dict:
    """``NAME=detector.key:value,association.key:value`` -> {name: (detector overrides, association overrides)}."""
    out = {"setup": ({}, {})}
    for spec in specs:
        name, _, body = spec.partition("=")
        det, assoc = {}, {}
        for item in filter(None, body.split(",")):
            key, _, value = item.partition(":")
            node, _, param = key.partition(".")
            (det if node == "detector" else assoc)[param] = json.loads(value)
        out[name] = (det, assoc)
    return out


def against_setup(setup_seeds: list[dict], seeds: list[dict]) -> str:
    """Scene by scene against the set-up (the same scenes in the same order): how many scenes a variant scores
    better and worse MOTA on, and its largest loss on one scene -- a pooled gain that one scene carries is not a
    gain across scenes (per-scene MOTA swings by +-0.02 for small changes)."""
    diff = np.array([r["mota"] for r in seeds]) - np.array([r["mota"] for r in setup_seeds])
    return f"{int((diff > 0).sum())} / {int((diff < 0).sum())}, {min(float(diff.min()), 0.0):+.3f}"


def markdown(results: dict) -> str:
    lines = ["# UAV camera: what holds MOTA down (bench/uav_tracking.py)", "",
             "Offline, every frame, scored as `make demo` scores (>= 30 % visible, border-cut included). "
             "MOTA points: each term / counted vehicles.", ""]
    for group, variants in results["groups"].items():
        lines += [f"## {group} seeds", "",
                  "| variant | MOTA pooled | mean / worst seed | seeds better / worse than setup, largest loss | "
                  "counted | misses | false pos. | ID sw. | "
                  + " | ".join(MISS_CLASSES) + " |", "|---" * (8 + len(MISS_CLASSES)) + "|"]
        for name, r in variants.items():
            p = r["pooled"]
            paired = against_setup(variants["setup"]["seeds"], r["seeds"]) if name != "setup" else ""
            lines.append(f"| {name} | {p['mota_pooled']:.3f} | {p['mota_mean']:.3f} / {p['mota_worst']:.3f} | "
                         f"{paired} | {p['counted']} | {p['misses']} ({p['mota_points']['misses']:.2f}) | "
                         f"{p['false_positives']} ({p['mota_points']['false_positives']:.2f}) | {p['id_switches']} | "
                         + " | ".join(f"{p['miss_causes'][c]} ({p['mota_points'][c]:.2f})" for c in MISS_CLASSES) + " |")
        lines += ["", "Detector alone as bench/uav_detector.py counts (every 4th frame, vehicles >= 70 % visible "
                  "counted): " + "; ".join(
                      f"{name} {r['pooled']['detector']['detection_rate']:.3f} / "
                      f"{r['pooled']['detector']['false_alarm_rate']:.3f} (per seed mean "
                      f"{r['pooled']['detector']['seed_detection_mean']:.3f} / "
                      f"{r['pooled']['detector']['seed_false_alarms_mean']:.3f}, worst "
                      f"{r['pooled']['detector']['seed_detection_worst']:.3f} / "
                      f"{r['pooled']['detector']['seed_false_alarms_worst']:.3f})" for name, r in variants.items())]
        lines += ["", "Misses by what the pipeline had on the vehicle (first that fits; MOTA points), and false "
                  "positives by where they lie:", "",
                  "| variant | " + " | ".join(CAUSES) + " | misses after the vehicle's first match | "
                  + " | ".join(f"false pos.: {c}" for c in FP_CAUSES) + " |",
                  "|---" * (2 + len(CAUSES) + len(FP_CAUSES)) + "|"]
        for name, r in variants.items():
            p = r["pooled"]
            lines.append(f"| {name} | " + " | ".join(f"{p['miss_detail'][c]} ({p['mota_points'][c]:.3f})"
                                                    for c in CAUSES)
                         + f" | {p['misses_after_first_match']} | "
                         + " | ".join(f"{p['fp_causes'][c]} ({p['mota_points'][c]:.3f})" for c in FP_CAUSES) + " |")
        lines += ["", "Misses with, in that frame: " + "; ".join(
            f"{name}: " + ", ".join(f"{c} {r['pooled']['misses_near'][c]}" for c in NEAR_CLASSES)
            for name, r in variants.items())]
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="all", choices=("tuning", "held-out", "demo", "all"))
    parser.add_argument("--quick", action="store_true", help="the demo's seed only (make bench --quick; about a minute)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=node.key:json,...",
                        help="a variant beside the set-up: detector.* / association.* parameter overrides")
    parser.add_argument("--out", default=str(HERE / "results" / "uav_tracking"), help="results path without suffix")
    parser.add_argument("--busy", type=float, nargs="*", default=[], metavar="INTERVALS",
                        help="also score each variant live: a keep-newest detector input taking INTERVALS frame "
                        "intervals a frame (the frames it cannot keep up with get no detections), without and with "
                        "the association's fill_skipped_frames (variant name + ' busy N' / ' busy N filled')")
    parser.add_argument("--oracle-boxes", type=float, default=0.0, metavar="IOU",
                        help="also score each variant with its detections at IoU IOU-0.5 on a counted vehicle moved "
                        "onto its box (a bound for the box regressor; variant name + ' oracle boxes')")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    variants = parse_variants(args.set)
    runs = {**variants, **({name + ORACLE: v for name, v in variants.items()} if args.oracle_boxes > 0 else {})}
    live = {}                           # run name -> (frame intervals a frame, filled) of the --busy runs
    for name, variant in variants.items():
        for busy in args.busy:
            for fill in (False, True):
                run = f"{name}{BUSY}{busy:g}{FILLED if fill else ''}"
                runs[run], live[run] = variant, (busy, fill)
    seeds = "demo" if args.quick else args.seeds
    groups = list(SEEDS) if seeds == "all" else [seeds]
    results = {"setup": SETUP.name, "variants": {k: {"detector": d, "association": a} for k, (d, a) in variants.items()},
               "groups": {}}
    for group in groups:
        results["groups"][group] = {name: {"seeds": []} for name in runs}
        for seed, difficulty in SEEDS[group]:
            stamps, images, truth = scene(seed, difficulty)
            for name, (det, assoc) in runs.items():
                tables = detections("uav", det, seed, difficulty, images)
                groups = rejected_too(det, seed, difficulty, images, tables)
                if name.endswith(ORACLE):
                    tables, groups = (oracle_boxes(truth, t, args.oracle_boxes) for t in (tables, groups))
                processed, fill = None, False
                if name in live:
                    busy, fill = live[name]
                    processed = keep_newest(len(images), busy)
                    tables, groups = ([t if k in processed else t[:0] for k, t in enumerate(ts)] for ts in (tables, groups))
                r = breakdown(truth, tables, track(stamps, tables, assoc, processed, fill), groups=groups)
                if processed is not None:
                    r["frames_detected"] = len(processed)
                d = detector_counts(truth, tables).summary()
                r["detector"] = {k: d[k] for k in ("detection_rate", "false_alarm_rate", "true_positives",
                                                   "ground_truth", "false_positives", "detections")}
                r.update(seed=seed, difficulty=difficulty)
                results["groups"][group][name]["seeds"].append(r)
                print(f"{group} seed {seed} {name}: MOTA {r['mota']:.3f} (misses {r['misses']}, false positives "
                      f"{r['false_positives']}, switches {r['id_switches']} of {r['counted']}) {r['miss_causes']}",
                      flush=True)
        for name in runs:
            results["groups"][group][name]["pooled"] = pooled(results["groups"][group][name]["seeds"])
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(results, indent=1))
    out.with_suffix(".md").write_text(markdown(results))
    print(markdown(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
