"""Multi-object tracking metrics through ``motmetrics`` (no ROS here).

CLEAR-MOT (Bernardin & Stiefelhagen 2008: MOTA, MOTP), identity measures (Ristani et al. 2016:
IDF1), ID switches, fragmentations, mostly tracked / lost (Li et al. 2009), and the measure of
seed 003 Fig. 4: for each ground-truth target, the number of frames it is tracked continuously.

The IoU distance matrix is computed here (``1 - IoU``, NaN where IoU < threshold) because
``motmetrics.distances.iou_matrix`` breaks on numpy 2; it is fed to ``motmetrics.MOTAccumulator``.
Conventions: MOTA, IDF1, precision, recall are fractions (x100 for the usual percent); ``motp`` is
the mean IoU of the matched pairs (MOTChallenge's convention, higher is better).

HOTA, DetA, AssA, LocA (Luiten et al., "HOTA: A Higher Order Metric for Evaluating Multi-Object
Tracking", IJCV 2021) follow TrackEval's ``trackeval/metrics/hota.py`` (v1.3.0 on PyPI) line for line:
IoU similarity, the global alignment score of every (gt id, track id) pair weighting a Hungarian
matching per frame, the 19 thresholds α = 0.05 ... 0.95 and the mean over them. TrackEval itself is
not a dependency (it pins opencv-python, which clashes with the headless build we use); the bench
checks this port against it in the peers' venv and ``test/test_mot_metrics.py`` pins its values.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import motmetrics
import numpy as np
from scipy.optimize import linear_sum_assignment

from aircraft_docking_tracker.io.motchallenge import boxes, frames, iou_matrix

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
    hota: float = float("nan")     # HOTA, DetA, AssA, LocA: means over TrackEval's 19 α thresholds
    deta: float = float("nan")
    assa: float = float("nan")
    loca: float = float("nan")
    continuity: list[TargetContinuity] = field(default_factory=list)

    def as_dict(self, with_continuity: bool = False) -> dict:
        d = asdict(self)
        if not with_continuity:
            d.pop("continuity")
        return d


def iou_distances(gt_xywh: np.ndarray, hyp_xywh: np.ndarray, iou_threshold: float = 0.5) -> np.ndarray:
    """``1 - IoU`` between ground truth (rows) and hypotheses (columns); NaN (no match) below the threshold."""
    return _thresholded_distances(iou_matrix(gt_xywh, hyp_xywh), iou_threshold)


def _thresholded_distances(similarity: np.ndarray, iou_threshold: float) -> np.ndarray:
    dist = 1.0 - similarity
    dist[dist > 1.0 - iou_threshold] = np.nan
    return dist


class MotEvaluator:
    """Frame-by-frame accumulation: call :meth:`update` once per frame, then :meth:`result`."""

    def __init__(self, iou_threshold: float = 0.5):
        if not 0.0 < iou_threshold <= 1.0:
            raise ValueError(f"iou_threshold={iou_threshold} must be in (0, 1]")
        self.iou_threshold = iou_threshold
        self.accumulator = motmetrics.MOTAccumulator(auto_id=False)
        self.hota = HotaAccumulator()

    def update(self, frame: int, gt_ids, gt_xywh, hyp_ids, hyp_xywh) -> None:
        """Add one frame: ground-truth ids and boxes, hypothesis (track) ids and boxes (x, y, w, h)."""
        gt_ids = np.asarray(gt_ids, dtype=np.int64).reshape(-1)
        hyp_ids = np.asarray(hyp_ids, dtype=np.int64).reshape(-1)
        similarity = iou_matrix(gt_xywh, hyp_xywh)
        dist = _thresholded_distances(similarity, self.iou_threshold)
        self.accumulator.update(gt_ids, hyp_ids, dist, frameid=int(frame))
        self.hota.update(gt_ids, hyp_ids, similarity)

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
        for name, value in self.hota.result().items():
            setattr(scores, name, value)
        scores.continuity = continuity(self.accumulator)
        return scores


#: TrackEval's localisation thresholds α (``np.arange(0.05, 0.99, 0.05)``: 0.05, 0.10, ..., 0.95).
HOTA_ALPHAS = np.arange(0.05, 0.99, 0.05)
_EPS = np.finfo("float").eps


class HotaAccumulator:
    """HOTA of one sequence, as TrackEval's ``HOTA.eval_sequence``: feed frames, then :meth:`result`.

    Per frame: the ground-truth ids, the track ids and their similarity (IoU, gt rows x track columns).
    """

    def __init__(self):
        self.frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def update(self, gt_ids, hyp_ids, similarity) -> None:
        gt_ids = np.asarray(gt_ids, dtype=np.int64).reshape(-1)
        hyp_ids = np.asarray(hyp_ids, dtype=np.int64).reshape(-1)
        similarity = np.asarray(similarity, dtype=np.float64).reshape(len(gt_ids), len(hyp_ids))
        self.frames.append((gt_ids, hyp_ids, similarity))

    def result(self) -> dict:
        """``hota``, ``deta``, ``assa``, ``loca``: fractions, means over :data:`HOTA_ALPHAS` (as TrackEval reports)."""
        arrays = self.arrays()
        return {name: float(np.mean(arrays[key])) for name, key in
                (("hota", "HOTA"), ("deta", "DetA"), ("assa", "AssA"), ("loca", "LocA"))}

    def arrays(self) -> dict:
        """TrackEval's per-α fields: HOTA, DetA, AssA, DetRe, DetPr, AssRe, AssPr, LocA, HOTA_TP/FN/FP."""
        n_alpha = len(HOTA_ALPHAS)
        res = {k: np.zeros(n_alpha) for k in ("HOTA_TP", "HOTA_FN", "HOTA_FP", "LocA", "AssA", "AssRe", "AssPr")}
        # TrackEval renumbers the ids of a sequence 0 .. n-1
        gt_all = np.unique(np.concatenate([f[0] for f in self.frames])) if self.frames else np.zeros(0, np.int64)
        hyp_all = np.unique(np.concatenate([f[1] for f in self.frames])) if self.frames else np.zeros(0, np.int64)
        frames = [(np.searchsorted(gt_all, g), np.searchsorted(hyp_all, h), s) for g, h, s in self.frames]
        num_gt_dets = sum(len(g) for g, _, _ in frames)
        num_hyp_dets = sum(len(h) for _, h, _ in frames)
        if num_hyp_dets == 0 or num_gt_dets == 0:        # TrackEval's early returns
            res["HOTA_FN"][:] = num_gt_dets if num_hyp_dets == 0 else 0
            res["HOTA_FP"][:] = num_hyp_dets if num_hyp_dets and num_gt_dets == 0 else 0
            res["LocA"][:] = 1.0
            return self._final(res)
        potential = np.zeros((len(gt_all), len(hyp_all)))
        gt_count = np.zeros((len(gt_all), 1))
        hyp_count = np.zeros((1, len(hyp_all)))
        for g, h, sim in frames:
            denom = sim.sum(0)[np.newaxis, :] + sim.sum(1)[:, np.newaxis] - sim
            sim_iou = np.zeros_like(sim)
            mask = denom > 0 + _EPS
            sim_iou[mask] = sim[mask] / denom[mask]
            potential[g[:, np.newaxis], h[np.newaxis, :]] += sim_iou
            gt_count[g] += 1
            hyp_count[0, h] += 1
        global_alignment = potential / (gt_count + hyp_count - potential)
        matches = np.zeros((n_alpha, len(gt_all), len(hyp_all)))
        for g, h, sim in frames:
            if len(g) == 0:
                res["HOTA_FP"] += len(h)
                continue
            if len(h) == 0:
                res["HOTA_FN"] += len(g)
                continue
            rows, cols = linear_sum_assignment(-(global_alignment[g[:, np.newaxis], h[np.newaxis, :]] * sim))
            matched_sim = sim[rows, cols]
            for a, alpha in enumerate(HOTA_ALPHAS):
                ok = matched_sim >= alpha - _EPS
                n = int(ok.sum())
                res["HOTA_TP"][a] += n
                res["HOTA_FN"][a] += len(g) - n
                res["HOTA_FP"][a] += len(h) - n
                if n:
                    res["LocA"][a] += matched_sim[ok].sum()
                    matches[a, g[rows[ok]], h[cols[ok]]] += 1
        for a in range(n_alpha):
            m = matches[a]
            tp = np.maximum(1, res["HOTA_TP"][a])
            res["AssA"][a] = np.sum(m * (m / np.maximum(1, gt_count + hyp_count - m))) / tp
            res["AssRe"][a] = np.sum(m * (m / np.maximum(1, gt_count))) / tp
            res["AssPr"][a] = np.sum(m * (m / np.maximum(1, hyp_count))) / tp
        res["LocA"] = np.maximum(1e-10, res["LocA"]) / np.maximum(1e-10, res["HOTA_TP"])
        return self._final(res)

    @staticmethod
    def _final(res: dict) -> dict:
        tp, fn, fp = res["HOTA_TP"], res["HOTA_FN"], res["HOTA_FP"]
        res["DetRe"] = tp / np.maximum(1, tp + fn)
        res["DetPr"] = tp / np.maximum(1, tp + fp)
        res["DetA"] = tp / np.maximum(1, tp + fn + fp)
        res["HOTA"] = np.sqrt(res["DetA"] * res["AssA"])
        return res


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
    return evaluator_of_rows(gt_rows, hyp_rows, iou_threshold).result()


