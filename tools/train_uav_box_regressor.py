"""Train the UAV set-up's box regressor (multi_target_tracker/box_regression.py) and choose its operating point.

    python tools/train_uav_box_regressor.py [--out multi_target_tracker/models/uav_vehicles_box_regressor.json]
    python tools/train_uav_box_regressor.py --image-stages 2     # the shipped uav_vehicles_box_regressor_image.json

1. **Training** (``UAV_TRAIN_SEEDS`` only: the verifier's training scenes, every 4th frame): the set-up's cascade
   (config/uav_camera.yaml's model, window margin and grouping); every group of at least the set-up's
   ``min_neighbors`` windows that overlaps a counted vehicle (>= 70 % visible) by IoU >= 0.3 is a sample, its
   target the offsets of that vehicle's box edges from the group's mean box; ridge regression on
   ``box_regression.FEATURES``.
2. **Operating point** (``UAV_TUNING_SEEDS`` only, every 4th frame as bench/uav_detector.py): the detector with
   the set-up's verifier and the new regressor (``box_scale`` 1: the regression places the box), for each
   ``containment`` of ``--containment`` and ``min_neighbors`` of ``--min-neighbors`` the verifier threshold of
   best detection minus false alarms pooled (``train_uav_verifier.operating_point``); the best is written into
   the model's ``info`` (copy it into config/uav_camera.yaml). The evaluation seeds are not touched.

``--set KEY=JSON`` (repeatable) overrides a detector parameter of the set-up in every scan, as in
tools/train_uav_verifier.py (e.g. another cascade's ``model``, or with ``--image-stages`` the regressor to extend).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

from aircraft_docking_tracker.geometry import box_iou  # noqa: E402
from multi_target_tracker.box_regression import (  # noqa: E402
    edge_offsets, fit_box_regressor, fit_image_stage, image_stage_features, member_features)
from multi_target_tracker.detector import MODELS_DIR, Detector, members_stats  # noqa: E402
from train_uav_verifier import (  # noqa: E402
    TUNING, cascade_detector, operating_point, parse_overrides, scene_frames, setup_detector, setup_verifier,
    training_scenes)


def samples(det: Detector, seeds) -> tuple[np.ndarray, np.ndarray]:
    """Box regression features and targets of the groups of ``seeds`` (see the module docstring)."""
    cfg = det.config
    rows, targets = [], []
    for seed, difficulty in seeds:
        for bgr, truth, ignore in scene_frames(seed, difficulty, 4):
            counted = truth[~ignore]
            members = det.members(det.raw(bgr))
            kept, group_boxes, *_ = members_stats(*members, cfg.window_margin, cfg.min_neighbors)
            if not len(group_boxes) or not len(counted):
                continue
            iou = box_iou(group_boxes[:, None], counted[None])
            near = iou.max(axis=1) >= 0.3
            rows.append(member_features(*members[:3], kept[near], group_boxes[near], cfg.window_margin,
                                        bgr.shape[1::-1]))
            targets.append(edge_offsets(group_boxes[near], counted[iou[near].argmax(axis=1)]))
        print(f"training seed {seed}: {sum(len(t) for t in targets)} groups so far", flush=True)
    return np.vstack(rows), np.vstack(targets)


CROP_GROW = 3.0


def published_groups(det: Detector, seeds, every: int) -> list[tuple]:
    """``(crop, boxes, member features, target boxes, on a vehicle)`` per frame of ``seeds``: the groups the set-up
    publishes, their boxes in a crop of CROP_GROW x the box (as :meth:`Detector._verified` gives them before the
    image stages), each one's counted vehicle (>= 30 % visible) of best IoU and whether that IoU is >= 0.3."""
    cfg = det.config
    floor = cfg.verifier_threshold - cfg.low_confidence_band
    out = []
    for seed, difficulty in seeds:
        for bgr, truth, ignore in scene_frames(seed, difficulty, every, min_visible=0.3):
            refined, logit, regression = det._candidates(bgr, det.raw(bgr), cfg.window_margin)
            keep = logit >= floor
            counted = truth[~ignore]
            if not keep.any() or not len(counted):
                continue
            iou = box_iou(refined[keep][:, None], counted[None])
            target, near = counted[iou.argmax(axis=1)], iou.max(axis=1) >= 0.3
            for box, features, t, n in zip(refined[keep], regression[keep], target, near):
                x0, y0 = (int(v) for v in np.floor(box[:2] + box[2:] / 2 - CROP_GROW * box[2:] / 2))
                x1, y1 = (int(v) for v in np.ceil(box[:2] + box[2:] / 2 + CROP_GROW * box[2:] / 2))
                x0, y0 = max(x0, 0), max(y0, 0)
                origin = np.array([x0, y0, 0.0, 0.0])
                out.append((bgr[y0:max(y1, y0 + 1), x0:max(x1, x0 + 1)].copy(), box - origin, features, t - origin, n))
        print(f"seed {seed}: {len(out)} published groups so far", flush=True)
    return out


