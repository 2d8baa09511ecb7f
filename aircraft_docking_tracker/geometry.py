"""Axis-aligned boxes (x, y, w, h) and quadrilaterals (4, 2: TL, TR, BR, BL): conversions and IoU. Pure.

The one place these are written: the cores (docking start / re-acquisition, detector, association)
and the metrics (``evaluation``) all use them.
"""
from __future__ import annotations

import numpy as np


def box_iou(a, b) -> np.ndarray:
    """IoU of boxes ``(..., 4)`` with boxes ``(..., 4)``, broadcasting the leading axes.

    ``box_iou(a, b)`` for two equal-length lists is per frame; ``box_iou(a[:, None], b[None])`` is
    the pairwise matrix. Boxes with w or h <= 0 have IoU 0; NaN boxes give IoU 0.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape[-1:] != (4,) or b.shape[-1:] != (4,):
        raise ValueError(f"boxes must end in x, y, w, h (got shapes {a.shape}, {b.shape})")
    ix = np.minimum(a[..., 0] + a[..., 2], b[..., 0] + b[..., 2]) - np.maximum(a[..., 0], b[..., 0])
    iy = np.minimum(a[..., 1] + a[..., 3], b[..., 1] + b[..., 3]) - np.maximum(a[..., 1], b[..., 1])
    inter = np.clip(ix, 0.0, None) * np.clip(iy, 0.0, None)
    area_a = np.clip(a[..., 2], 0.0, None) * np.clip(a[..., 3], 0.0, None)
    area_b = np.clip(b[..., 2], 0.0, None) * np.clip(b[..., 3], 0.0, None)
    union = area_a + area_b - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(union > 0, inter / union, 0.0)
    return np.nan_to_num(iou, nan=0.0)


def box_to_quad(boxes) -> np.ndarray:
    """Axis-aligned boxes ``(N, 4)`` (or one box) -> quadrilaterals TL, TR, BR, BL, shape ``(N, 4, 2)``."""
    b = np.asarray(boxes, dtype=np.float64)
    if b.ndim not in (1, 2) or b.shape[-1] != 4:
        raise ValueError(f"boxes must be (N, 4) x, y, w, h rows, got shape {b.shape}")
    b = b.reshape(-1, 4)
    x0, y0, x1, y1 = b[:, 0], b[:, 1], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3]
    return np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1),
                     np.stack([x1, y1], -1), np.stack([x0, y1], -1)], axis=1)


def quad_to_box(quads) -> np.ndarray:
    """The axis-aligned bounding box ``x, y, w, h`` of each quadrilateral: ``(..., 4, 2)`` -> ``(..., 4)``."""
    q = np.asarray(quads, dtype=np.float64)
    if q.ndim < 2 or q.shape[-2:] != (4, 2):
        raise ValueError(f"quadrilaterals must be (..., 4, 2) point arrays, got shape {q.shape}")
    lo, hi = q.min(axis=-2), q.max(axis=-2)
    return np.concatenate([lo, hi - lo], axis=-1)


def scale_boxes(boxes, factor: float) -> np.ndarray:
    """``(n, 4)`` boxes x, y, w, h scaled about their centres by ``factor``."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    return np.column_stack([boxes[:, :2] + (1 - factor) * boxes[:, 2:] / 2, boxes[:, 2:] * factor])


def boxes_hold(boxes, points) -> np.ndarray:
    """Whether each box ``(n, 4)`` x, y, w, h holds its point ``(n, 2)`` (or one point ``(2,)`` for all boxes)."""
    boxes, points = np.asarray(boxes, np.float64), np.asarray(points, np.float64)
    return ((points[..., 0] >= boxes[:, 0]) & (points[..., 0] <= boxes[:, 0] + boxes[:, 2])
            & (points[..., 1] >= boxes[:, 1]) & (points[..., 1] <= boxes[:, 1] + boxes[:, 3]))


def centres_agree(boxes, box) -> np.ndarray:
    """Per box of ``(n, 4)``: whether it holds the centre of ``box`` (one x, y, w, h) and ``box`` holds its centre
    (the two agree on where the object is, whatever their sizes and IoU)."""
    boxes, box = np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(box, np.float64)
    return boxes_hold(boxes, box[:2] + box[2:] / 2) & boxes_hold(box[None], boxes[:, :2] + boxes[:, 2:] / 2)