def evaluator_of_rows(gt_rows: np.ndarray, hyp_rows: np.ndarray, iou_threshold: float = 0.5) -> MotEvaluator:
    """The :class:`MotEvaluator` fed with every frame of two MOT row tables (see :func:`evaluate_rows`)."""
    last = int(max(gt_rows["frame"].max() if len(gt_rows) else 0, hyp_rows["frame"].max() if len(hyp_rows) else 0))
    evaluator = MotEvaluator(iou_threshold)
    hyp_by_frame = dict(frames(hyp_rows, 1, last))
    for frame, gt in frames(gt_rows, 1, last):
        hyp = hyp_by_frame[frame]
        evaluator.update(frame, gt["id"], boxes(gt), hyp["id"], boxes(hyp))
    return evaluator


def reacquisitions(accumulator: motmetrics.MOTAccumulator, min_gap: int) -> tuple[int, int]:
    """Long hides bridged: (hides, re-acquired). A hide is a gap of at least ``min_gap`` frames in a
    ground-truth target's annotation (hidden targets are not annotated) with the target matched in
    its last annotated frame before; it is re-acquired when the first match after the gap has the
    same track id as that last match before it."""
    events = accumulator.mot_events
    events = events[events["Type"].isin(["MATCH", "SWITCH", "MISS"]) & events["OId"].notna()]
    frame_ids = events.index.get_level_values(0).to_numpy()
    hides = kept = 0
    for gt_id in set(events["OId"].astype(float)):
        mask = (events["OId"].astype(float) == gt_id).to_numpy()
        order = np.argsort(frame_ids[mask], kind="stable")
        f = frame_ids[mask][order]
        hyp = events["HId"].to_numpy()[mask][order]
        for k in np.flatnonzero(np.diff(f) >= min_gap):
            before = hyp[k]
            if before != before:                      # not tracked when it disappeared
                continue
            hides += 1
            after = hyp[k + 1:]
            after = after[after == after]
            kept += int(len(after) > 0 and after[0] == before)
    return hides, kept
