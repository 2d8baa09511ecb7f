"""Training frames of the UAV cascade as a YOLO folder (offline; the data itself is not in the repo).

    python tools/uav_training_data.py OUT [--seeds 1000 1299] [--ground-resolution 3.0] [--frames 80] [--every 16]

For each training seed (``UAV_TRAIN_SEEDS`` only: disjoint from the tuning and evaluation seeds),
a UAV scene at the set-up's camera height; difficulty cycles 1, 2, 1, 2, 0 by seed (canopy, smoke
and look-alike clutter of every kind), every ``every``-th frame written as ``images/sSEED_fFRAME.png``
with ``labels/*.txt``:

* class 0: a vehicle at least 70 % visible, its box reshaped to the cascade window's 3:2 aspect
  (same centre and area; the scan only ever sees windows of that shape), then enlarged ``context``
  times about its centre: the window then holds the vehicle's outline against the ground around
  it, which tells a camouflaged vehicle from the inside of a tree canopy of the same texture (the
  detector's ``box_scale`` takes the context off again);
* class 1: every other vehicle (hidden or partly hidden under trees or smoke): train with
  ``--ignore-class-ids 1``, so it is neither a positive nor cut as a negative.

Everything else in the frame (canopy, smoke, roads, roofs, containers, bushes) is background, which
``train_cascade`` mines for hard negatives stage by stage (bootstrapping over all the frames).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from aircraft_docking_tracker.scenarios.uav import (  # noqa: E402
    UAV_SETUP_GROUND_RESOLUTION, UAV_TRAIN_SEEDS, UavScene, UavSceneConfig, detection_truth)

WINDOW_ASPECT = 1.5


def window_box(box, aspect: float = WINDOW_ASPECT, context: float = 1.0) -> np.ndarray:
    """``box`` x, y, w, h reshaped to ``aspect`` along its longer side (same centre and area), then
    scaled ``context`` times about its centre."""
    x, y, w, h = (float(v) for v in box)
    a = aspect if w >= h else 1.0 / aspect
    nw, nh = np.sqrt(w * h * a) * context, np.sqrt(w * h / a) * context
    return np.array([x + (w - nw) / 2, y + (h - nh) / 2, nw, nh])


def yolo_line(cls: int, box, size: tuple[int, int]) -> str:
    x, y, w, h = box
    width, height = size
    return f"{cls} {(x + w / 2) / width:.6f} {(y + h / 2) / height:.6f} {w / width:.6f} {h / height:.6f}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", help="output folder (images/ + labels/)")
    parser.add_argument("--seeds", nargs=2, type=int, default=[1000, 1299], metavar=("FIRST", "LAST"))
    parser.add_argument("--ground-resolution", type=float, default=UAV_SETUP_GROUND_RESOLUTION)
    parser.add_argument("--frames", type=int, default=80, help="frames per scene (as long as the demo's: the "
                        "canopies that hide a vehicle grow with the scene's length, and they are the hardest negatives)")
    parser.add_argument("--context", type=float, default=1.3, help="vehicle windows enlarged this much about their "
                        "centre (ground around the vehicle)")
    parser.add_argument("--every", type=int, default=16, help="write every k-th frame (the middle one of each k)")
    args = parser.parse_args(argv)
    seeds = range(args.seeds[0], args.seeds[1] + 1)
    if seeds.start not in UAV_TRAIN_SEEDS or seeds[-1] not in UAV_TRAIN_SEEDS:
        parser.error(f"training seeds must lie in {UAV_TRAIN_SEEDS} (tuning and evaluation seeds are kept out)")
    out = Path(args.out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "labels").mkdir(parents=True, exist_ok=True)
    positives = 0
    for seed in seeds:
        config = UavSceneConfig(frames=args.frames, difficulty=(1, 2, 1, 2, 0)[seed % 5],
                                ground_resolution=args.ground_resolution)
        for k, frame in enumerate(UavScene(config, seed=seed).frames()):
            if k % args.every != args.every // 2:
                continue
            size = (frame.image.shape[1], frame.image.shape[0])
            boxes, ignore = detection_truth(frame.ground_truth)
            lines = [yolo_line(1, b, size) if ig else yolo_line(0, window_box(b, context=args.context), size) for b, ig in zip(boxes, ignore)]
            positives += int((~ignore).sum())
            name = f"s{seed:04d}_f{k:03d}"
            cv2.imwrite(str(out / "images" / f"{name}.png"), frame.image)
            (out / "labels" / f"{name}.txt").write_text("".join(line + "\n" for line in lines))
    print(f"{len(seeds)} scenes, {positives} vehicle boxes (class 0) in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
