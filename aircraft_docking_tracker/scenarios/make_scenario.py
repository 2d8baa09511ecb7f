"""``make_scenario``: write a synthetic docking or UAV scene as an MCAP bag with ground truth.

    make_scenario --kind docking --seed 3 --out docking3.mcap [--width 1280 --height 720 --fps 20]
    make_scenario --kind uav --seed 7 --out uav7.mcap --detections [--difficulty 2]

Topics (every message stamped with its frame's time, frame_id "camera"):
docking: ``image``, ``ground_truth/polygon``, ``ground_truth/nose``, ``ground_truth/guidance`` (one
``GUIDANCE_DTYPE`` row: the exact distance to go, lateral offset, closing speed and the state a perfect
guidance shows), ``ground_truth/stand`` (once); ``--stand-file`` also writes the stand's calibration file;
uav: ``image``, ``ground_truth`` (TRACK_DTYPE rows, see ``scenarios.uav``), and with
``--detections`` also ``detections`` synthesised from the ground truth.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from aircraft_docking_tracker.io.bag import BagWriter
from aircraft_docking_tracker.config import ConfigError, add_config_arguments, config_from_arguments
from aircraft_docking_tracker.scenarios import messages as m
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
from aircraft_docking_tracker.scenarios.strips import frame_strip
from aircraft_docking_tracker.scenarios.uav import UavScene, UavSceneConfig, synthesize_detections


def write_docking_bag(scene: DockingScene, path: str | Path, progress: bool = True, overwrite: bool = False,
                      keep_every: int = 0) -> dict:
    """Render ``scene`` into a bag at ``path``; returns a summary (and every ``keep_every``-th frame)."""
    from aircraft_docking_tracker.docking.guidance import true_guidance  # noqa: PLC0415

    kept = []
    guidance = true_guidance(*scene.guidance_truth().T)
    with BagWriter(path, overwrite=overwrite) as bag:
        for frame in tqdm(scene.frames(), total=scene.config.frames, desc=f"docking seed {scene.seed}",
                          disable=not progress, unit="frame"):
            hdr = m.header(frame.stamp_ns)
            if frame.index == 0:
                bag.write(m.GT_STAND, m.string_msg(scene.stand_json()), frame.stamp_ns)
            bag.write(m.IMAGE, m.image_msg(frame.image, hdr), frame.stamp_ns)
            bag.write(m.GT_POLYGON, m.quad_to_polygon(frame.quad, hdr), frame.stamp_ns)
            bag.write(m.GT_NOSE, m.point_msg(frame.nose, hdr), frame.stamp_ns)
            bag.write(m.GT_GUIDANCE, m.cloud_msg(guidance[frame.index:frame.index + 1], hdr), frame.stamp_ns)
            if keep_every and frame.index % keep_every == 0:
                kept.append(frame)
        counts = bag.topic_counts
    return {"path": str(path), "kind": "docking", "seed": scene.seed, "topics": counts, "kept": kept}


def write_uav_bag(scene: UavScene, path: str | Path, detections: bool = False, miss_rate: float = 0.05,
                  clutter_rate: float = 0.5, jitter_px: float = 2.0, progress: bool = True,
                  overwrite: bool = False, keep_every: int = 0) -> dict:
    """Render ``scene`` into a bag at ``path`` (optionally with synthesised detections)."""
    cfg = scene.config
    rng = np.random.default_rng([scene.seed, 5])
    kept = []
    with BagWriter(path, overwrite=overwrite) as bag:
        for frame in tqdm(scene.frames(), total=cfg.frames, desc=f"uav seed {scene.seed}",
                          disable=not progress, unit="frame"):
            hdr = m.header(frame.stamp_ns)
            bag.write(m.IMAGE, m.image_msg(frame.image, hdr), frame.stamp_ns)
            bag.write(m.GROUND_TRUTH, m.cloud_msg(frame.ground_truth, hdr), frame.stamp_ns)
            if detections:
                dets = synthesize_detections(frame.ground_truth, rng, miss_rate, clutter_rate, jitter_px,
                                             (cfg.width, cfg.height), cfg.hidden_below)
                bag.write(m.DETECTIONS, m.cloud_msg(dets, hdr), frame.stamp_ns)
            if keep_every and frame.index % keep_every == 0:
                kept.append(frame)
        counts = bag.topic_counts
    return {"path": str(path), "kind": "uav", "seed": scene.seed, "topics": counts, "kept": kept}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="make_scenario", description=__doc__.split("\n")[0],
                                     conflict_handler="resolve")
    parser.add_argument("--kind", required=True, choices=["docking", "uav"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True, help="output .mcap file (or bag directory)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing output")
    parser.add_argument("--detections", action="store_true", help="uav: also write synthesised detections")
    parser.add_argument("--miss-rate", type=float, default=0.05, help="uav detections: probability of a miss")
    parser.add_argument("--clutter-rate", type=float, default=0.5, help="uav detections: false alarms per frame")
    parser.add_argument("--jitter", type=float, default=2.0, help="uav detections: corner jitter [px]")
    parser.add_argument("--strip", help="also write a PNG strip of 6 frames with the ground truth drawn")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--stand-file", help="docking: also write the stand's calibration file (YAML) here, as a "
                        "surveyor would (ten apron marks clicked to 0.5 px, the lead-in line, the aircraft type)")
    add_config_arguments(parser, DockingSceneConfig)
    add_config_arguments(parser, UavSceneConfig)
    # options both kinds share, with both defaults in the help (these replace the per-kind ones)
    parser.add_argument("--fps", type=float, default=None,
                        help="camera frame rate [Hz] (default: docking 14, seed 000's camera; uav 25)")
    parser.add_argument("--difficulty", type=int, default=None, choices=[0, 1, 2],
                        help="0 easy, 1 normal, 2 hard: noise, weather, occlusion, vehicles, hiding (default 1)")
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    try:
        if args.kind == "docking":
            scene = DockingScene(config_from_arguments(DockingSceneConfig, args), args.seed)
            keep = max(1, scene.config.frames // 6) if args.strip else 0
            result = write_docking_bag(scene, args.out, not args.quiet, args.overwrite, keep)
            if args.stand_file:
                from aircraft_docking_tracker.docking.stand import stand_file_text  # noqa: PLC0415

                Path(args.stand_file).write_text(stand_file_text(scene.stand_calibration()))
        else:
            scene = UavScene(config_from_arguments(UavSceneConfig, args), args.seed)
            keep = max(1, scene.config.frames // 6) if args.strip else 0
            result = write_uav_bag(scene, args.out, args.detections, args.miss_rate, args.clutter_rate,
                                   args.jitter, not args.quiet, args.overwrite, keep)
    except (ConfigError, ValueError) as exc:
        print(f"make_scenario: {exc}", file=sys.stderr)
        return 2
    if args.strip:
        frame_strip(result["kept"][:6], args.strip)
    counts = ", ".join(f"{k}: {v}" for k, v in sorted(result["topics"].items()))
    print(f"wrote {args.out} ({counts})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
