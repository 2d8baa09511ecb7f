"""Benchmark of the detector (issues 5, 12): seed 003 Table 1's feature comparison on real drone tiles.

    python bench/detector.py [--quick] [--train] [--models DIR] [--no-folds | --folds-only | --folds-from JSON]

Generalisation (issue 12), first: k-fold by video prefix. The tiles of one prefix come from one video;
four folds (Drone2_ | 0_+3_ | 1_+5_ | 2_+4_) each hold out whole videos. Per fold and feature set a
cascade is trained on the other prefixes by the fold recipe (``FOLD_TRAIN_ARGS`` + ``RECIPES[name]``),
its raw windows on the held-out tiles are grouped at the node defaults and at the grouping chosen
without the held-out fold (``kfold``'s ``inner``), and the mean and the *worst* fold are reported
with the pooled PR curve (``bench/plots/detector_kfold_pr.png``). The fold models are not kept; the
shipped fused model is the fold recipe trained on every prefix. ``--quick`` skips the inner choice
and thins the tiles.

Then, side by side in one run, the shipped models:

* data: ``../shared/data/detect/drone-view-vehicles`` split by file-name prefix (tiles of one
  prefix share a video): validation = prefixes ``1_`` and ``4_`` (both street axes), training =
  the others (``Drone2_``, ``0_``, ``2_``, ``3_``, ``5_``);
* detectors: our boosted cascade on LBP only, contour only, and the fused features (seed 003
  Table 1), each trained on the training tiles with the same settings (``--train``; otherwise
  the models shipped in ``multi_target_tracker/models``), and OpenCV's ``CascadeClassifier`` with
  the third-party ``cars.xml`` for speed only (``opencv_traincascade`` is not in the pip wheel, so
  no OpenCV cascade can be trained on the same tiles here; ``cars.xml`` is a rear-view car model
  and is not meant for nadir tiles);
* accuracy (``evaluation.detection_metrics``): a detection counts when IoU >= 0.5 with a still
  unmatched ground-truth box (greedy by score); detection rate = TP / GT boxes; false-alarm rate =
  FP / detections (as seed Table 1 reads); the operating point is the node's defaults
  (``min_neighbors`` 3); PR curve and VOC all-point AP over the detection score with every group
  kept (``min_neighbors`` 1; score = windows in the group + a fraction). Boxes cut by the tile border (about 20 % of them) are *ignored* (neither misses nor false
  alarms: a whole-vehicle window cannot match half a car); the rates over all boxes are reported too;
* speed: frames/s of ``Detector.detect`` alone, single-threaded (``cv2.setNumThreads(1)``), on
  640x640 validation tiles, 640x480 crops of them, and 1280x720 frames of TinyTLP CarChase2, the
  same window-size range for every detector; ``cars.xml`` on ``video1.avi`` (320x240) and on the
  same 640x480 crops.

Writes ``bench/results/detector.json`` and ``.md`` and ``bench/plots/detector_*.png``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir  # noqa: E402
from aircraft_docking_tracker.geometry import box_iou  # noqa: E402
from aircraft_docking_tracker.evaluation.detection_metrics import DetectionAccumulator  # noqa: E402
from aircraft_docking_tracker.evaluation.plots import grouped_bars  # noqa: E402
from aircraft_docking_tracker.offline import build_processor  # noqa: E402
from aircraft_docking_tracker.evaluation.speed import fps, latency_percentiles  # noqa: E402
from multi_target_tracker.box_regression import BoxRegressor, edge_offsets, fit_box_regressor, member_features  # noqa: E402
from multi_target_tracker.detector import (  # noqa: E402
    MODELS_DIR, Detector, DetectorConfig, group_members, group_windows, members_stats, suppress_contained)
from multi_target_tracker.train_cascade import main as train_main  # noqa: E402
from multi_target_tracker.train_cascade import read_yolo_folder, truncated  # noqa: E402

DATA = Path(os.environ.get("ADT_SHARED_DATA", REPO.parent / "shared" / "data"))
TILES = DATA / "detect" / "drone-view-vehicles"
RESULTS = HERE / "results" / "detector.json"   # the last run's results: modes that add to them read it
VALIDATION = ["1_", "4_"]
FEATURE_SETS = ("lbp", "contour", "fused")
TRAIN_ARGS = ["--window", "64", "32", "--rotate90", "--flips", "hv", "--max-positives", "10000",
              "--stages", "20", "--negatives", "5000"]
QUICK_TRAIN_ARGS = ["--window", "64", "32", "--rotate90", "--flips", "hv", "--max-positives", "2000",
                    "--stages", "8", "--negatives", "1500"]


def model_name(feature_set: str) -> str:
    return f"drone_vehicles_{feature_set}.json"


def train_models(out_dir: Path, quick: bool) -> dict:
    seconds = {}
    for fs in FEATURE_SETS:
        started = time.perf_counter()
        args = ["--yolo", str(TILES), "--exclude-prefix", *VALIDATION, "--feature-set", fs,
                "--output", str(out_dir / model_name(fs))] + (QUICK_TRAIN_ARGS if quick else TRAIN_ARGS)
        if train_main(args) != 0:
            raise SystemExit(f"training the {fs} cascade failed")
        seconds[fs] = time.perf_counter() - started
    return seconds


#: the drone-view set-up's scan where config/detector.yaml sets it beyond the dataclass defaults: the colour blobs'
#: views (issue 12, session 34). Every drone-view figure below scans as the node does; the tiles are read in colour.
_SETUP = load_yaml_parameters(package_config_dir() / "detector.yaml", "detector")
SETUP_SCAN = {key: value for key, value in _SETUP.items() if key.startswith("blob_")}
#: the drone-view node's grouping (config/detector.yaml; session 49: chosen over three training seeds, node_grouping)
SETUP_GROUPING = {key: _SETUP[key] for key in ("min_neighbors", "window_margin")}


def detector_for(model: Path, **overrides) -> Detector:
    """Node defaults (the window-size range the model was trained for, config/detector.yaml's scan and grouping),
    with ``overrides``."""
    return Detector(DetectorConfig(model=str(model), **{**SETUP_SCAN, **SETUP_GROUPING, **overrides}))


def evaluate(det: Detector, items) -> tuple[dict, dict]:
    """Accumulated metrics with border-cut boxes ignored, and over all boxes."""
    ignore_cut, all_boxes = DetectionAccumulator(), DetectionAccumulator()
    for item in items:
        image = item.load_colour()
        table = det.detect(image)
        boxes = np.column_stack([table["x"], table["y"], table["w"], table["h"]])
        ignore_cut.add_frame(boxes, table["score"], item.boxes,
                             truncated(item.boxes, image.shape[1::-1], BORDER_MARGIN))
        all_boxes.add_frame(boxes, table["score"], item.boxes)
    return ignore_cut.summary(), all_boxes.summary()


def synthetic_items(kind: str, seed: int, frames: int, every: int):
    """Held-out synthetic frames (not in the models' training bags) as ``(bgr, boxes, ignore flags)`` (BGR: the
    UAV set-up's colour verifier reads it; the detector converts to grey itself)."""
    if kind == "uav":
        from aircraft_docking_tracker.scenarios.uav import (  # noqa: PLC0415
            UAV_SETUP_GROUND_RESOLUTION, UavScene, UavSceneConfig, detection_truth)
        # at the camera height the UAV set-up is made for (bench/uav_detector.py has the full protocol)
        scene = UavScene(UavSceneConfig(frames=frames, difficulty=2, ground_resolution=UAV_SETUP_GROUND_RESOLUTION),
                         seed=seed)
    else:
        from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: PLC0415
        scene = DockingScene(DockingSceneConfig(frames=frames), seed=seed)
    out = []
    for k, frame in enumerate(scene.frames()):
        if k % every:
            continue
        if kind == "uav":
            boxes, ignore = detection_truth(frame.ground_truth)   # hidden or mostly hidden vehicles ignored
        else:
            lo, hi = frame.quad.min(axis=0), frame.quad.max(axis=0)
            boxes, ignore = np.array([[lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]]]), np.zeros(1, bool)
        out.append((frame.image, boxes, ignore))
    return out


# --------------------------------------------------------------------------- k-fold by video prefix
# Each fold holds out whole videos (file-name prefixes). Drone2_ is one long video (785 tiles); 0_..5_
# are six short ones, paired so that every fold holds 110-140 of their tiles.
FOLDS = (("Drone2_",), ("0_", "3_"), ("1_", "5_"), ("2_", "4_"))
ALL_PREFIXES = tuple(p for fold in FOLDS for p in fold)
# The fold recipe: the shipped recipe (TRAIN_ARGS) made cheaper so that 4 folds x (outer + inner model)
# x 3 feature sets fit in a bench run: fewer positives, stages and negatives per stage.
FOLD_TRAIN_ARGS = ["--window", "64", "32", "--rotate90", "--flips", "hv", "--max-positives", "3000",
                   "--stages", "12", "--negatives", "2000"]
QUICK_FOLD_ARGS = ["--max-positives", "1000", "--stages", "6", "--negatives", "1000"]   # --quick: a smoke run
RECIPES = {"seed": [],                                              # the shipped recipe, made cheaper
           "photometric": ["--photometric", "0.6"],                   # + grey-level augmentation of the copies
           "negatives": ["--negatives", "4000", "--stages", "16"],    # + more, harder negatives (deeper cascade)
           # one change at a time on top of `photometric` (issue 12 item 2): the miner already bootstraps every
           # stage from full frames of every training prefix, so "more negatives" is more of them and more stages
           "photometric+negatives": ["--photometric", "0.6", "--negatives", "4000", "--stages", "16"],
           # windows for the aspect ratios that occur: boxes from 1:1 (vehicles at 45 degrees) to 2.6:1, a 48x32
           # window in both orientations overlaps each of them by IoU >= 0.6 at equal area and centre (a 64x32 one
           # only 0.55 on a square box: no margin for the scan's scale steps); positives cut at the window's shape
           "photometric+window48": ["--photometric", "0.6", "--window", "48", "32", "--positive-aspect", "window"],
           # ... and positives at every heading: the held-out misses are mostly vehicles at 30-60 degrees (boxes
           # of aspect < 1.6: 12 % of Drone2_'s, found at 0.1-0.5 against 0.85 for the others), rare in training
           "photometric+window48+turn45": ["--photometric", "0.6", "--window", "48", "32", "--positive-aspect",
                                           "window", "--turn-jitter", "45"],
           # issue 12, session 9: the worst fold's false alarms depend on the training seed (0.080 vs 0.119 at the
           # inner choice): each stage's threshold keeps 99.5 % of only 3000 positives (set by its ~15 hardest) and
           # the positives are a random 3000 of the many jittered/flipped views; twice as many should steady both.
           # Measured (seed 0): not better, worst fold 0.872 / 0.085 against 0.904 / 0.080 (bench/results/detector.md)
           "photometric+negatives+positives": ["--photometric", "0.6", "--negatives", "4000", "--stages", "16",
                                               "--max-positives", "6000"]}
SHIPPED_RECIPE = "photometric+negatives"   # k-fold: worst fold FA 0.167 -> 0.120, mean det. 0.929 -> 0.943
# boxes cut by the tile border are ignored (truncated(): closer than this to the border); the recipe rows
# measured before the labels' 1-px clipping was seen (border margin 1.0) are marked in the comparison
BORDER_MARGIN = 1.5
GRID_MIN_NEIGHBORS = (1, 2, 3, 4, 5, 6, 8, 10, 13, 16, 20)
GRID_MARGIN = (-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)
# the grouping the folds report besides the inner choice: the node defaults before the k-fold protocol
# (the trained cascade, OpenCV's 3 neighbours). The node defaults now are the choice over all four folds,
# so their held-out estimate is the inner-choice column (each fold's choice made without it).
REFERENCE_GROUPING = {"min_neighbors": 3, "window_margin": 0.0}
TARGET_DETECTION = 0.90
TARGET_FALSE_ALARMS = 0.10
CHOICE_FALSE_ALARMS = 0.08   # the inner choice keeps a margin below the target
# how the inner choice weighs the inner folds (choose_grouping); the other rule is reported beside it
CHOICE_RULES = ("worst-fold", "pooled")
CHOICE_RULE = "worst-fold"


def fold_tiles(prefixes, every_drone2: int = 3):
    """Tiles of these prefixes (Drone2_ thinned to every ``every_drone2``-th tile: one long video)."""
    items = read_yolo_folder(TILES, include=list(prefixes))
    drone2 = [it for it in items if it.name.startswith("Drone2_")][::every_drone2]
    return [it for it in items if not it.name.startswith("Drone2_")] + drone2


def train_fold_model(out: Path, prefixes, feature_set: str, recipe: list[str], seed: int = 0) -> float:
    started = time.perf_counter()
    args = ["--yolo", str(TILES), "--include-prefix", *prefixes, "--feature-set", feature_set, "--seed", str(seed),
            "--output", str(out)] + FOLD_TRAIN_ARGS + recipe
    if train_main(args) != 0:
        raise SystemExit(f"training {out.name} failed")
    return time.perf_counter() - started


def raw_windows(model: Path, items, margin: float = min(GRID_MARGIN)):
    """Every window the cascade passes with last-stage margin >= ``margin``, per tile, with the tile's GT."""
    det = detector_for(model, window_margin=margin)
    out = []
    for item in items:
        image = item.load_colour()
        boxes, scores, _ = det.raw(image)   # the drone-view set-up groups upright boxes
        out.append((boxes, scores, item.boxes, truncated(item.boxes, image.shape[1::-1], BORDER_MARGIN)))
    return det.config, out


def grouped_summary(config: DetectorConfig, raws, min_neighbors: int, margin: float) -> dict:
    """Detection metrics (border-cut boxes ignored) of the raw windows grouped with these parameters."""
    acc = DetectionAccumulator()
    for boxes, scores, gt, cut in raws:
        keep = scores >= margin
        b, s = group_windows(boxes[keep], scores[keep], config.group_iou, min_neighbors, config.containment,
                             config.max_detections)
        acc.add_frame(b, s, gt, cut)
    return acc.summary()


def worst_fold_key(worst_detection: float, worst_false_alarms: float) -> tuple:
    """Rule ``worst-fold``'s order of settings: those with every fold at <= CHOICE_FALSE_ALARMS first, by their worst
    detection, then fewer false alarms; the others by their worst false alarms, then detection."""
    if worst_false_alarms <= CHOICE_FALSE_ALARMS:
        return True, worst_detection, -worst_false_alarms
    return False, -worst_false_alarms, worst_detection


def choose_grouping(config: DetectorConfig, raws_by_fold: list, rule: str = None) -> dict:
    """(min_neighbors, window_margin) chosen on inner validation tiles, given per fold (per video group).

    ``worst-fold`` (the default, ``CHOICE_RULE``): the highest *worst* fold's detection rate with every fold
    at <= CHOICE_FALSE_ALARMS false alarms: the setting must hold on each group of videos, as it must on the
    videos we do not have. ``pooled`` (sessions 4-5): the highest detection rate at <= CHOICE_FALSE_ALARMS
    over all inner tiles pooled; a setting that suits the pooled tiles can still fail on one video. If nothing meets the false-alarm
    bound: the fewest (worst-fold or pooled) false alarms. Worst-fold ties: fewer false alarms, then more
    neighbours, then a higher margin."""
    rule = rule or CHOICE_RULE
    best = None
    for mn in GRID_MIN_NEIGHBORS:
        for m in GRID_MARGIN:
            if rule == "pooled":
                s = grouped_summary(config, [r for raws in raws_by_fold for r in raws], mn, m)
                det, far = s["detection_rate"], s["false_alarm_rate"]
            else:
                per_fold = [grouped_summary(config, raws, mn, m) for raws in raws_by_fold]
                det = min(f["detection_rate"] for f in per_fold)
                far = max(f["false_alarm_rate"] for f in per_fold)
            if rule == "pooled":
                key = (far <= CHOICE_FALSE_ALARMS, det if far <= CHOICE_FALSE_ALARMS else -far)
            else:
                key = worst_fold_key(det, far)
            if best is None or key > best[0] or (rule != "pooled" and key == best[0]):
                best = (key, {"min_neighbors": mn, "window_margin": m, "rule": rule,
                              "inner_detection_rate": det, "inner_false_alarm_rate": far})
    return best[1]


def kfold(feature_sets, recipe_name: str, work: Path, inner: str = "crossfit", seed: int = 0,
          quick: bool = False, reuse: bool = False) -> dict:
    """The k-fold protocol for one training recipe: per fold, a model trained on the other prefixes, its raw
    windows on the held-out tiles; held-out metrics at the node defaults and at grouping parameters chosen
    without the held-out fold (``inner``), and the pooled PR curve.

    ``inner`` "model": for fold k a second model is trained without the next fold and the parameters are
    chosen on that fold (strictly inside fold k's training prefixes; one more training per fold).
    "crossfit" (cheap): the parameters are chosen on the held-out windows of the *other* folds' models,
    pooled; the tiles scored are all in fold k's training prefixes, but those models were trained with
    fold k's tiles among theirs (a weak leak: through how they score other videos). "none": defaults only.
    ``reuse``: fold models already in ``work`` (same recipe and feature set) are evaluated, not retrained.
    """
    recipe = RECIPES[recipe_name]
    defaults = DetectorConfig()
    out = {"recipe": recipe_name, "border_margin": BORDER_MARGIN, "train_args": FOLD_TRAIN_ARGS + recipe + (QUICK_FOLD_ARGS if quick else []), "folds": [list(f) for f in FOLDS],
           "seed": seed, "inner": inner, "reference_grouping": REFERENCE_GROUPING, "feature_sets": {}}
    every = 9 if quick else 3
    for fs in feature_sets:
        folds, fold_raws = [], []
        for k, held in enumerate(FOLDS):
            train = [p for p in ALL_PREFIXES if p not in held]
            tag = f"{recipe_name}_{fs}_fold{k}" + (f"_seed{seed}" if seed else "")
            model = work / f"{tag}.json"
            seconds = (json.loads(model.read_text())["info"].get("train_seconds", 0.0) if reuse and model.is_file()
                       else train_fold_model(model, train, fs, recipe + (QUICK_FOLD_ARGS if quick else []), seed))
            config, raws = raw_windows(model, fold_tiles(held, every))
            fold_raws.append(raws)
            info = json.loads(model.read_text())
            entry = {"held_out": list(held), "train_seconds": round(seconds, 1), "tiles": len(raws),
                     "stages": len(info["stages"]), "stumps": sum(len(st["features"]) for st in info["stages"]),
                     "defaults": _rates(grouped_summary(config, raws, REFERENCE_GROUPING["min_neighbors"],
                                                        REFERENCE_GROUPING["window_margin"]))}
            pr = grouped_summary(config, raws, 1, REFERENCE_GROUPING["window_margin"])
            entry["average_precision"] = pr["average_precision"]
            entry["best_at_10pct_false_alarms"] = _best_at(pr)
            if inner == "model":
                inner_fold = FOLDS[(k + 1) % len(FOLDS)]
                inner_model = work / f"{tag}_inner.json"
                train_fold_model(inner_model, [p for p in train if p not in inner_fold], fs, recipe, seed)
                inner_config, inner_raws = raw_windows(inner_model, fold_tiles(inner_fold, every))
                entry["inner_fold"] = list(inner_fold)
                entry["chosen"] = choose_grouping(inner_config, [inner_raws], "pooled")
            folds.append(entry)
            print(f"[{recipe_name} {fs}] fold {k} {'+'.join(held)}: defaults {entry['defaults']}", flush=True)
        for k, entry in enumerate(folds):
            if inner == "crossfit":
                others = [raws for j, raws in enumerate(fold_raws) if j != k]
                entry["rules"] = {}
                for rule in CHOICE_RULES:
                    chosen = choose_grouping(defaults, others, rule)
                    entry["rules"][rule] = {"chosen": chosen, "at_choice": _rates(grouped_summary(
                        defaults, fold_raws[k], chosen["min_neighbors"], chosen["window_margin"]))}
                entry["chosen"] = entry["rules"][CHOICE_RULE]["chosen"]
            if "chosen" in entry:
                entry["at_choice"] = _rates(grouped_summary(defaults, fold_raws[k], entry["chosen"]["min_neighbors"],
                                                            entry["chosen"]["window_margin"]))
                print(f"[{recipe_name} {fs}] fold {k}: choice {entry['chosen']} -> {entry['at_choice']}", flush=True)
        if "rules" in folds[0]:
            summary_rules = {}
            for rule in CHOICE_RULES:
                det = [f["rules"][rule]["at_choice"]["detection_rate"] for f in folds]
                far = [f["rules"][rule]["at_choice"]["false_alarm_rate"] for f in folds]
                summary_rules[rule] = {**fold_summary(det, far),
                                       "all_folds_choice": choose_grouping(defaults, fold_raws, rule)}
        pooled = DetectionAccumulator()
        for raws in fold_raws:
            for boxes, scores, gt, cut in raws:
                keep = scores >= REFERENCE_GROUPING["window_margin"]
                b, sc = group_windows(boxes[keep], scores[keep], defaults.group_iou, 1, defaults.containment,
                                      defaults.max_detections)
                pooled.add_frame(b, sc, gt, cut)
        pooled = pooled.summary()
        summary = {"folds": folds, "choice_rule": CHOICE_RULE if inner == "crossfit" else "pooled"}
        if "rules" in folds[0]:
            summary["rules"] = summary_rules
        for key in ("defaults", "at_choice"):
            if key in folds[0]:
                det = [f[key]["detection_rate"] for f in folds]
                far = [f[key]["false_alarm_rate"] for f in folds]
                summary[key] = fold_summary(det, far)
        # the setting for a model trained on every prefix: chosen on all folds' held-out windows
        summary["all_folds_choice"] = choose_grouping(defaults, fold_raws)
        summary["pooled_average_precision"] = pooled["average_precision"]
        summary["pooled_best_at_10pct_false_alarms"] = _best_at(pooled)
        step = max(1, len(pooled["pr_precision"]) // 400)
        summary["pooled_pr_precision"] = pooled["pr_precision"][::step]
        summary["pooled_pr_recall"] = pooled["pr_recall"][::step]
        out["feature_sets"][fs] = summary
    return out


BOX_REGRESSION_IOU = 0.3        # a group is a regression sample when it overlaps a counted box this much
BOX_REGRESSION_MIN_WINDOWS = 3   # ... and holds at least this many windows
BOX_REGRESSION_L2 = 100.0


def member_groups(raws_by_fold: list, sizes_by_fold: list) -> list:
    """Per fold, tile and grid margin: every group of the fold's raw windows (min count 1) with its mean box,
    window count, best margin and box-regression features (``box_regression.member_features``)."""
    out = []
    for raws, sizes in zip(raws_by_fold, sizes_by_fold):
        fold = []
        for (boxes, scores, gt, cut), size in zip(raws, sizes):
            per_margin = {}
            for m in GRID_MARGIN:
                keep = scores >= m
                members = group_members(boxes[keep], scores[keep], DetectorConfig().group_iou)
                kept, gboxes, counts, _, best = members_stats(*members, m, 1)
                feats = member_features(*members[:3], kept, gboxes, m, size)
                per_margin[m] = (gboxes, counts, best, feats)
            fold.append((per_margin, gt, cut))
        out.append(fold)
    return out


def regression_samples(groups_by_fold: list) -> tuple[np.ndarray, np.ndarray]:
    """Features and edge-offset targets of the groups (every grid margin, >= BOX_REGRESSION_MIN_WINDOWS
    windows) that overlap a counted (not border-cut) box by IoU >= BOX_REGRESSION_IOU."""
    rows, targets = [], []
    for fold in groups_by_fold:
        for per_margin, gt, cut in fold:
            counted = np.asarray(gt, np.float64).reshape(-1, 4)[~np.asarray(cut, bool)]
            if not len(counted):
                continue
            for gboxes, counts, _, feats in per_margin.values():
                big = counts >= BOX_REGRESSION_MIN_WINDOWS
                if not big.any():
                    continue
                iou = box_iou(gboxes[big][:, None], counted[None])
                near = iou.max(axis=1) >= BOX_REGRESSION_IOU
                rows.append(feats[big][near])
                targets.append(edge_offsets(gboxes[big][near], counted[iou[near].argmax(axis=1)]))
    return np.vstack(rows), np.vstack(targets)


def regressed_summary(config: DetectorConfig, fold_groups: list, regressor, min_neighbors: int, margin: float) -> dict:
    """:func:`grouped_summary` with each group's box moved by ``regressor`` (None: the mean box, as the node)."""
    acc = DetectionAccumulator()
    for per_margin, gt, cut in fold_groups:
        gboxes, counts, best, feats = per_margin[margin]
        big = counts >= min_neighbors
        b, sc = gboxes[big], counts[big] + 1.0 / (1.0 + np.exp(-best[big]))
        if regressor is not None and len(b):
            b = regressor.refine(b, feats[big])
        keep = suppress_contained(b, sc, config.containment, config.max_detections, config.suppression_iou)
        acc.add_frame(b[keep], sc[keep], gt, cut)
    return acc.summary()


def regressed_grid(config: DetectorConfig, fold_groups: list, regressor) -> dict:
    """``{(min_neighbors, window_margin): regressed_summary}`` of one fold's groups refined by ``regressor`` (None: mean
    boxes), at every setting of the grid, in grid order."""
    return {(mn, m): regressed_summary(config, fold_groups, regressor, mn, m)
            for mn in GRID_MIN_NEIGHBORS for m in GRID_MARGIN}


def choose_regressed(grids: list) -> dict:
    """``choose_grouping``'s ``worst-fold`` rule over inner folds (their :func:`regressed_grid`, each refined by its own
    regressor); ties go to the later setting of the grid."""
    best = None
    for mn, m in grids[0]:
        det = min(g[mn, m]["detection_rate"] for g in grids)
        far = max(g[mn, m]["false_alarm_rate"] for g in grids)
        key = worst_fold_key(det, far)
        if best is None or key >= best[0]:
            best = (key, {"min_neighbors": mn, "window_margin": m, "rule": "worst-fold",
                          "inner_detection_rate": det, "inner_false_alarm_rate": far})
    return best[1]


def kfold_box_regression(work: Path, recipe_name: str, seed: int, feature_set: str = "fused",
                         transfer: Path | None = None, regressors_dir: Path | None = None):
    """The group box regressor (``box_regression``) on the drone-view prefix folds, on fold models already in
    ``work`` (named as ``kfold`` names them). Per held-out fold k: the regressor is trained on the held-out
    groups of the other folds' models (their tiles are fold k's training tiles, scored by models that did not
    train on them; those models saw fold k's tiles: ``kfold``'s crossfit leak); the grouping is chosen by rule
    ``worst-fold`` over those inner folds, each refined by a regressor trained without it (nor fold k); then
    fold k is scored with and without the regressor at its own choice and at the node defaults.

    Each fold's regressor is written to ``regressors_dir`` (default ``work``; ``fold_regressor_path``). ``transfer``: the folder of another
    training seed's fold regressors; fold k is also scored, at the node defaults, with the regressor trained
    on that seed's models without fold k ("transferred"): a regressor on the windows of a model it was not
    trained with (as the shipped regressor on the shipped model, trained on every prefix), on tiles it did not see.

    Returns ``(results, regressor)``: the regressor trained on all four folds' held-out groups (the shipped
    drone-view regressor when the fold models are the shipped model's recipe and training seed)."""
    defaults = DetectorConfig()
    raws_by_fold, sizes_by_fold, models = [], [], []
    for k, held in enumerate(FOLDS):
        model = work / (f"{recipe_name}_{feature_set}_fold{k}" + (f"_seed{seed}" if seed else "") + ".json")
        if not model.is_file():
            raise SystemExit(f"{model} not found: train the fold models first (--compare --work)")
        items = fold_tiles(held, 3)
        _, raws = raw_windows(model, items)
        raws_by_fold.append(raws)
        sizes_by_fold.append([item.size for item in items])        # read_yolo_folder's: no second read
        models.append(model.name)
        print(f"[box regression seed {seed}] fold {k}: {len(raws)} tiles", flush=True)
    groups = member_groups(raws_by_fold, sizes_by_fold)
    folds = []
    node = (SETUP_GROUPING["min_neighbors"], SETUP_GROUPING["window_margin"])
    for k, held in enumerate(FOLDS):
        inner = [j for j in range(len(FOLDS)) if j != k]
        regressor = fit_box_regressor(*regression_samples([groups[j] for j in inner]), BOX_REGRESSION_L2)
        inner_regs = [fit_box_regressor(*regression_samples([groups[i] for i in inner if i != j]), BOX_REGRESSION_L2)
                      for j in inner]
        regressor.save(fold_regressor_path(regressors_dir or work, recipe_name, feature_set, k, seed))
        entry = {"held_out": list(held), "model": models[k], "samples": regressor.info["samples"]}
        if transfer is not None:
            other = sorted(transfer.glob(fold_regressor_path(Path(), recipe_name, feature_set, k, "*").name))
            other = [o for o in other if o.name != fold_regressor_path(Path(), recipe_name, feature_set, k, seed).name]
            if not other:
                raise SystemExit(f"no fold-{k} regressor in {transfer}: run --box-regression on that folder first")
            entry["transferred"] = {"regressor": other[0].name, "at_node_defaults": _rates(regressed_summary(
                defaults, groups[k], BoxRegressor.load(other[0]), *node))}
            print(f"[box regression seed {seed}] fold {k} transferred: {entry['transferred']}", flush=True)
        inner_grids = {}
        for name, reg, regs in (("mean box", None, [None] * len(inner)), ("regressed", regressor, inner_regs)):
            inner_grids[name] = [regressed_grid(defaults, groups[j], r) for j, r in zip(inner, regs)]
            chosen = choose_regressed(inner_grids[name])
            entry[name] = {"chosen": chosen,
                           "at_choice": _rates(regressed_summary(defaults, groups[k], reg, chosen["min_neighbors"],
                                                                 chosen["window_margin"])),
                           "at_node_defaults": _rates(regressed_summary(defaults, groups[k], reg, *node))}
            print(f"[box regression seed {seed}] fold {k} {name}: {entry[name]}", flush=True)
        # every grid setting, for the choice of the node's grouping over all training seeds (node_grouping); the inner
        # folds' grids are the ones the regressed inner choice was made on
        entry["grid"] = grid_rates(regressed_grid(defaults, groups[k], regressor))
        entry["inner_grids"] = {str(j): grid_rates(g) for j, g in zip(inner, inner_grids["regressed"])}
        plain = entry["mean box"]["chosen"]     # the regressor as a last step only: the mean box's grouping kept
        entry["regressed, mean-box grouping"] = {"chosen": plain, "at_choice": _rates(regressed_summary(
            defaults, groups[k], regressor, plain["min_neighbors"], plain["window_margin"]))}
        folds.append(entry)
    out = {"seed": seed, "recipe": recipe_name, "feature_set": feature_set, "node_defaults": list(node),
           "iou": BOX_REGRESSION_IOU, "min_windows": BOX_REGRESSION_MIN_WINDOWS, "l2": BOX_REGRESSION_L2,
           "folds": folds}
    for name in ("mean box", "regressed", "regressed, mean-box grouping", "transferred"):
        if name not in folds[0]:
            continue
        for point in ("at_node_defaults",) if name == "transferred" else \
                ("at_choice", "at_node_defaults")[:1 if name.endswith("grouping") else 2]:
            det = [f[name][point]["detection_rate"] for f in folds]
            far = [f[name][point]["false_alarm_rate"] for f in folds]
            out.setdefault("summary", {}).setdefault(name, {})[point] = fold_summary(det, far)
    regressor = fit_box_regressor(*regression_samples(groups), BOX_REGRESSION_L2)
    regressor.info.update({"fold_models": models, "recipe": recipe_name, "training_seed": seed,
                           "samples_from": "held-out groups of the prefix-fold models (bench/detector.py "
                                           "--box-regression)", "iou": BOX_REGRESSION_IOU,
                           "min_windows": BOX_REGRESSION_MIN_WINDOWS, "window_margins": list(GRID_MARGIN),
                           "group_iou": defaults.group_iou})
    return out, regressor


def grid_rates(grid: dict) -> dict:
    """A :func:`regressed_grid` as stored: ``{"min_neighbors/window_margin": [detection, false alarms]}``, rounded."""
    return {grid_key(mn, m): [round(s["detection_rate"], 4), round(s["false_alarm_rate"], 4)]
            for (mn, m), s in grid.items()}


def grid_key(min_neighbors: int, margin: float) -> str:
    return f"{min_neighbors}/{margin:+.1f}"


def fold_summary(det: list, far: list) -> dict:
    """Mean and worst detection / false alarms of folds, and how many of them meet issue 12's target."""
    return {"mean_detection_rate": float(np.mean(det)), "mean_false_alarm_rate": float(np.mean(far)),
            "worst_detection_rate": float(np.min(det)), "worst_false_alarm_rate": float(np.max(far)),
            "folds_meeting_target": int(sum(target_margin(d, f) >= 0 for d, f in zip(det, far)))}


def target_margin(detection: float, false_alarms: float) -> float:
    """How far a fold lies inside issue 12's target, on its nearer side: ``min(det - 0.90, 0.10 - FA)`` (< 0: missed)."""
    return min(detection - TARGET_DETECTION, TARGET_FALSE_ALARMS - false_alarms)


def choose_by_margin(grids: list) -> str:
    """The grid setting whose smallest :func:`target_margin` over ``grids`` (one per fold and training seed) is the
    largest; ties: the higher mean detection. Both sides of the target count alike: videos we do not have lose
    ground on either."""
    def key(setting):
        rates = [g[setting] for g in grids]
        return min(target_margin(d, f) for d, f in rates), float(np.mean([d for d, _ in rates]))
    return max(grids[0], key=key)


def choose_by_worst_fold(grids: list) -> str:
    """:func:`choose_grouping`'s ``worst-fold`` rule on stored grids (:func:`worst_fold_key`, ties as there)."""
    best = None
    for setting in grids[0]:        # grid order; ties go to the later setting (more neighbours, higher margin)
        key = worst_fold_key(min(g[setting][0] for g in grids), max(g[setting][1] for g in grids))
        if best is None or key >= best[0]:
            best = (key, setting)
    return best[1]


PREVIOUS_GROUPING = (3, -0.5)   # the node's min_neighbors / window_margin from session 6 to 48 (rule worst-fold, seed 0)
NODE_GROUPING_RULES = {"margin": choose_by_margin, "worst-fold": choose_by_worst_fold}


def node_grouping(runs: dict, recipe_name: str = SHIPPED_RECIPE) -> dict | None:
    """The drone-view node's grouping (min_neighbors, window_margin) chosen over every training seed's fold models
    (``kfold_box_regression``'s grids, each fold refined by its own regressor), and the protocol's estimate of that
    choice on videos it did not see: fold k scored at the setting each rule picks on the *other* folds of every seed
    (their grids refined by regressors trained without fold k). None before a run stored grids."""
    runs = [r for key, r in sorted(runs.items()) if key.startswith(f"{recipe_name}_seed")
            and all("grid" in f for f in r.get("folds", ()))]
    if not runs:
        return None

    def summary(cells):
        return {**fold_summary([c[0] for c in cells], [c[1] for c in cells]), "cells": len(cells),
                "smallest_target_margin": float(min(target_margin(d, f) for d, f in cells))}
    out = {"seeds": [r["seed"] for r in runs], "rules": {}}
    every = [f["grid"] for r in runs for f in r["folds"]]
    out["shown"] = {label: {"setting": grid_key(*setting), **summary([g[grid_key(*setting)] for g in every])}
                    for label, setting in (("node defaults of sessions 6-48", PREVIOUS_GROUPING),
                                           ("node defaults (config/detector.yaml)", runs[0]["node_defaults"]))}
    for name, rule in NODE_GROUPING_RULES.items():
        chosen = rule(every)
        held_out = []
        for k in range(len(FOLDS)):
            inner = [g for r in runs for g in r["folds"][k]["inner_grids"].values()]
            setting = rule(inner)
            held_out += [{"seed": r["seed"], "fold": k, "setting": setting, "rates": r["folds"][k]["grid"][setting]}
                         for r in runs]
        out["rules"][name] = {"all_folds": {"setting": chosen, **summary([g[chosen] for g in every])},
                              "held_out": {"folds": held_out, **summary([h["rates"] for h in held_out])}}
    return out


def fold_regressor_path(work: Path, recipe_name: str, feature_set: str, fold: int, seed) -> Path:
    """Where ``kfold_box_regression`` keeps fold ``fold``'s regressor (trained without that fold)."""
    return work / f"box_regressor_{recipe_name}_{feature_set}_fold{fold}_seed{seed}.json"


def regressor_speed(regressor: Path, rounds: int = 5, frames: int = 12) -> dict:
    """Frames/s of the shipped fused model at the node defaults with and without ``regressor``, timed in
    alternation (``rounds`` times) on the same 640x480 crops of validation tiles, one thread; each frame's
    latency is its best over the rounds (the shared machine's load spikes hit one arm's round, not every round)."""
    cv2.setNumThreads(1)
    validation = read_yolo_folder(TILES, include=VALIDATION)[::3]
    crops = [item.load_colour()[80:560] for item in validation[:frames]]
    arms = {"mean box": detector_for(MODELS_DIR / model_name("fused")),
            "regressed": detector_for(MODELS_DIR / model_name("fused"), box_regressor=str(regressor))}
    latencies = {name: np.full((rounds, len(crops)), np.inf) for name in arms}
    for r in range(rounds):
        for i, crop in enumerate(crops):
            for name, det in arms.items():
                started = time.perf_counter()
                det.detect(crop)
                latencies[name][r, i] = time.perf_counter() - started
    best = {name: {"fps": fps(lat.min(axis=0)), **latency_percentiles(lat.min(axis=0))} for name, lat in latencies.items()}
    return {**best, "ratio": best["regressed"]["fps"] / best["mean box"]["fps"], "frames": len(crops),
            "rounds": rounds, "regressor": Path(regressor).name, "timing": "per frame best of the rounds"}


def _rates(summary: dict) -> dict:
    return {"detection_rate": round(summary["detection_rate"], 4), "false_alarm_rate": round(summary["false_alarm_rate"], 4),
            "detections": summary["detections"], "ground_truth": summary["ground_truth"]}


def _best_at(pr: dict, false_alarms: float = TARGET_FALSE_ALARMS) -> dict:
    """Highest recall on a PR curve with precision >= 1 - false_alarms (an oracle read-out, for comparison)."""
    precision, recall = np.asarray(pr["pr_precision"]), np.asarray(pr["pr_recall"])
    ok = np.flatnonzero(precision >= 1 - false_alarms)
    return {"detection_rate": float(recall[ok].max()) if len(ok) else 0.0}


def setup_detector(setup: str) -> Detector:
    """The detector as a camera set-up file configures it (``config/<setup>``), built as run_offline does."""
    processor = build_processor("detector", package_config_dir() / setup)
    if processor.detector is None:
        raise SystemExit(f"bench/detector.py: {setup}: {processor.model_error}")
    return processor.detector


def evaluate_synthetic(det: Detector, items) -> dict:
    acc = DetectionAccumulator()
    latencies = []
    for image, boxes, ignore in items:
        started = time.perf_counter()
        table = det.detect(image)
        latencies.append(time.perf_counter() - started)
        acc.add_frame(np.column_stack([table["x"], table["y"], table["w"], table["h"]]), table["score"], boxes, ignore)
    summary = {k: v for k, v in acc.summary().items() if not k.startswith("pr_")}
    counted = np.concatenate([b[~ig] for _, b, ig in items]) if items else np.zeros((0, 4))
    short = np.minimum(counted[:, 2], counted[:, 3])
    sizes = {"box_short_side_percentiles_5_25_50_75_95": np.percentile(short, [5, 25, 50, 75, 95]).round(1).tolist(),
             "fraction_short_side_below_20px": float(np.mean(short < 20)),
             "fraction_short_side_below_32px": float(np.mean(short < 32))} if len(short) else {}
    return {**summary, "fps": fps(latencies), "searched_min_size": float(max(det.min_size, det.window[1])), **sizes}


def cars_reference() -> Detector | None:
    """OpenCV's ``CascadeClassifier`` with the third-party ``cars.xml`` (None without the file), scanning as the fused
    cascade's 640x480 speed row does (the drone-view model's window sizes, both orientations): C++ code this package
    does not change, so its frames/s in a run reads the machine's speed in that run (the UAV bench times it too)."""
    cars = DATA / "cascades" / "cars.xml"
    if not cars.is_file():
        return None
    return Detector(DetectorConfig(backend="opencv", model=str(cars), scale_factor=1.2, min_neighbors=2,
                                   orientation="both", min_size=28, max_size=84))


def time_frames(detect, frames) -> dict:
    latencies = []
    for frame in frames:
        started = time.perf_counter()
        detect(frame)
        latencies.append(time.perf_counter() - started)
    return {"fps": fps(latencies), **latency_percentiles(latencies)}


def video_frames(path: Path, n: int) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    out = []
    while len(out) < n:
        ok, frame = cap.read()
        if not ok:
            break
        out.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a validation subset and few speed frames (~2 min)")
    parser.add_argument("--train", action="store_true", help="train the three cascades first (minutes each)")
    parser.add_argument("--models", default=None, help="folder with drone_vehicles_<set>.json (default: shipped)")
    parser.add_argument("--no-folds", action="store_true", help="skip the k-fold protocol (keep its last results)")
    parser.add_argument("--folds-only", action="store_true", help="run only the k-fold protocol")
    parser.add_argument("--folds-from", default=None, help="take the k-fold results from this JSON (a kfold() result "
                        "or an earlier detector.json) instead of training the folds")
    parser.add_argument("--update-folds", default=None, metavar="JSON",
                        help="measure nothing: put this k-fold result into bench/results/detector.json and rewrite "
                        "the tables and plots")
    parser.add_argument("--recipe", default=SHIPPED_RECIPE, choices=sorted(RECIPES), help="training recipe of the folds")
    parser.add_argument("--table1", nargs="+", default=None, metavar="JSON",
                        help="measure nothing: put these --compare runs (kfold_<recipe>_seed<S>.json in their --work, "
                        "scanned as config/detector.yaml scans; runs of one seed with other feature sets are merged) "
                        "into Table 1 by training seed")
    parser.add_argument("--compare", action="store_true",
                        help="measure nothing else: run the k-fold protocol for --recipe (fused features, inner choice "
                        "by crossfit) and put it into the recipe comparison of bench/results/detector.json")
    parser.add_argument("--feature-sets", nargs="*", default=["fused"], choices=FEATURE_SETS,
                        help="feature sets of --compare (all three: Table 1 by that recipe)")
    parser.add_argument("--work", default=None, help="keep the fold models here (--compare; reused when present)")
    parser.add_argument("--seed", type=int, default=0, help="--compare: training seed of the fold models (another "
                        "seed is kept apart, as the spread of that recipe over seeds)")
    parser.add_argument("--as-main", action="store_true",
                        help="--compare: this run (all three feature sets) also becomes the main k-fold table")
    parser.add_argument("--synthetic-only", action="store_true",
                        help="rerun only the synthetic scenes' rows (UAV and stand set-ups); keep every other result")
    parser.add_argument("--box-regression", action="store_true",
                        help="the group box regressor on the fold models in --work (recipe --recipe, training seed "
                        "--seed; trained by --compare), against the mean box; adds its rows to the results")
    parser.add_argument("--save-regressor", default=None, metavar="JSON",
                        help="--box-regression: also write the regressor trained on all four folds' held-out groups "
                        "and time the shipped fused model with and without it")
    parser.add_argument("--regressors", default=None, metavar="DIR",
                        help="--box-regression: write each fold's regressor here (default: --work)")
    parser.add_argument("--transfer", default=None, metavar="DIR",
                        help="--box-regression: also score each fold with another training seed's fold regressor "
                        "(written to DIR by an earlier --box-regression run)")
    args = parser.parse_args()
    if args.box_regression:
        cv2.setNumThreads(1)
        if not args.work:
            parser.error("--box-regression needs --work (the folder of the fold models)")
        br, regressor = kfold_box_regression(Path(args.work), args.recipe, args.seed,
                                             transfer=Path(args.transfer) if args.transfer else None,
                                             regressors_dir=Path(args.regressors) if args.regressors else None)
        results = json.loads(RESULTS.read_text())
        if args.save_regressor:
            regressor.info["for_models"] = [model_name("fused")]    # the detector refuses it with another model
            regressor.info["scan"] = SETUP_SCAN                      # the windows it was trained on
            regressor.save(args.save_regressor)
            print(f"wrote {args.save_regressor}: {regressor.info['samples']} groups")
            results.setdefault("box_regression", {})["speed_640x480"] = regressor_speed(Path(args.save_regressor))
            print(f"speed: {results['box_regression']['speed_640x480']}", flush=True)
        results.setdefault("box_regression", {})[f"{args.recipe}_seed{args.seed}"] = br
        write_results(results)
        return 0
    if args.compare:
        cv2.setNumThreads(1)
        work = Path(args.work or tempfile.mkdtemp(prefix="detector_folds_"))
        work.mkdir(parents=True, exist_ok=True)
        started = time.perf_counter()
        kf = kfold(tuple(args.feature_sets), args.recipe, work, "crossfit", seed=args.seed, reuse=True)
        kf["wall_seconds"] = time.perf_counter() - started
        (work / f"kfold_{args.recipe}_seed{args.seed}.json").write_text(json.dumps(kf, indent=1))
        results = json.loads(RESULTS.read_text())
        add_to_comparison(results["kfold"], kf)
        if args.as_main:
            results["kfold"].update({k: v for k, v in kf.items() if k != "feature_sets"})
            results["kfold"]["feature_sets"] = kf["feature_sets"]
        write_results(results)
        return 0
    if args.synthetic_only:
        results = json.loads(RESULTS.read_text())
        synthetic(results, args.quick)
        write_results(results)
        return 0
    if args.table1:
        results = json.loads(RESULTS.read_text())
        results["table1_by_seed"] = table1_by_seed([json.loads(Path(p).read_text()) for p in args.table1])
        write_results(results)
        return 0
    if args.update_folds:
        results = json.loads(RESULTS.read_text())
        saved = json.loads(Path(args.update_folds).read_text())
        results["kfold"] = saved.get("kfold", saved)
        write_results(results)
        return 0
    if not TILES.is_dir():
        print(f"bench/detector.py: {TILES} not found; nothing to measure", file=sys.stderr)
        return 0
    cv2.setNumThreads(1)
    models_dir = Path(args.models) if args.models else MODELS_DIR
    train_seconds = {}
    if args.train:
        models_dir = Path(tempfile.mkdtemp(prefix="detector_models_"))
        train_seconds = train_models(models_dir, args.quick)
    validation = read_yolo_folder(TILES, include=VALIDATION)
    validation = validation[::8 if args.quick else 3]   # every 3rd tile: the contour-only cascade is slow
    tiles = [item.load_colour() for item in validation[:6 if args.quick else 12]]
    crops = [t[80:560] for t in tiles]
    wide = []
    chase = DATA / "sot" / "CarChase2" / "img"
    if chase.is_dir():
        wide = [cv2.imread(str(p), cv2.IMREAD_COLOR) for p in sorted(chase.iterdir())[:3 if args.quick else 8]]

    results = {"validation_prefixes": VALIDATION, "validation_tiles": len(validation), "quick": args.quick,
               "train_seconds": train_seconds, "models_dir": str(models_dir), "detectors": {}}
    last_results = json.loads(RESULTS.read_text()) if RESULTS.is_file() else None
    previous = Path(args.folds_from) if args.folds_from else RESULTS
    if (args.no_folds or args.folds_from) and previous.is_file():
        saved = json.loads(previous.read_text()) if args.folds_from else last_results
        results["kfold"] = saved.get("kfold", saved)
    elif not args.no_folds:
        with tempfile.TemporaryDirectory(prefix="detector_folds_") as work:   # fold models are not kept
            results["kfold"] = kfold(("fused",) if args.quick else FEATURE_SETS, args.recipe, Path(work),
                                     "none" if args.quick else "crossfit",
                                     quick=args.quick)
    for key in ("box_regression", "table1_by_seed"):                # only --box-regression / --table1 remake them
        if last_results and key in last_results:
            results[key] = last_results[key]
    for fs in () if args.folds_only else FEATURE_SETS:
        model = models_dir / model_name(fs)
        if not model.is_file():
            print(f"bench/detector.py: no {model}; skipped", file=sys.stderr)
            continue
        det = detector_for(model)
        info = json.loads(model.read_text())
        op, op_all = evaluate(det, validation)
        pr, pr_all = evaluate(detector_for(model, min_neighbors=1), validation)
        precision, recall, score = (np.asarray(pr[k]) for k in ("pr_precision", "pr_recall", "pr_score"))
        ok = np.flatnonzero(precision >= 0.9)
        at10 = {"detection_rate": float(recall[ok].max()) if len(ok) else 0.0,
                "score_threshold": float(score[ok[np.argmax(recall[ok])]]) if len(ok) else None}
        meta = info.get("info", {})
        seen = [p for p in VALIDATION if (meta.get("include_prefix") is None or p in meta["include_prefix"])
                and p not in (meta.get("exclude_prefix") or [])]
        entry = {"model": str(model), "stages": len(info["stages"]), "validation_seen_in_training": seen,
                 "train_seconds": info.get("info", {}).get("train_seconds"),
                 "best_at_10pct_false_alarms": at10,
                 "stumps": sum(len(s["features"]) for s in info["stages"]),
                 "operating_point": {k: v for k, v in op.items() if not k.startswith("pr_")},
                 "operating_point_all_boxes": {k: v for k, v in op_all.items() if not k.startswith("pr_")},
                 "average_precision": pr["average_precision"], "average_precision_all_boxes": pr_all["average_precision"],
                 "pr_precision": pr["pr_precision"][::max(1, len(pr["pr_precision"]) // 400)],
                 "pr_recall": pr["pr_recall"][::max(1, len(pr["pr_recall"]) // 400)]}
        entry["speed_640x640"] = time_frames(det.detect, tiles)
        entry["speed_640x480"] = time_frames(det.detect, crops)
        if wide:
            entry["speed_1280x720"] = time_frames(det.detect, wide)
        if fs == "fused":   # the node's `threads` parameter: levels scanned at once on this machine's 2 cores
            entry["speed_640x480_2_threads"] = time_frames(detector_for(model, threads=2).detect, crops)
        results["detectors"][f"cascade ({fs})"] = entry
        print(f"{fs}: {entry['operating_point']['detection_rate']:.3f} detection rate, "
              f"{entry['operating_point']['false_alarm_rate']:.3f} false alarms, AP {entry['average_precision']:.3f}, "
              f"{entry['speed_640x480']['fps']:.1f} frames/s at 640x480", flush=True)

    det = cars_reference()
    if det is not None:
        cars = Path(det.config.model)
        entry = {"model": str(cars), "note": "third-party rear-view car Haar cascade: speed only",
                 "speed_640x480": time_frames(det.detect, crops), "speed_640x640": time_frames(det.detect, tiles)}
        if wide:
            entry["speed_1280x720"] = time_frames(det.detect, wide)
        video = video_frames(DATA / "cascades" / "video1.avi", 30 if args.quick else 200)
        det_native = Detector(DetectorConfig(backend="opencv", model=str(cars), scale_factor=1.1, min_neighbors=2))
        entry["speed_320x240_video1"] = time_frames(det_native.detect, video)
        results["detectors"]["OpenCV CascadeClassifier (cars.xml)"] = entry

    synthetic(results, args.quick)
    write_results(results)
    return 0


def synthetic(results: dict, quick: bool) -> None:
    """The set-ups of the synthetic cameras (``config/uav_camera.yaml``, ``config/stand_camera.yaml``) on one
    held-out scene each: ``results["synthetic"]``."""
    cv2.setNumThreads(1)
    results["synthetic"] = {}
    for kind, setup, seed, frames_, every in (("uav", "uav_camera.yaml", 106, 40, 8 if quick else 4),
                                              ("docking", "stand_camera.yaml", 105, 120, 12 if quick else 4)):
        det = setup_detector(setup)
        results["synthetic"][kind] = {"model": Path(det.config.model).name, "setup": setup, "seed": seed,
                                      **evaluate_synthetic(det, synthetic_items(kind, seed, frames_, every))}


def add_to_comparison(kfold_results: dict, kf: dict) -> None:
    """Put one recipe's k-fold run (its fused rows and per-fold figures; every feature set it ran) beside the
    others: ``recipe_comparison`` (fused, one row per recipe) and ``recipe_runs[recipe]`` (all feature sets)."""
    if kf.get("seed", 0):      # another training seed of a recipe: its spread, not a new row
        spread = kfold_results.setdefault("seed_runs", {}).setdefault(kf["recipe"], {})
        spread[str(kf["seed"])] = {fs: {k: e[k] for k in ("defaults", "at_choice", "pooled_average_precision",
                                                          "pooled_best_at_10pct_false_alarms", "choice_rule",
                                                          "rules") if k in e}
                                   for fs, e in kf["feature_sets"].items()}
        return
    runs = kfold_results.setdefault("recipe_runs", {})
    runs.setdefault(kf["recipe"], {}).update({fs: {k: v for k, v in e.items() if not k.startswith("pooled_pr_")}
                                              for fs, e in kf["feature_sets"].items()})
    if "fused" not in kf["feature_sets"]:
        return
    e = kf["feature_sets"]["fused"]
    row = {"recipe": kf["recipe"], "border_margin": kf.get("border_margin", 1.0), "options": RECIPES[kf["recipe"]],
           "choice_rule": e.get("choice_rule", "pooled"),
           "defaults": e["defaults"],
           "at_choice": e.get("at_choice"), "pooled_average_precision": e["pooled_average_precision"],
           "pooled_best_at_10pct_false_alarms": e["pooled_best_at_10pct_false_alarms"],
           "train_seconds": round(sum(f["train_seconds"] for f in e["folds"]), 1)}
    comparison = [r for r in kfold_results.get("recipe_comparison", [])
                  if (r["recipe"], r.get("border_margin", 1.0), r.get("choice_rule", "pooled"))
                  != (kf["recipe"], row["border_margin"], row["choice_rule"])]
    kfold_results["recipe_comparison"] = comparison + [row]


def table1_by_seed(runs: list) -> dict:
    """Seed 003's Table 1 from ``kfold`` runs of one recipe at several training seeds: per seed and feature set the
    pooled AP, the oracle detection at <= 10 % false alarms and each inner-choice rule's mean / worst."""
    recipes = {r["recipe"] for r in runs}
    if len(recipes) != 1:
        raise SystemExit(f"--table1 takes runs of one recipe, got {sorted(recipes)}")
    seeds = {}
    for r in runs:
        for fs, e in r["feature_sets"].items():
            seeds.setdefault(str(r["seed"]), {})[fs] = {
                "pooled_average_precision": e["pooled_average_precision"],
                "pooled_best_at_10pct_false_alarms": e["pooled_best_at_10pct_false_alarms"],
                "rules": {rule: {k: v for k, v in m.items() if k != "all_folds_choice"} for rule, m in e["rules"].items()}}
    return {"recipe": recipes.pop(), "scan": SETUP_SCAN, "train_args": runs[0]["train_args"], "seeds": seeds}


def table1_markdown(t1: dict) -> list[str]:
    """``table1_by_seed`` as a table, and how often fused is at least as good as each other feature set."""
    rows = ["### Seed 003 Table 1 with the drone-view set-up's scan, by training seed (issue 12, session 49)", "",
            f"The prefix folds above, each feature set trained by recipe `{t1['recipe']}` at each training seed, every "
            f"model scanned as config/detector.yaml scans (the colour blobs' views, {t1['scan']}; mean boxes, no "
            "regressor, for every feature set). *Oracle*: the best detection at <= 10 % false alarms on the pooled "
            "held-out PR curve, i.e. detection at equal false alarms. *Inner choice*: rule `worst-fold`, each fold's "
            "grouping chosen without it. Border-cut boxes ignored.", "",
            "| training seed | features | pooled AP | oracle det. at <= 10 % FA | inner choice mean det. / FA | "
            "inner choice worst det. / FA | folds meeting 0.90 / 0.10 |", "|---|---|---|---|---|---|---|"]
    for seed, sets in sorted(t1["seeds"].items()):
        for fs in FEATURE_SETS:
            if fs not in sets:
                continue
            e, c = sets[fs], sets[fs]["rules"]["worst-fold"]
            rows.append(f"| {seed} | {fs} | {e['pooled_average_precision']:.3f} | "
                        f"{e['pooled_best_at_10pct_false_alarms']['detection_rate']:.3f} | "
                        f"{c['mean_detection_rate']:.3f} / {c['mean_false_alarm_rate']:.3f} | "
                        f"{c['worst_detection_rate']:.3f} / {c['worst_false_alarm_rate']:.3f} | "
                        f"{c['folds_meeting_target']} of {len(FOLDS)} |")
    for other in FEATURE_SETS:
        pairs = [(sets["fused"], sets[other]) for sets in t1["seeds"].values() if other != "fused"
                 and "fused" in sets and other in sets]
        if pairs:
            oracle = sum(f["pooled_best_at_10pct_false_alarms"]["detection_rate"]
                         >= o["pooled_best_at_10pct_false_alarms"]["detection_rate"] for f, o in pairs)
            ap = sum(f["pooled_average_precision"] >= o["pooled_average_precision"] for f, o in pairs)
            inner = [(f["rules"]["worst-fold"], o["rules"]["worst-fold"]) for f, o in pairs]
            both = sum(f["mean_detection_rate"] >= o["mean_detection_rate"]
                       and f["mean_false_alarm_rate"] <= o["mean_false_alarm_rate"] for f, o in inner)
            rows += ["", f"Fused against {other}-only: detection at <= 10 % false alarms at least as high at {oracle} "
                     f"of {len(pairs)} training seeds, pooled AP at {ap} of {len(pairs)}; at the inner choice, at least "
                     f"as much detection at no more false alarms (means over the folds) at {both} of {len(pairs)}."]
    return rows + [""]


def write_results(results: dict) -> None:
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "plots").mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=1))
    (HERE / "results" / "detector.md").write_text(markdown(results, results.get("quick", False)))
    plots(results)
    print((HERE / "results" / "detector.md").read_text())


RULE_TEXT = {"worst-fold": "with the highest detection rate on the worst inner fold, every inner fold at <= 8 % "
                           "false alarms (rule `worst-fold`)",
             "pooled": "with the highest detection rate at <= 8 % false alarms over the inner folds' tiles pooled "
                       "(rule `pooled`)"}


def _rule_of(kf: dict) -> str:
    """The inner-choice rule of a k-fold result (results before the rule was recorded used ``pooled``)."""
    return next((e.get("choice_rule", "pooled") for e in kf.get("feature_sets", {}).values()), "pooled")


INNER_TEXT = {"model": "on the next fold, with a second model trained without it: strictly inside the training prefixes",
              "crossfit": "on the other folds' held-out windows, pooled: those tiles are training tiles of this fold, "
                          "but the models that scored them had this fold's tiles in their training set, a weak leak",
              "none": "not run"}


def kfold_markdown(kf: dict) -> list[str]:
    """The k-fold table: per feature set, every fold at the node defaults and at the inner choice."""
    ref = kf.get("reference_grouping", REFERENCE_GROUPING)
    rows = ["### Generalisation to unseen videos: k-fold by video prefix (issue 12)", "",
            f"Folds (each held out whole): {'; '.join('+'.join(f) for f in kf['folds'])}. Every fold's cascade is trained "
            f"on the other prefixes with recipe `{kf['recipe']}` (`train_cascade {' '.join(kf['train_args'])}`); "
            "Drone2_ held-out tiles thinned to every 3rd. Border-cut boxes ignored (closer than "
            f"{kf.get('border_margin', 1.0)} px to the tile border: the labels clip boxes 1 px inside the tile). "
            "*Reference*: grouping with "
            f"min_neighbors {ref['min_neighbors']}, window_margin {ref['window_margin']} (the node defaults before this "
            "protocol). *Inner choice*: min_neighbors and window_margin "
            + RULE_TEXT[_rule_of(kf)] + ", chosen without the held-out fold's tiles ("
            + INNER_TEXT.get(kf.get("inner"), "-") + "), then applied to the held-out fold. *Oracle*: best detection rate at <= 10 % false alarms "
            "on the held-out PR curve (not a usable setting, an upper bound). The node defaults are the choice over all "
            "four folds (below), so their held-out estimate is the inner-choice column.", "",
            "| features | fold held out | detection (reference) | false alarms (reference) | inner choice mn / margin | "
            "detection (inner) | false alarms (inner) | AP | oracle det. at <= 10 % FA |",
            "|---|---|---|---|---|---|---|---|---|"]
    for fs, e in kf["feature_sets"].items():
        for f in e["folds"]:
            d, c = f["defaults"], f.get("at_choice")
            ch = f.get("chosen")
            rows.append(f"| {fs} | {'+'.join(f['held_out'])} | {d['detection_rate']:.3f} | {d['false_alarm_rate']:.3f} | "
                        + (f"{ch['min_neighbors']} / {ch['window_margin']:+.1f} | {c['detection_rate']:.3f} | "
                           f"{c['false_alarm_rate']:.3f} |" if c else "- | - | - |")
                        + f" {f['average_precision']:.3f} | {f['best_at_10pct_false_alarms']['detection_rate']:.3f} |")
        for key, label in (("defaults", "reference"), ("at_choice", "inner choice")):
            if key in e:
                m = e[key]
                rows.append(f"| **{fs}** | **mean / worst ({label})** | {m['mean_detection_rate']:.3f} / "
                            f"**{m['worst_detection_rate']:.3f}** | {m['mean_false_alarm_rate']:.3f} / "
                            f"**{m['worst_false_alarm_rate']:.3f}** | folds meeting 0.90 / 0.10: "
                            f"{m['folds_meeting_target']} of {len(e['folds'])} | | | pooled AP "
                            f"{e['pooled_average_precision']:.3f} | {e['pooled_best_at_10pct_false_alarms']['detection_rate']:.3f} |")
    ruled = {fs: e for fs, e in kf["feature_sets"].items() if "rules" in e} or \
        {fs: e for fs, e in kf.get("recipe_runs", {}).get(SHIPPED_RECIPE, {}).items() if "rules" in e}
    if ruled:
        rows += ["", f"Inner-choice rules compared on the same fold models (recipe `{SHIPPED_RECIPE}`; each fold's grouping "
                 "chosen without it):", "",
                 "| features | rule | mean det. / FA | worst det. / worst FA | folds meeting 0.90 / 0.10 | "
                 "all-folds choice mn / margin |", "|---|---|---|---|---|---|"]
        for fs, e in ruled.items():
            for rule, m in e["rules"].items():
                c = m["all_folds_choice"]
                rows.append(f"| {fs} | `{rule}`{' (used)' if rule == e.get('choice_rule') else ''} | "
                            f"{m['mean_detection_rate']:.3f} / {m['mean_false_alarm_rate']:.3f} | "
                            f"{m['worst_detection_rate']:.3f} / {m['worst_false_alarm_rate']:.3f} | "
                            f"{m['folds_meeting_target']} of {len(e['folds'])} | "
                            f"{c['min_neighbors']} / {c['window_margin']:+.1f} |")
    choices = {fs: e["all_folds_choice"] for fs, e in kf["feature_sets"].items() if "all_folds_choice" in e}
    if choices:
        rows += ["", "Grouping chosen on all four folds' held-out windows (for a model trained on every prefix): "
                 + "; ".join(f"{fs} min_neighbors {c['min_neighbors']}, window_margin {c['window_margin']}"
                             for fs, c in choices.items()) + "."]
    if kf.get("recipe_comparison"):
        rows += ["", "Training recipes compared one change at a time (fused features, same folds; the shipped "
                 "recipe is the one with the better held-out figures):", "",
                 "| recipe | train_cascade options added | mean det. / FA (reference) | worst det. / worst FA (reference) | "
                 "inner-choice rule | mean det. / FA (inner choice) | worst det. / worst FA (inner choice) | pooled AP | "
                 "oracle det. at <= 10 % FA |",
                 "|---|---|---|---|---|---|---|---|---|"]
        for r in kf["recipe_comparison"]:
            d, c = r["defaults"], r.get("at_choice")
            old = " (border-cut test 1.0 px: the clipped boxes counted)" if r.get("border_margin", 1.0) < 1.5 else ""
            rows.append(f"| {r['recipe']}{old} | `{' '.join(r['options']) or '-'}` | {d['mean_detection_rate']:.3f} / "
                        f"{d['mean_false_alarm_rate']:.3f} | {d['worst_detection_rate']:.3f} / {d['worst_false_alarm_rate']:.3f} | "
                        f"`{r.get('choice_rule', 'pooled')}` | "
                        + (f"{c['mean_detection_rate']:.3f} / {c['mean_false_alarm_rate']:.3f} | {c['worst_detection_rate']:.3f} / "
                           f"{c['worst_false_alarm_rate']:.3f} |" if c else "- | - |")
                        + f" {r['pooled_average_precision']:.3f} | {r['pooled_best_at_10pct_false_alarms']['detection_rate']:.3f} |")
    table1 = kf.get("recipe_runs", {}).get(SHIPPED_RECIPE, {})
    if len(table1) > 1 and SHIPPED_RECIPE != kf.get("recipe"):
        rows += ["", f"Seed 003 Table 1 by the shipped recipe `{SHIPPED_RECIPE}` (same folds, each feature set's own "
                 "inner choice by rule `pooled`, the rule all three were run with):", "", "| features | mean det. / FA (inner choice) | worst det. / worst FA (inner choice) | "
                 "folds meeting 0.90 / 0.10 | pooled AP | oracle det. at <= 10 % FA |", "|---|---|---|---|---|---|"]
        for fs in FEATURE_SETS:
            if fs in table1 and table1[fs].get("at_choice"):
                e = table1[fs]
                c = e["rules"]["pooled"] if "rules" in e else e["at_choice"]
                rows.append(f"| {fs} | {c['mean_detection_rate']:.3f} / {c['mean_false_alarm_rate']:.3f} | "
                            f"{c['worst_detection_rate']:.3f} / {c['worst_false_alarm_rate']:.3f} | "
                            f"{c['folds_meeting_target']} of {len(e['folds'])} | {e['pooled_average_precision']:.3f} | "
                            f"{e['pooled_best_at_10pct_false_alarms']['detection_rate']:.3f} |")
    for recipe, seeds in kf.get("seed_runs", {}).items():
        base = kf.get("recipe_runs", {}).get(recipe, {}).get("fused")
        runs = ([("0", base)] if base else []) + [(k, v["fused"]) for k, v in sorted(seeds.items()) if "fused" in v]
        if len(runs) > 1:
            rows += ["", f"Spread over training seeds, recipe `{recipe}` (fused, inner choice): " + "; ".join(
                f"seed {k}: " + ", ".join(
                    f"rule `{rule}` mean {c['mean_detection_rate']:.3f} / {c['mean_false_alarm_rate']:.3f}, worst "
                    f"{c['worst_detection_rate']:.3f} / {c['worst_false_alarm_rate']:.3f}"
                    for rule, c in (e["rules"].items() if "rules" in e else [(e.get("choice_rule", "pooled"), e["at_choice"])]))
                + f", pooled AP {e['pooled_average_precision']:.3f}" for k, e in runs) + "."]
    if kf.get("note"):
        rows += ["", kf["note"]]
    return rows + [""]


def box_regression_markdown(runs: dict) -> list[str]:
    """The group box regressor on the prefix folds (``kfold_box_regression``), one row per fold and seed."""
    rows = ["### Group box regressor on the prefix folds (issue 12, sessions 9-10; shipped in config/detector.yaml)", "",
            "The fold models of recipe `photometric+negatives` (fused) at each training seed; per held-out fold a "
            "box regressor (`multi_target_tracker/box_regression.py`, the UAV set-up's: ridge regression of each edge "
            "of a group's mean box from its member windows' statistics) is trained on the held-out groups of the "
            "*other* folds' models (groups of >= 3 windows at every grid margin overlapping a counted box by IoU >= 0.3; "
            "those tiles are the fold's training tiles, scored by models that did not train on them, but those models "
            "saw the held-out fold's tiles: the crossfit leak of the inner choice). The grouping is chosen by rule "
            "`worst-fold` over the inner folds, each refined by a regressor trained without it and without the "
            "held-out fold. Every model scans as the drone-view set-up does (config/detector.yaml: since session 34 "
            f"also the colour blobs' views, {SETUP_SCAN}), and the regressors learn from those windows. "
            "*Node defaults*: min_neighbors / window_margin of config/detector.yaml. *Transferred*: "
            "fold k of a seed-1 or seed-2 model scored with the regressor trained on the *seed-0* models' groups "
            "without fold k: a regressor on the windows of a model it was not trained with, on tiles it did not see "
            "(the shipped regressor is the seed-0 one trained on all four folds, used with the shipped model, which "
            "trained on every prefix). Border-cut boxes ignored. Columns: detection / false alarms. Shipped since "
            "session 10 (`config/detector.yaml` `box_regressor: drone_vehicles_box_regressor.json`, the seed-0 "
            "regressor trained on all four folds; `--save-regressor`); the k-fold table and Table 1 above are without "
            "it for every feature set (one recipe and one grouping for all three: the comparison stays fair), as is "
            "the table of shipped models below.", "",
            "| seed | fold held out | mean box, inner choice (mn / margin) | regressed, inner choice (mn / margin) | "
            "regressed at the mean box's inner choice | mean box, node defaults | regressed, node defaults | "
            "transferred (seed-0 regressor), node defaults |",
            "|---|---|---|---|---|---|---|---|"]
    arms = (("mean box", "at_choice"), ("regressed", "at_choice"), ("regressed, mean-box grouping", "at_choice"),
            ("mean box", "at_node_defaults"), ("regressed", "at_node_defaults"), ("transferred", "at_node_defaults"))
    for key, run in sorted(runs.items()):
        if key == "speed_640x480":
            continue

        def cell(f, name, point):
            c = f[name][point]
            text = f"{c['detection_rate']:.3f} / {c['false_alarm_rate']:.3f}"
            if point == "at_choice" and name != "regressed, mean-box grouping":
                text += f" ({f[name]['chosen']['min_neighbors']} / {f[name]['chosen']['window_margin']:+.1f})"
            return text
        for f in run["folds"]:
            rows.append(f"| {run['seed']} | {'+'.join(f['held_out'])} | " + " | ".join(
                cell(f, name, point) if name in f else "-" for name, point in arms) + " |")
        rows.append(f"| **{run['seed']}** | **mean / worst** | " + " | ".join(
            "{mean_detection_rate:.3f} / {mean_false_alarm_rate:.3f}; **{worst_detection_rate:.3f} / "
            "{worst_false_alarm_rate:.3f}**; {folds_meeting_target} of 4 folds meet 0.90 / 0.10".format(
                **run["summary"][name][point]) if name in run["summary"] else "-" for name, point in arms) + " |")
    speed = runs.get("speed_640x480")
    if speed:
        rows += ["", f"Speed of the shipped fused model at the node defaults with and without the regressor "
                 f"(`{speed['regressor']}`), interleaved frame by frame over {speed['rounds']} rounds of the same "
                 f"{speed['frames']} 640x480 crops (each frame's best round), one thread, on the shared machine under "
                 f"load: {speed['regressed']['fps']:.1f} vs {speed['mean box']['fps']:.1f} frames/s (ratio "
                 f"{speed['ratio']:.2f}; the quiet-machine figure of the mean-box set-up is in the table below)."]
    return rows + [""]


def node_grouping_markdown(choice: dict) -> list[str]:
    """``node_grouping``'s choice of the drone-view node's grouping over the training seeds, and its held-out estimate."""
    def cells(m):
        return (f"{m['mean_detection_rate']:.3f} / {m['mean_false_alarm_rate']:.3f} | **{m['worst_detection_rate']:.3f} "
                f"/ {m['worst_false_alarm_rate']:.3f}** | {m['smallest_target_margin']:+.3f} | "
                f"{m['folds_meeting_target']} of {m['cells']}")
    seeds = ", ".join(str(s) for s in choice["seeds"])
    rows = ["### The drone-view node's grouping over training seeds (issue 12, session 49)", "",
            f"The fold models of the shipped recipe at training seeds {seeds} (the table above: each fold refined by "
            "its own regressor, trained without it). Every grid setting (min_neighbors x window_margin) is scored on "
            "every fold of every seed. Rule `margin`: the setting whose smallest margin to the target, min(det - 0.90, "
            "0.10 - FA), over all those folds is the largest (ties: higher mean detection); rule `worst-fold`: the "
            "inner choice's rule (the highest worst detection at <= 8 % false alarms everywhere). *All folds*: the "
            "setting a rule picks on every fold of every seed (the node's choice; not a held-out figure). *Held out*: "
            "fold k at the setting the rule picks on the other three folds of every seed (their regressors trained "
            "without fold k): the protocol's estimate for videos the choice did not see. Detection / false alarms, "
            "border-cut boxes ignored.", "",
            "| grouping | setting (min_neighbors / margin) | mean | worst | smallest margin | folds x seeds meeting "
            "0.90 / 0.10 |", "|---|---|---|---|---|---|"]
    for label, shown in choice["shown"].items():
        rows.append(f"| {label} | {shown['setting']} | {cells(shown)} |")
    for name, rule in choice["rules"].items():
        rows.append(f"| rule `{name}`, all folds | {rule['all_folds']['setting']} | {cells(rule['all_folds'])} |")
        settings = sorted({h["setting"] for h in rule["held_out"]["folds"]})
        rows.append(f"| rule `{name}`, held out | {', '.join(settings)} | {cells(rule['held_out'])} |")
    return rows + [""]


def markdown(results: dict, quick: bool) -> str:
    rows = ["## Detector (issue 5)", ""]
    if results.get("kfold"):
        rows += kfold_markdown(results["kfold"])
    if results.get("table1_by_seed"):
        rows += table1_markdown(results["table1_by_seed"])
    if results.get("box_regression"):
        rows += box_regression_markdown(results["box_regression"])
        choice = node_grouping(results["box_regression"])
        if choice:
            rows += node_grouping_markdown(choice)
    rows += ["### Shipped models: accuracy on prefixes 1_ and 4_ (the former split), speed", "",
            f"Validation: drone-view tiles with prefixes {', '.join(results['validation_prefixes'])} "
            f"({'every 8th' if quick else 'every 3rd'} tile: {results['validation_tiles']} tiles); a model trained on them too "
            "is marked (its figures are not held-out: see the k-fold table). Detection counts at IoU >= 0.5 with an unmatched box; false-alarm rate = false detections / "
            "all detections; boxes cut by the tile border ignored (rates over all boxes in brackets). "
            "The column at <= 10 % false alarms reads the validation PR curve at its best threshold on the "
            "detection score (an oracle choice, shown with that threshold; the operating point columns use the defaults). "
            "Speed: `Detector.detect` alone, one thread.", "",
            "| detector | stages / stumps | training [s] | detection rate | false-alarm rate | AP | detection rate at <= 10 % false alarms (threshold) | frames/s 640x480 | 640x640 | 1280x720 |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    base = None
    for name, e in results["detectors"].items():
        speed = lambda key: f"{e[key]['fps']:.1f}" if key in e else "-"  # noqa: E731
        if "operating_point" in e:
            op, opa = e["operating_point"], e["operating_point_all_boxes"]
            trained = f"{e['train_seconds']:.0f}" if e.get("train_seconds") else "-"
            label = name + (" (trained on these tiles too: not a held-out figure)"
                            if e.get("validation_seen_in_training") else "")
            rows.append(f"| {label} | {e['stages']} / {e['stumps']} | {trained} | {op['detection_rate']:.3f} "
                        f"({opa['detection_rate']:.3f}) | {op['false_alarm_rate']:.3f} ({opa['false_alarm_rate']:.3f}) | "
                        f"{e['average_precision']:.3f} ({e['average_precision_all_boxes']:.3f}) | "
                        f"{e['best_at_10pct_false_alarms']['detection_rate']:.3f} "
                        f"({e['best_at_10pct_false_alarms']['score_threshold'] or float('nan'):.2f}) | "
                        f"{speed('speed_640x480')} | {speed('speed_640x640')} | {speed('speed_1280x720')} |")
            if name == "cascade (fused)":
                base = e
        else:
            rows.append(f"| {name} | - | - | - | - | - | - | {speed('speed_640x480')} | {speed('speed_640x640')} | "
                        f"{speed('speed_1280x720')} |")
    cv = results["detectors"].get("OpenCV CascadeClassifier (cars.xml)")
    if base and cv:
        rows += ["", f"Speed ratio fused cascade / OpenCV cars.xml at 640x480 (same window sizes, both orientations): "
                 f"{base['speed_640x480']['fps'] / max(cv['speed_640x480']['fps'], 1e-9):.2f}. "
                 f"cars.xml on video1.avi 320x240 (its own setting, scale 1.1): "
                 f"{cv['speed_320x240_video1']['fps']:.1f} frames/s."]
    if base and "speed_640x480_2_threads" in base:
        rows += ["", f"Fused cascade at 640x480 with `threads: 2` (pyramid levels scanned at once): "
                 f"{base['speed_640x480_2_threads']['fps']:.1f} frames/s, "
                 f"{base['speed_640x480_2_threads']['fps'] / max(base['speed_640x480']['fps'], 1e-9):.2f}x one thread."]
    if results.get("synthetic"):
        rows += ["", "Synthetic scenes (held-out seeds, shipped models, each camera set-up's detector parameters):", "",
                 "| scene | model (set-up) | frames | detection rate | false-alarm rate | detections / frame | frames/s |",
                 "|---|---|---|---|---|---|---|"]
        for kind, e in results["synthetic"].items():
            rows.append(f"| {kind} seed {e['seed']} | {e['model']} ({e.get('setup', '-')}) | {e['frames']} | {e['detection_rate']:.3f} | "
                        f"{e['false_alarm_rate']:.3f} | {e['detections'] / max(e['frames'], 1):.1f} | {e['fps']:.1f} |")
        uav = results["synthetic"].get("uav", {})
        if "fraction_short_side_below_20px" in uav:
            p = uav["box_short_side_percentiles_5_25_50_75_95"]
            rows += ["", f"UAV scene vehicle sizes (boxes counted above): shorter box side 5/25/50/75/95th percentiles "
                     f"{' / '.join(f'{v:.0f}' for v in p)} px; {100 * uav['fraction_short_side_below_20px']:.0f} % below "
                     f"20 px, {100 * uav['fraction_short_side_below_32px']:.0f} % below 32 px. The set-up searches windows "
                     f"from {uav['searched_min_size']:.0f} px high (windows below 32 px are upsampled to the texture "
                     "window, which is slow). The UAV camera's height, its set-up and their held-out numbers: "
                     "bench/uav_detector.py."]
    if results.get("train_seconds"):
        rows += ["", "Training time [s]: " + ", ".join(f"{k} {v:.0f}" for k, v in results["train_seconds"].items())]
    return "\n".join(rows) + "\n"


def plots(results: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for name, e in results["detectors"].items():
        if "pr_recall" in e:
            ax.plot(e["pr_recall"], e["pr_precision"], label=f"{name} AP {e['average_precision']:.3f}")
            op = e["operating_point"]
            ax.plot(op["detection_rate"], 1 - op["false_alarm_rate"], "o", color=ax.lines[-1].get_color())
    ax.set_xlabel("recall (detection rate)")
    ax.set_ylabel("precision (1 - false-alarm rate)")
    ax.set_title("drone-view validation tiles (dot: trained cascade)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "plots" / "detector_pr.png", dpi=110)
    plt.close(fig)

    kf = results.get("kfold")
    if kf:
        fig, axes = plt.subplots(1, len(kf["feature_sets"]), figsize=(4.2 * len(kf["feature_sets"]), 4.0), squeeze=False)
        for ax, (fs, e) in zip(axes[0], kf["feature_sets"].items()):
            ax.plot(e["pooled_pr_recall"], e["pooled_pr_precision"], "k-", lw=1.5,
                    label=f"pooled AP {e['pooled_average_precision']:.3f}")
            for f in e["folds"]:
                d = f["defaults"]
                ax.plot(d["detection_rate"], 1 - d["false_alarm_rate"], "o", label=f"{'+'.join(f['held_out'])}")
                if "at_choice" in f:
                    c = f["at_choice"]
                    ax.plot(c["detection_rate"], 1 - c["false_alarm_rate"], "^", color=ax.lines[-1].get_color())
            ax.axhline(0.9, color="r", lw=0.8, ls="--")
            ax.axvline(0.9, color="r", lw=0.8, ls="--")
            ax.set_xlim(0, 1)
            ax.set_ylim(0, 1.02)
            ax.set_title(f"{fs}: held-out folds (o reference grouping, ^ inner choice)", fontsize=9)
            ax.set_xlabel("recall (detection rate)")
            ax.grid(alpha=0.3)
            ax.legend(loc="lower left", fontsize=7)
        axes[0][0].set_ylabel("precision (1 - false-alarm rate)")
        fig.tight_layout()
        fig.savefig(HERE / "plots" / "detector_kfold_pr.png", dpi=110)
        plt.close(fig)

    names = list(results["detectors"])
    keys = ["speed_640x480", "speed_640x640", "speed_1280x720"]
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    grouped_bars(ax, [n.replace("OpenCV CascadeClassifier", "OpenCV") for n in names],
                 {key.replace("speed_", ""): [results["detectors"][n].get(key, {}).get("fps", 0.0) for n in names]
                  for key in keys}, fontsize=8)
    ax.axhline(15, color="k", lw=0.8, ls="--")
    ax.set_ylabel("frames/s, one thread")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "plots" / "detector_speed.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