def image_stage_iou(stages, groups) -> tuple[np.ndarray, np.ndarray]:
    """The groups' IoU with their target vehicle before and after ``stages``."""
    before, after = [], []
    for crop, box, features, target, _ in groups:
        before.append(box_iou(box, target))
        box = box[None]
        for stage in stages:
            box = stage.refine(crop, box, features[None])
        after.append(box_iou(box[0], target))
    return np.array(before), np.array(after)


def train_image_stages(args, overrides: dict) -> int:
    """``--image-stages``: see the module docstring."""
    det = setup_detector(overrides)
    regressor = det.box_regressor
    train = training_scenes(args.train_scenes)
    groups = published_groups(det, train, 2)
    near = np.array([g[4] for g in groups])
    boxes = np.array([g[1] for g in groups])
    targets = np.array([g[3] for g in groups])
    regressor.image_stages = []
    for k in range(args.image_stages):
        x = np.vstack([image_stage_features(crop, box[None], f[None], args.grow, args.size)
                       for (crop, _, f, _, _), box in zip(groups, boxes)])
        stage = fit_image_stage(x[near], edge_offsets(boxes[near], targets[near]), args.grow, args.size, args.image_l2)
        regressor.image_stages.append(stage)
        boxes = np.vstack([stage.refine(crop, box[None], f[None]) for (crop, _, f, _, _), box in zip(groups, boxes)])
        iou = box_iou(boxes[near], targets[near])
        print(f"stage {k + 1}: training groups on a vehicle at IoU >= 0.5 {np.mean(iou >= 0.5):.3f}", flush=True)
    tuning = published_groups(det, TUNING, 4)
    before, after = image_stage_iou(regressor.image_stages, tuning)
    on = before >= 0.1
    regressor.info["image_stages"] = {
        "train_seeds": [s for s, _ in train], "train_groups": int(near.sum()), "grow": args.grow, "size": args.size,
        "l2": args.image_l2, "tuning_seeds": [s for s, _ in TUNING],
        "tuning_groups_on_a_vehicle": int(on.sum()),
        "tuning_iou_at_least_0.5_before_after": [int((before[on] >= 0.5).sum()), int((after[on] >= 0.5).sum())],
        "tuning_mean_iou_before_after": [round(float(before[on].mean()), 4), round(float(after[on].mean()), 4)]}
    regressor.save(args.out)
    print(f"wrote {args.out}: {regressor.info['image_stages']}")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=None, help="default multi_target_tracker/models/"
                        "uav_vehicles_box_regressor.json (with --image-stages uav_vehicles_box_regressor_image.json)")
    parser.add_argument("--train-scenes", type=int, default=30, help="training scenes of difficulty 1 (half as "
                        "many of difficulty 2)")
    parser.add_argument("--l2", type=float, default=100.0)
    parser.add_argument("--min-neighbors", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--containment", type=float, nargs="+", default=[0.4, 0.5])
    parser.add_argument("--image-stages", type=int, default=0, help="add this many image stages to the set-up's "
                        "regressor instead (see above)")
    parser.add_argument("--grow", type=float, default=1.3, help="image stages: region grown this many times")
    parser.add_argument("--size", type=int, default=32, help="image stages: region resampled to size x size px")
    parser.add_argument("--image-l2", type=float, default=30.0, help="image stages: ridge penalty")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=JSON",
                        help="override a detector parameter of the set-up in every scan (repeatable)")
    args = parser.parse_args()
    overrides = parse_overrides(args.set)
    cv2.setNumThreads(1)
    if args.image_stages:
        args.out = args.out or str(MODELS_DIR / "uav_vehicles_box_regressor_image.json")
        return train_image_stages(args, overrides)
    args.out = args.out or str(MODELS_DIR / "uav_vehicles_box_regressor.json")
    det = cascade_detector({"box_scale": 1.0, **overrides})
    train = training_scenes(args.train_scenes)
    x, y = samples(det, train)
    regressor = fit_box_regressor(x, y, args.l2)
    regressor.info.update({"train_seeds": [s for s, _ in train], "cascade": Path(det.config.model).name,
                           "window_margin": det.config.window_margin, "group_iou": det.config.group_iou,
                           "min_windows": det.config.min_neighbors})
    out = Path(args.out)
    regressor.save(out)
    det.verifier = setup_verifier(overrides)
    det.box_regressor = regressor
    base, best = det.config, None
    for containment in args.containment:
        det.config = dataclasses.replace(base, containment=containment)
        point = {"containment": containment, **operating_point(det, TUNING, args.min_neighbors)}
        if best is None or point["detection"] - point["false_alarms"] > best["detection"] - best["false_alarms"]:
            best = point
    regressor.info["operating_point"] = best
    regressor.info["tuning_seeds"] = [s for s, _ in TUNING]
    regressor.save(out)
    print(f"wrote {out}: {regressor.info['samples']} groups; operating point {best}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
