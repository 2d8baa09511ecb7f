"""Detection metrics: seed 003 Table 1's detection and false-alarm rates, PR curve, AP (no ROS here).

Definitions (the seed's Table 1 reports 正确率 "detection rate" 95.2 % and 虚警率 "false-alarm rate"
4.5 % without defining them; these are the definitions this package uses and the README states):

* **matching**, per frame: detections are taken in order of decreasing score; each is matched to
  the *still unmatched* ground-truth box with which it has the highest IoU, if that IoU >= 0.5
  (``iou_threshold``). A matched detection is a true positive (TP), an unmatched one a false
  positive (FP); a ground-truth box left unmatched is a miss (FN).
* **detection rate** = TP / number of ground-truth boxes (recall);
* **false-alarm rate** = FP / number of detections (= 1 - precision). The two are independent:
  Table 1's pairs do not sum to 100 % (89.7 + 15.9, 93.9 + 8.3), so its "correct rate" is not
  1 - false-alarm rate, i.e. it is read as recall;
* **precision-recall curve**: all detections of all frames sorted by decreasing score; after the
  k-th, precision = TP_k / k and recall = TP_k / #GT;
* **average precision**: the area under that curve with PASCAL VOC's all-point interpolation
  (VOC 2010+): precision made monotonically decreasing from the right, summed over recall steps.

Ground-truth boxes flagged *ignore* (e.g. a vehicle fully hidden under trees, which no detector is
expected to see) count neither as misses nor, when a detection matches them, as false alarms.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aircraft_docking_tracker.config import param
from aircraft_docking_tracker.evaluation.sot_metrics import MetricInputError, as_boxes
from aircraft_docking_tracker.geometry import box_iou


@dataclass
class DetectionMetricsConfig:
    """How detections are matched to ground truth."""

    iou_threshold: float = param(0.5, "a detection counts when its IoU with an unmatched GT box is at least this",
                                 low=0.0, high=1.0)
    min_score: float = param(0.0, "detections scoring below this are dropped before the rates are computed",
                             low=-1e9, high=1e9)


def match_frame(det_boxes, det_scores, gt_boxes, iou_threshold: float = 0.5, gt_ignore=None):
    """Greedy matching of one frame's detections to its ground truth (see the module docstring).

    Returns ``(det_gt, det_ignored)``: for each detection the index of its ground-truth box or -1,
    and whether it only matched an *ignored* box (then it is neither TP nor FP).
    """
    dets = as_boxes(det_boxes) if len(det_boxes) else np.zeros((0, 4))
    gts = as_boxes(gt_boxes) if len(gt_boxes) else np.zeros((0, 4))
    scores = np.asarray(det_scores, dtype=np.float64).reshape(-1)
    if len(scores) != len(dets):
        raise MetricInputError(f"{len(dets)} detection boxes but {len(scores)} scores")
    ignore = np.zeros(len(gts), bool) if gt_ignore is None else np.asarray(gt_ignore, bool).reshape(-1)
    if len(ignore) != len(gts):
        raise MetricInputError(f"{len(gts)} ground-truth boxes but {len(ignore)} ignore flags")
    det_gt = np.full(len(dets), -1, dtype=np.int64)
    det_ignored = np.zeros(len(dets), dtype=bool)
    if len(dets) == 0 or len(gts) == 0:
        return det_gt, det_ignored
    iou = box_iou(dets[:, None, :], gts[None, :, :])
    taken = ignore.copy()              # ignored boxes are never matched as true positives
    for d in np.argsort(-scores, kind="stable"):
        candidates = np.where(taken, -1.0, iou[d])
        g = int(np.argmax(candidates))
        if candidates[g] >= iou_threshold:
            det_gt[d] = g
            taken[g] = True
        elif ignore.any() and iou[d, ignore].max() >= iou_threshold:
            det_ignored[d] = True
    return det_gt, det_ignored


@dataclass
class DetectionAccumulator:
    """Collects matched frames; :meth:`summary` gives the rates, the PR curve and AP."""

    config: DetectionMetricsConfig = field(default_factory=DetectionMetricsConfig)
    scores: list = field(default_factory=list)
    is_tp: list = field(default_factory=list)
    n_gt: int = 0
    n_frames: int = 0

    def add_frame(self, det_boxes, det_scores, gt_boxes, gt_ignore=None) -> None:
        """Match one frame and keep its detections' scores and TP flags."""
        scores = np.asarray(det_scores, dtype=np.float64).reshape(-1)
        keep = scores >= self.config.min_score
        det_boxes = np.asarray(det_boxes, dtype=np.float64).reshape(-1, 4)[keep]
        scores = scores[keep]
        det_gt, det_ignored = match_frame(det_boxes, scores, gt_boxes, self.config.iou_threshold, gt_ignore)
        counted = ~det_ignored
        self.scores.extend(scores[counted].tolist())
        self.is_tp.extend((det_gt[counted] >= 0).tolist())
        n_boxes = len(np.asarray(gt_boxes).reshape(-1, 4))
        n_ignored = 0 if gt_ignore is None else int(np.asarray(gt_ignore, bool).sum())
        self.n_gt += n_boxes - n_ignored
        self.n_frames += 1

    def summary(self) -> dict:
        """Detection rate, false-alarm rate, PR curve and AP (plain types, JSON-ready)."""
        return detection_summary(np.asarray(self.scores), np.asarray(self.is_tp, dtype=bool), self.n_gt,
                                 self.n_frames)


def pr_curve(scores, is_tp, n_gt: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(precision, recall, score)`` after each detection, detections sorted by decreasing score."""
    scores = np.asarray(scores, dtype=np.float64)
    is_tp = np.asarray(is_tp, dtype=bool)
    order = np.argsort(-scores, kind="stable")
    tp = np.cumsum(is_tp[order])
    k = np.arange(1, len(order) + 1)
    precision = tp / np.maximum(k, 1)
    recall = tp / n_gt if n_gt > 0 else np.zeros(len(order))
    return precision, recall, scores[order]


def average_precision(precision, recall) -> float:
    """PASCAL VOC (2010+) all-point interpolated AP of a PR curve."""
    mrec = np.concatenate([[0.0], np.asarray(recall, dtype=np.float64), [1.0]])
    mpre = np.concatenate([[0.0], np.asarray(precision, dtype=np.float64), [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    steps = np.where(mrec[1:] != mrec[:-1])[0]
    return float(np.sum((mrec[steps + 1] - mrec[steps]) * mpre[steps + 1]))


def detection_summary(scores, is_tp, n_gt: int, n_frames: int = 0) -> dict:
    """Rates over all detections given their scores and TP flags and the number of GT boxes."""
    is_tp = np.asarray(is_tp, dtype=bool)
    tp = int(is_tp.sum())
    n_det = int(len(is_tp))
    precision, recall, sorted_scores = pr_curve(scores, is_tp, n_gt)
    return {
        "frames": int(n_frames),
        "ground_truth": int(n_gt),
        "detections": n_det,
        "true_positives": tp,
        "false_positives": n_det - tp,
        "misses": int(n_gt - tp),
        "detection_rate": tp / n_gt if n_gt else 0.0,
        "false_alarm_rate": (n_det - tp) / n_det if n_det else 0.0,
        "average_precision": average_precision(precision, recall) if n_gt else 0.0,
        "pr_precision": precision.tolist(),
        "pr_recall": recall.tolist(),
        "pr_score": sorted_scores.tolist(),
    }
