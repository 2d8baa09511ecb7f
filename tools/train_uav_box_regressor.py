"""Train the UAV set-up's box regressor (multi_target_tracker/box_regression.py) and choose its operating point.

    python tools/train_uav_box_regressor.py [--out multi_target_tracker/models/uav_vehicles_box_regressor.json]

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
from multi_target_tracker.box_regression import edge_offsets, fit_box_regressor, member_features  # noqa: E402
from multi_target_tracker.detector import MODELS_DIR, Detector, group_members, members_stats  # noqa: E402
from train_uav_verifier import (  # noqa: E402
    TUNING, cascade_detector, operating_point, scene_frames, setup_verifier, training_scenes)


def samples(det: Detector, seeds) -> tuple[np.ndarray, np.ndarray]:
    """Box regression features and targets of the groups of ``seeds`` (see the module docstring)."""
    cfg = det.config
    rows, targets = [], []
    for seed, difficulty in seeds:
        for bgr, truth, ignore in scene_frames(seed, difficulty, 4):
            counted = truth[~ignore]
            members = group_members(*det.raw(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)), cfg.group_iou)
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(MODELS_DIR / "uav_vehicles_box_regressor.json"))
    parser.add_argument("--train-scenes", type=int, default=30, help="training scenes of difficulty 1 (half as "
                        "many of difficulty 2)")
    parser.add_argument("--l2", type=float, default=100.0)
    parser.add_argument("--min-neighbors", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--containment", type=float, nargs="+", default=[0.4, 0.5])
    args = parser.parse_args()
    cv2.setNumThreads(1)
    det = cascade_detector({"box_scale": 1.0})
    train = training_scenes(args.train_scenes)
    x, y = samples(det, train)
    regressor = fit_box_regressor(x, y, args.l2)
    regressor.info.update({"train_seeds": [s for s, _ in train], "cascade": Path(det.config.model).name,
                           "window_margin": det.config.window_margin, "group_iou": det.config.group_iou,
                           "min_windows": det.config.min_neighbors})
    out = Path(args.out)
    regressor.save(out)
    det.verifier = setup_verifier()
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
