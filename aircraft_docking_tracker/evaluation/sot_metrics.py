"""Single-target tracking metrics, the OTB benchmark's definitions (no ROS here).

Wu, Lim & Yang, "Online Object Tracking: A Benchmark" (CVPR 2013; TPAMI 2015):

* overlap (IoU) of the tracked and true regions, ``|A ∩ B| / |A ∪ B|``; for the docking tracker's
  affine quadrilaterals, the IoU of the two convex polygons (:func:`polygon_iou`);
* **success curve**: the fraction of frames whose IoU is *greater than* a threshold, thresholds
  0, 0.05, …, 1 (21 values, as the OTB toolkit); **AUC** = the mean of that curve;
* **centre error**: the Euclidean distance in pixels between the centres of the two regions;
* **precision curve**: the fraction of frames whose centre error is *at most* a threshold,
  thresholds 0 … 50 px; **precision at 20 px** is the number OTB ranks by;
* **lost-track frames** (ours, for the docking product): frames where the tracker reports no region
  or one with IoU <= ``lost_iou`` (default 0: no overlap at all), with the longest such run.

Conventions: boxes are ``(x, y, w, h)`` with ``x, y`` the top-left corner; quadrilaterals are
``(4, 2)`` point arrays in the order top-left, top-right, bottom-right, bottom-left of the template.
A frame whose *ground truth* is NaN (target absent or marked lost) is left out of every metric; a
frame whose *prediction* is NaN (tracker reports nothing) scores IoU 0 and centre error infinity.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aircraft_docking_tracker.config import param
from aircraft_docking_tracker.geometry import box_iou

SUCCESS_THRESHOLDS = np.round(np.arange(0.0, 1.0 + 1e-9, 0.05), 2)   # OTB: 0:0.05:1
PRECISION_THRESHOLDS = np.arange(0.0, 51.0)                           # OTB: 0:50 px


class MetricInputError(ValueError):
    """Inputs to a metric that cannot be scored (wrong shapes, mismatched lengths)."""


@dataclass
class SotMetricsConfig:
    """What the single-target scores are read at."""

    precision_px: float = param(20.0, "centre-error threshold of the reported precision [px] (OTB: 20)",
                                low=0.0, high=1000.0)
    lost_iou: float = param(0.0, "a frame counts as lost when its IoU is at most this", low=0.0, high=1.0)


# --- geometry ----------------------------------------------------------------------------------

def as_boxes(boxes) -> np.ndarray:
    """``(N, 4)`` float64 array of ``x, y, w, h`` rows (a single box becomes one row)."""
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise MetricInputError(f"boxes must be (N, 4) x, y, w, h rows, got shape {arr.shape}")
    return arr


def as_quads(quads) -> np.ndarray:
    """``(N, 4, 2)`` float64 array of quadrilaterals (a single quad becomes one)."""
    arr = np.asarray(quads, dtype=np.float64)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (4, 2):
        raise MetricInputError(f"quadrilaterals must be (N, 4, 2) point arrays, got shape {arr.shape}")
    return arr


def centers(regions) -> np.ndarray:
    """Centres ``(N, 2)`` of boxes ``(N, 4)`` or quadrilaterals ``(N, 4, 2)`` (mean of the corners)."""
    arr = np.asarray(regions, dtype=np.float64)
    if arr.ndim >= 2 and arr.shape[-2:] == (4, 2):
        return as_quads(arr).mean(axis=1)
    b = as_boxes(arr)
    return b[:, :2] + b[:, 2:] / 2.0


def polygon_iou(p, q) -> np.ndarray:
    """IoU of convex quadrilaterals, per pair: ``(N, 4, 2)`` with ``(N, 4, 2)`` -> ``(N,)``.

    The intersection is ``cv2.intersectConvexConvex`` of the convex hulls (so a point order of
    either orientation works); NaN or zero-area polygons give IoU 0.
    """
    p, q = as_quads(p), as_quads(q)
    if len(p) != len(q):
        raise MetricInputError(f"{len(p)} predicted and {len(q)} true quadrilaterals")
    out = np.zeros(len(p))
    for i, (pi, qi) in enumerate(zip(p, q)):
        if not (np.isfinite(pi).all() and np.isfinite(qi).all()):
            continue
        hp = cv2.convexHull(pi.astype(np.float32))
        hq = cv2.convexHull(qi.astype(np.float32))
        area_p, area_q = cv2.contourArea(hp), cv2.contourArea(hq)
        if area_p <= 0 or area_q <= 0:
            continue
        inter, _ = cv2.intersectConvexConvex(hp, hq, handleNested=True)
        inter = max(float(inter), 0.0)
        out[i] = inter / (area_p + area_q - inter)
    return out


def region_iou(pred, gt) -> np.ndarray:
    """Per-frame IoU of boxes ``(N, 4)`` or quadrilaterals ``(N, 4, 2)`` (both of the same kind)."""
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    if pred.shape != gt.shape:
        raise MetricInputError(f"prediction shape {pred.shape} differs from ground truth {gt.shape}")
    if pred.ndim == 3:
        return polygon_iou(pred, gt)
    return box_iou(as_boxes(pred), as_boxes(gt))


def center_errors(pred, gt) -> np.ndarray:
    """Per-frame centre distance [px]; infinity where the prediction is missing (NaN)."""
    err = np.linalg.norm(centers(pred) - centers(gt), axis=1)
    return np.where(np.isnan(err), np.inf, err)


# --- curves ------------------------------------------------------------------------------------

def success_curve(ious, thresholds=SUCCESS_THRESHOLDS) -> np.ndarray:
    """Fraction of frames with IoU > threshold, for each threshold (OTB success plot)."""
    ious = np.asarray(ious, dtype=np.float64)
    if ious.size == 0:
        return np.zeros(len(thresholds))
    return (ious[None, :] > np.asarray(thresholds)[:, None]).mean(axis=1)


def success_auc(ious, thresholds=SUCCESS_THRESHOLDS) -> float:
    """Area under the success curve: the mean over OTB's 21 thresholds."""
    return float(np.mean(success_curve(ious, thresholds)))


