"""Multi-object tracking metrics through ``motmetrics`` (no ROS here).

CLEAR-MOT (Bernardin & Stiefelhagen 2008: MOTA, MOTP), identity measures (Ristani et al. 2016:
IDF1), ID switches, fragmentations, mostly tracked / lost (Li et al. 2009), and the measure of
seed 003 Fig. 4: for each ground-truth target, the number of frames it is tracked continuously.

The IoU distance matrix is computed here (``1 - IoU``, NaN where IoU < threshold) because
``motmetrics.distances.iou_matrix`` breaks on numpy 2; it is fed to ``motmetrics.MOTAccumulator``.
Conventions: MOTA, IDF1, precision, recall are fractions (x100 for the usual percent); ``motp`` is
the mean IoU of the matched pairs (MOTChallenge's convention, higher is better).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import motmetrics
import numpy as np

from multi_target_tracker.motchallenge import boxes, frames, iou_matrix

_METRICS = ["num_frames", "mota", "motp", "idf1", "idp", "idr", "precision", "recall",
            "num_switches", "num_fragmentations", "mostly_tracked", "partially_tracked", "mostly_lost",
            "num_false_positives", "num_misses", "num_objects", "num_unique_objects", "num_matches"]  # num_matches excludes switches


@dataclass
class TargetContinuity:
    """Seed 003 Fig. 4 for one ground-truth target: its span and its continuous tracking."""

    gt_id: int
    first_frame: int
    last_frame: int
    frames_present: int      # frames in which the target is annotated
    frames_tracked: int      # of those, frames matched to any track
    longest_continuous: int  # longest run of consecutive annotated frames matched to one track id


@dataclass
class MotScores:
    """The summary of one sequence (fractions, counts) and the per-target continuity."""

    num_frames: int = 0
    mota: float = float("nan")
    motp: float = float("nan")
    idf1: float = float("nan")
    idp: float = float("nan")
    idr: float = float("nan")
    precision: float = float("nan")
    recall: float = float("nan")
    num_switches: int = 0
    num_fragmentations: int = 0
    mostly_tracked: int = 0
    partially_tracked: int = 0
    mostly_lost: int = 0
    num_false_positives: int = 0
    num_misses: int = 0
    num_objects: int = 0
    num_unique_objects: int = 0
    num_matches: int = 0
    continuity: list[TargetContinuity] = field(default_factory=list)

    def as_dict(self, with_continuity: bool = False) -> dict:
        d = asdict(self)
        if not with_continuity:
            d.pop("continuity")
        return d


def iou_distances(gt_xywh: np.ndarray, hyp_xywh: np.ndarray, iou_threshold: float = 0.5) -> np.ndarray:
    """``1 - IoU`` between ground truth (rows) and hypotheses (columns); NaN (no match) below the threshold."""
    dist = 1.0 - iou_matrix(gt_xywh, hyp_xywh)
    dist[dist > 1.0 - iou_threshold] = np.nan
    return dist


class MotEvaluator:
    """Frame-by-frame accumulation: call :meth:`update` once per frame, then :meth:`result`."""

    def __init__(self, iou_threshold: float = 0.5):
        if not 0.0 < iou_threshold <= 1.0:
            raise ValueError(f"iou_threshold={iou_threshold} must be in (0, 1]")
        self.iou_threshold = iou_threshold
        self.accumulator = motmetrics.MOTAccumulator(auto_id=False)

    def update(self, frame: int, gt_ids, gt_xywh, hyp_ids, hyp_xywh) -> None:
        """Add one frame: ground-truth ids and boxes, hypothesis (track) ids and boxes (x, y, w, h)."""
        gt_ids = np.asarray(gt_ids, dtype=np.int64).reshape(-1)
        hyp_ids = np.asarray(hyp_ids, dtype=np.int64).reshape(-1)
        dist = iou_distances(gt_xywh, hyp_xywh, self.iou_threshold)
        self.accumulator.update(gt_ids, hyp_ids, dist, frameid=int(frame))

    def result(self) -> MotScores:
        """The metrics of everything accumulated so far."""
        summary = motmetrics.metrics.create().compute(self.accumulator, metrics=_METRICS, name="seq")
        row = summary.loc["seq"]
        scores = MotScores()
        for name in _METRICS:
            value = row[name]
            default = getattr(scores, name)
            setattr(scores, name, int(value) if isinstance(default, int) else float(value))
        scores.motp = 1.0 - scores.motp if np.isfinite(scores.motp) else float("nan")
        scores.continuity = continuity(self.accumulator)
        return scores


def continuity(accumulator: motmetrics.MOTAccumulator) -> list[TargetContinuity]:
    """Seed 003 Fig. 4: per ground-truth target, frames present, frames tracked, longest continuous run.

    A run is a sequence of the target's annotated frames (gaps in the annotation do not break it)
    in which it is matched to the same track id; a miss or an id change ends it.
    """
    events = accumulator.mot_events
    events = events[events["Type"].isin(["MATCH", "SWITCH", "MISS"])]  # one event per target and frame
    events = events[events["OId"].notna()]
    out = []
    frame_ids = events.index.get_level_values(0).to_numpy()
    for gt_id in sorted(set(events["OId"].dropna().astype(int))):
        mask = (events["OId"].astype(float) == gt_id).to_numpy()
        sub = events[mask]
        f = frame_ids[mask]
        order = np.argsort(f, kind="stable")
        f, kinds, hyps = f[order], sub["Type"].to_numpy()[order], sub["HId"].to_numpy()[order]
        best = run = 0
        last_hyp = None
        tracked = 0
        for kind, hyp in zip(kinds, hyps):
            if kind == "MISS" or hyp != hyp:  # NaN hypothesis: not tracked this frame
                run, last_hyp = 0, None
                continue
            tracked += 1
            run = run + 1 if hyp == last_hyp else 1
            last_hyp = hyp
            best = max(best, run)
        out.append(TargetContinuity(int(gt_id), int(f[0]), int(f[-1]), len(f), tracked, best))
    return out


def evaluate_rows(gt_rows: np.ndarray, hyp_rows: np.ndarray, iou_threshold: float = 0.5) -> MotScores:
    """MOT metrics of results against ground truth, both as ``motchallenge.MOT_ROW_DTYPE`` rows.

    Every frame from 1 to the last frame of either file counts (frames without ground truth add
    the hypotheses there as false positives).
    """
    last = int(max(gt_rows["frame"].max() if len(gt_rows) else 0, hyp_rows["frame"].max() if len(hyp_rows) else 0))
    evaluator = MotEvaluator(iou_threshold)
    hyp_by_frame = dict(frames(hyp_rows, 1, last))
    for frame, gt in frames(gt_rows, 1, last):
        hyp = hyp_by_frame[frame]
        evaluator.update(frame, gt["id"], boxes(gt), hyp["id"], boxes(hyp))
    return evaluator.result()
