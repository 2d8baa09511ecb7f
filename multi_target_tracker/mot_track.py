"""``mot_track``: the association core over a MOTChallenge ``det.txt``, writing MOTChallenge results.

    mot_track DET.txt -o results.txt [--fps 25 | --seqinfo seqinfo.ini] [--min-score 0.3] [--gt gt.txt]
              [--score-scale 100]
              [--no-coasting] [--backfill] [--params config/association.yaml] [--gate cost ...]

The very same :class:`MultiTargetTracker` as ``association_node``; every parameter of
``config/association.yaml`` is also an option (``--max-misses``, ``--kalman-acceleration-noise``,
...). Frame ``k`` has the stamp ``(k - 1) / fps``. With ``--gt`` the MOT metrics are printed, and
seed 003's Fig. 4 measure (frames of continuous tracking per ground-truth target), and HOTA.
Scores: thresholds (``--min-score``, ``--high-score``) are fractions; a file whose scores go above 1
(and not above 100) is read as percent unless ``--score-scale`` is given. A ``seqinfo.ini`` that
disagrees with the detections (``seqLength`` shorter, boxes outside the image) is reported; every
frame of the data is tracked.
By default the output is what the live node publishes (confirmed tracks and coasting ones while their
prediction is trusted: states 1 and 2);
``--no-coasting`` drops coasting ones, ``--backfill`` adds a confirmed track's tentative frames
(offline only). Seed 003 as written: ``--params config/association_seed.yaml``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from aircraft_docking_tracker.io.bag import BagError, check_outputs
from aircraft_docking_tracker.config import ConfigError, add_config_arguments, config_from_arguments, tool_parameters
from aircraft_docking_tracker.io import motchallenge as mc
from multi_target_tracker.association import AssociationConfig, MultiTargetTracker
from multi_target_tracker.kalman import KalmanConfig

KALMAN_PREFIX = "kalman."
NODE_NAME = "association"  # the ROS node name, and its section in config/association.yaml


def track_sequence(detections: np.ndarray, fps: float, tracker: MultiTargetTracker, last_frame: int | None = None,
                   include_tentative: bool = False, include_coasting: bool = True, backfill: bool = False,
                   progress: bool = False) -> tuple[np.ndarray, int]:
    """Run ``tracker`` over MOTChallenge detection rows; return (result rows, rejected detections).

    ``backfill`` (offline only): when a tentative track is confirmed (rule 4) its earlier frames,
    already recorded by the core, are written too, as a live node cannot.
    """
    if not fps > 0:
        raise ValueError(f"fps={fps} must be positive")
    out, rejected = [], 0
    frame_of = {}
    for frame, rows in tqdm(mc.frames(detections, 1, last_frame), total=last_frame or int(detections["frame"].max()),
                            disable=not progress, unit="frame"):
        result = tracker.step((frame - 1) / fps, mc.boxes(rows), rows["score"])
        frame_of[result.frame_index] = frame
        rejected += result.rejected
        shown = result.tracks.visible(include_tentative, include_coasting)
        out.append(mc.make_rows(frame, shown.ids, shown.boxes, shown.scores))
        if backfill:
            for track_id in result.confirmed_now:
                past = tracker.trail(track_id)[:-1]
                if not include_coasting:
                    past = past[past[:, 5] > 0]
                out.append(np.concatenate([mc.make_rows(frame_of[int(p[0])], [track_id], p[1:5]) for p in past])
                           if len(past) else mc.make_rows(frame, [], np.zeros((0, 4))))
    rows = np.concatenate(out) if out else mc.make_rows(0, [], np.zeros((0, 4)))
    return rows[np.lexsort((rows["id"], rows["frame"]))], rejected


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mot_track", description=__doc__.split("\n\n")[0])
    parser.add_argument("det", type=Path, help="MOTChallenge det.txt")
    parser.add_argument("-o", "--output", type=Path, help="results file (MOTChallenge layout)")
    parser.add_argument("--fps", type=float, help="frame rate (default: seqinfo.ini next to det.txt, else 30)")
    parser.add_argument("--seqinfo", type=Path, help="seqinfo.ini giving frameRate and seqLength")
    parser.add_argument("--gt", type=Path, help="gt.txt: print MOT metrics of the results")
    parser.add_argument("--params", type=Path, help="ROS 2 parameter file (default: config/association.yaml)")
    parser.add_argument("--include-tentative", action="store_true", help="also write tentative tracks")
    parser.add_argument("--no-coasting", action="store_true", help="do not write tracks coasting on prediction")
    parser.add_argument("--backfill", action="store_true", help="write a confirmed track's tentative frames too")
    parser.add_argument("--json", action="store_true", help="print the metrics (and per-target continuity) as JSON")
    parser.add_argument("--max-frame", type=int, default=mc.MAX_FRAME,
                        help=f"refuse files with frame numbers above this (default {mc.MAX_FRAME}; every frame up to "
                        "the last is tracked)")
    add_config_arguments(parser, AssociationConfig)
    add_config_arguments(parser, KalmanConfig, prefix="kalman_")
    return parser


def configs_from(args) -> tuple[AssociationConfig, KalmanConfig]:
    """Association and Kalman configs: YAML file, then the command-line options on top."""
    base = tool_parameters(args.params, "association.yaml", NODE_NAME)
    kalman_base = {k[len(KALMAN_PREFIX):]: v for k, v in base.items() if k.startswith(KALMAN_PREFIX)}
    assoc = config_from_arguments(AssociationConfig, args, base=base)
    kalman = config_from_arguments(KalmanConfig, args, prefix="kalman_", base=kalman_base)
    return assoc, kalman


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if not args.det.is_file():
        print(f"mot_track: {args.det} not found", file=sys.stderr)
        return 2
    try:  # `-o det.txt` would replace the detections by the results
        check_outputs([args.output], [p for p in (args.det, args.gt, args.seqinfo, args.params) if p])
    except BagError as exc:
        print(f"mot_track: {exc}", file=sys.stderr)
        return 2
    try:
        info = mc.read_seqinfo(args.seqinfo or args.det.parent)
        fps = args.fps or info.get("frameRate") or 30.0
        assoc, kalman = configs_from(args)
        detections = mc.read_detections(args.det, max_frame=args.max_frame)
        if args.score_scale is None:                       # not declared: detected from the file
            assoc.score_scale = mc.score_scale_of(detections["score"])
            if assoc.score_scale != 1.0:
                print(f"mot_track: {args.det} has scores up to {detections['score'].max():g}: read as percent "
                      "(--score-scale 100; min_score and high_score are fractions)", file=sys.stderr)
        for warning in mc.seqinfo_disagreements(info, detections):
            print(f"mot_track: warning: {warning}", file=sys.stderr)
        last = max(info.get("seqLength") or 0, int(detections["frame"].max()) if len(detections) else 0)
        if args.gt:
            gt = mc.read_ground_truth(args.gt, max_frame=args.max_frame)
            last = max(last, int(gt["frame"].max()) if len(gt) else 0)
        if not 0 <= last <= args.max_frame:
            raise mc.MotFormatError(f"sequence length {last} is beyond --max-frame {args.max_frame}")
        if not fps > 0 or not np.isfinite(fps):
            raise ValueError(f"frame rate {fps} must be a positive number")
    except (mc.MotFormatError, ConfigError, ValueError, OSError) as exc:
        print(f"mot_track: {exc}", file=sys.stderr)
        return 2
    rows, rejected = track_sequence(detections, fps, MultiTargetTracker(assoc, kalman), last,
                                    args.include_tentative, not args.no_coasting, args.backfill, progress=True)
    if rejected:
        print(f"mot_track: {rejected} invalid detections (NaN, inf, size <= 0) rejected", file=sys.stderr)
    if args.output:
        mc.write_results(args.output, rows)
    if args.gt:
        from aircraft_docking_tracker.evaluation.mot_metrics import evaluate_rows  # noqa: PLC0415

        scores = evaluate_rows(gt, rows)
        if args.json:
            print(json.dumps(scores.as_dict(with_continuity=True), indent=1))
        else:
            print(f"HOTA {100 * scores.hota:.1f}  DetA {100 * scores.deta:.1f}  AssA {100 * scores.assa:.1f}  "
                  f"MOTA {100 * scores.mota:.1f}  MOTP {100 * scores.motp:.1f}  IDF1 {100 * scores.idf1:.1f}  "
                  f"IDSW {scores.num_switches}  FRAG {scores.num_fragmentations}  MT {scores.mostly_tracked}  "
                  f"ML {scores.mostly_lost}  FP {scores.num_false_positives}  FN {scores.num_misses}")
            print("seed 003 Fig. 4 (frames of continuous tracking per target): " + ", ".join(
                f"{c.gt_id}: {c.longest_continuous}/{c.frames_present} ({c.first_frame}-{c.last_frame})"
                for c in scores.continuity))
    return 0


if __name__ == "__main__":
    sys.exit(main())
