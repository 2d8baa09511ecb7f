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

``--heading`` (the heading-aligned model, ``uav_vehicles_heading.json``): the frames are written with
*every* vehicle as class 1 (ignored; the frames give the hard negatives only), and each counted vehicle
(>= 70 % visible, not cut by the border) also gives ``--turns`` chips ``images/cSEED_fFRAME_vID_k.png``:
the frame turned about the vehicle's centre so that its long axis (from the scene's own corners under
the frame's homography) lies along x, give or take a random turn of up to ``--turn-jitter`` degrees
(the detector scans at 45-degree steps: ``DetectorConfig.angles``), cut twice the size of the window
box around it; the box (class 0) is the vehicle's length x width reshaped to 2:1 (same area) and
enlarged ``--context`` times. A vehicle at any heading then looks alike in the window: along it, with
its outline, tracks or windows at the same places, which the upright 3:2 windows never showed.
``--partly-visible V`` adds such chips (``pSEED_...``) of the vehicles from V to 70 % visible, partly under canopy
or smoke, each boxed as the whole vehicle (occlusion as the scenes make it; measured in docs/uav_camera.md).
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
from multi_target_tracker.train_cascade import truncated  # noqa: E402
from multi_target_tracker.heading import chip_height, turned_canvas  # noqa: E402

WINDOW_ASPECT = 1.5
HEADING_ASPECT = 2.0


def vehicle_axes(scene: UavScene, vehicle: int, t: int, homography: np.ndarray):
    """Image centre (x, y), length, width [px] and heading [deg, image x towards y] of one vehicle."""
    sh, sw = scene.sprites[vehicle][1].shape
    corners = np.array([[0, 0], [sw, 0], [sw, sh], [0, sh]], np.float64)
    a = scene.vehicle_affine(vehicle, t)
    world = corners @ a[:2, :2].T + a[:2, 2]
    img = cv2.perspectiveTransform(world[None], homography)[0]
    along, across = img[1] - img[0], img[3] - img[0]
    return img.mean(axis=0), float(np.hypot(*along)), float(np.hypot(*across)), float(np.degrees(np.arctan2(along[1], along[0])))


def heading_chip(image: np.ndarray, centre, length: float, width: float, heading: float, context: float):
    """``image`` turned about ``centre`` by ``heading`` (the vehicle along x), cut twice the window box's size
    around it: ``(chip, box x, y, w, h in the chip)``."""
    bh = chip_height(length, width, HEADING_ASPECT, context)
    bw = HEADING_ASPECT * bh
    cw, ch = int(round(2 * bw)), int(round(2 * bh))
    chip, _ = turned_canvas(image, centre, heading, (cw, ch))
    return chip, np.array([(cw - bw) / 2, (ch - bh) / 2, bw, bh])


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
    parser.add_argument("--context", type=float, default=None, help="vehicle windows enlarged this much about their "
                        "centre (ground around the vehicle; default 1.3, with --heading 1.25)")
    parser.add_argument("--every", type=int, default=16, help="write every k-th frame (the middle one of each k)")
    parser.add_argument("--heading", action="store_true", help="heading-aligned chips as the positives, the frames "
                        "(every vehicle ignored) as the negatives; see the module docstring")
    parser.add_argument("--turns", type=int, default=2, help="--heading: chips per vehicle and frame")
    parser.add_argument("--turn-jitter", type=float, default=22.5, help="--heading: chips turned up to this many "
                        "degrees off the vehicle's axis (half the detector's angle step)")
    parser.add_argument("--partly-visible", type=float, default=None, metavar="V",
                        help="--heading: also chips (pSEED_...) of the vehicles from V to 70 %% visible, partly under "
                        "canopy or smoke, boxed as the whole vehicle; drawn from their own random stream, so the "
                        "counted vehicles' chips stay the same")
    args = parser.parse_args(argv)
    if args.context is None:     # the shipped models': 1.3 (upright, uav_vehicles_low), 1.25 (heading-aligned)
        args.context = 1.25 if args.heading else 1.3
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
        scene = UavScene(config, seed=seed)
        rng = np.random.default_rng([seed, 7])
        rng_partly = np.random.default_rng([seed, 8])
        for k, frame in enumerate(scene.frames()):
            if k % args.every != args.every // 2:
                continue
            size = (frame.image.shape[1], frame.image.shape[0])
            boxes, ignore = detection_truth(frame.ground_truth)
            name = f"s{seed:04d}_f{k:03d}"
            if args.heading:
                lines = [yolo_line(1, b, size) for b in boxes]
                counted = ~ignore & ~truncated(boxes, size)
                chips = [("c", rng, counted)]
                if args.partly_visible is not None:
                    partly = ignore & ~detection_truth(frame.ground_truth, args.partly_visible)[1] & ~truncated(boxes, size)
                    chips.append(("p", rng_partly, partly))
                for prefix, stream, chosen in chips:
                    for vid in frame.ground_truth["id"][chosen]:
                        centre, length, width, heading = vehicle_axes(scene, int(vid) - 1, k, frame.homography)
                        for turn in range(args.turns):
                            chip, box = heading_chip(frame.image, centre, length, width,
                                                     heading + stream.uniform(-args.turn_jitter, args.turn_jitter),
                                                     args.context)
                            chip_name = f"{prefix}{seed:04d}_f{k:03d}_v{int(vid):02d}_{turn}"
                            cv2.imwrite(str(out / "images" / f"{chip_name}.png"), chip)
                            (out / "labels" / f"{chip_name}.txt").write_text(
                                yolo_line(0, box, (chip.shape[1], chip.shape[0])) + "\n")
                            positives += 1
            else:
                lines = [yolo_line(1, b, size) if ig else yolo_line(0, window_box(b, context=args.context), size)
                         for b, ig in zip(boxes, ignore)]
                positives += int((~ignore).sum())
            cv2.imwrite(str(out / "images" / f"{name}.png"), frame.image)
            (out / "labels" / f"{name}.txt").write_text("".join(line + "\n" for line in lines))
    print(f"{len(seeds)} scenes, {positives} {'heading-aligned chips' if args.heading else 'vehicle boxes'} "
          f"(class 0) in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
