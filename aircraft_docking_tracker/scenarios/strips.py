"""Image strips: scene frames or bag images side by side, ground truth (green) and results (magenta)
drawn in (OpenCV only: no matplotlib, no ROS). Used by ``make_scenario --strip``, the evaluation
report's strips and ``bench/strips``.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from aircraft_docking_tracker.object_table import table_boxes

GT_COLOR = (60, 220, 60)          # BGR
RESULT_COLOR = (230, 40, 230)
HIDDEN_COLOR = (40, 40, 230)


def draw_annotations(image: np.ndarray, quads=(), boxes=(), color=GT_COLOR, labels=None, point=None,
                     hidden=None) -> np.ndarray:
    """A copy of ``image`` with quadrilaterals, ``x, y, w, h`` boxes (labels), and a point drawn in."""
    out = image.copy()
    for quad in quads:
        if np.isfinite(np.asarray(quad, float)).all():
            cv2.polylines(out, [np.round(np.asarray(quad)).astype(np.int32)], True, color, 2, cv2.LINE_AA)
    for k, (x, y, w, h) in enumerate(np.asarray(boxes, float).reshape(-1, 4)):
        c = HIDDEN_COLOR if hidden is not None and hidden[k] else color
        cv2.rectangle(out, (int(x), int(y)), (int(x + w), int(y + h)), c, 1, cv2.LINE_AA)
        if labels is not None:
            cv2.putText(out, str(labels[k]), (int(x), int(y) - 2), cv2.FONT_HERSHEY_SIMPLEX, 0.35, c, 1, cv2.LINE_AA)
    if point is not None and np.isfinite(np.asarray(point, float)).all():
        cv2.drawMarker(out, (int(point[0]), int(point[1])), color, cv2.MARKER_CROSS, 12, 2)
    return out


def annotate_scene_frame(frame) -> np.ndarray:
    """Ground truth drawn on a ``DockingFrame`` (quad, nose) or ``UavFrame`` (boxes, ids; hidden red)."""
    if hasattr(frame, "quad"):
        return draw_annotations(frame.image, quads=[frame.quad], point=frame.nose)
    gt = frame.ground_truth
    return draw_annotations(frame.image, boxes=table_boxes(gt), labels=gt["id"].tolist(), hidden=(gt["state"] == 2).tolist())


def strip_image(frames, tile_width: int = 427, caption: str = "", numbers=None) -> np.ndarray:
    """Scene frames (annotated with their ground truth) or plain images side by side, frame numbers
    (``numbers``, else the scene frame's index, else the position) on top."""
    tiles = []
    for k, frame in enumerate(frames):
        image = annotate_scene_frame(frame) if hasattr(frame, "image") else np.asarray(frame)
        scale = tile_width / image.shape[1]
        tile = cv2.resize(image, (tile_width, int(round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
        number = numbers[k] if numbers is not None else getattr(frame, "index", k)
        label = f"{caption + ' ' if caption and k == 0 else ''}frame {number}"
        cv2.putText(tile, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 2, cv2.LINE_AA)
        cv2.putText(tile, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(tile)
    if not tiles:
        raise ValueError("frame strip: no frames")
    height = max(t.shape[0] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, height - t.shape[0], 0, 2, cv2.BORDER_CONSTANT, value=(255, 255, 255))
             for t in tiles]
    return np.hstack(tiles)


def frame_strip(frames, path: str | Path, tile_width: int = 427, numbers=None) -> Path:
    """:func:`strip_image` written as a PNG."""
    return write_image(strip_image(frames, tile_width, numbers=numbers), path)


def write_image(image: np.ndarray, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")
    return path