def precision_curve(errors, thresholds=PRECISION_THRESHOLDS) -> np.ndarray:
    """Fraction of frames with centre error <= threshold, for each threshold (OTB precision plot)."""
    errors = np.asarray(errors, dtype=np.float64)
    if errors.size == 0:
        return np.zeros(len(thresholds))
    return (errors[None, :] <= np.asarray(thresholds)[:, None]).mean(axis=1)


def precision_at(errors, threshold_px: float = 20.0) -> float:
    """Fraction of frames with centre error <= ``threshold_px`` (OTB reports 20 px)."""
    return float(precision_curve(errors, [threshold_px])[0])


def lost_frames(ious, lost_iou: float = 0.0) -> np.ndarray:
    """Boolean mask of lost frames: IoU <= ``lost_iou`` (a missing prediction has IoU 0)."""
    return np.asarray(ious, dtype=np.float64) <= lost_iou


def longest_run(mask) -> int:
    """Length of the longest run of True in a boolean sequence."""
    best = run = 0
    for value in np.asarray(mask, dtype=bool):
        run = run + 1 if value else 0
        best = max(best, run)
    return best


# --- one sequence ------------------------------------------------------------------------------

def valid_gt(gt) -> np.ndarray:
    """Mask of frames whose ground truth is present (no NaN coordinate)."""
    gt = np.asarray(gt, dtype=np.float64)
    return np.isfinite(gt.reshape(len(gt), -1)).all(axis=1)


def score_sequence(pred, gt, config: SotMetricsConfig | None = None) -> dict:
    """Every single-target score of one sequence; ``pred`` and ``gt`` aligned per frame.

    Both are ``(N, 4)`` boxes or ``(N, 4, 2)`` quadrilaterals; NaN rows mark missing predictions /
    absent ground truth (see the module docstring). Returns plain floats and lists (JSON-ready).
    """
    cfg = config or SotMetricsConfig()
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    if len(pred) != len(gt):
        raise MetricInputError(f"{len(pred)} predictions for {len(gt)} ground-truth frames")
    keep = valid_gt(gt)
    ious = region_iou(pred[keep], gt[keep]) if keep.any() else np.zeros(0)
    errors = center_errors(pred[keep], gt[keep]) if keep.any() else np.zeros(0)
    lost = lost_frames(ious, cfg.lost_iou)
    finite = errors[np.isfinite(errors)]
    return {
        "frames": int(len(gt)),
        "scored_frames": int(keep.sum()),
        "mean_iou": float(ious.mean()) if ious.size else 0.0,
        "success_auc": success_auc(ious),
        "success_at_0.5": float(success_curve(ious, [0.5])[0]),
        "precision_px": float(cfg.precision_px),
        "precision": precision_at(errors, cfg.precision_px),
        "mean_center_error": float(finite.mean()) if finite.size else float("nan"),
        "median_center_error": float(np.median(errors)) if errors.size else float("nan"),
        "lost_frames": int(lost.sum()),
        "longest_loss": longest_run(lost),
        "success_thresholds": SUCCESS_THRESHOLDS.tolist(),
        "success_curve": success_curve(ious).tolist(),
        "precision_thresholds": PRECISION_THRESHOLDS.tolist(),
        "precision_curve": precision_curve(errors).tolist(),
        "iou": ious.tolist(),
        "center_error": [e if np.isfinite(e) else None for e in errors.tolist()],
    }
