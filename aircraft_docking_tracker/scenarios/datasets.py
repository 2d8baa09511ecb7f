"""Readers of the real datasets' files (no ROS): OTB / TinyTLP boxes, frame folders, YOLO labels.

Conventions of the files, and what they become here (0-based pixels, top-left corner, ``x, y, w, h``):

* OTB ``groundtruth_rect.txt``: one ``x,y,w,h`` per frame (commas, tabs or spaces), **1-based**
  pixels (the OTB toolkit's MATLAB convention) -> 1 is subtracted from x and y;
* TinyTLP ``groundtruth_rect.txt``: ``frame,x,y,w,h,lost`` per line -> x, y kept as they are
  (TLP gives no base; its boxes are read as 0-based) and frames with ``lost = 1`` become NaN
  (target absent: not scored);
* YOLO ``labels/*.txt``: ``class cx cy w h`` normalised to the image -> pixel boxes;
* MOTChallenge files are read by ``aircraft_docking_tracker.io.motchallenge`` (the one reader of them).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from aircraft_docking_tracker.geometry import box_to_quad
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, TRACK_DTYPE

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


class DatasetError(ValueError):
    """A dataset file or folder that cannot be read; the message names the file and the reason."""


def _rows(path: Path) -> list[list[float]]:
    """Numbers per non-empty line, split at commas, tabs or spaces."""
    if not path.is_file():
        raise DatasetError(f"{path}: no such file")
    out = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            out.append([float(v) for v in re.split(r"[,\s]+", line)])
        except ValueError:
            raise DatasetError(f"{path}:{number}: not a row of numbers: {line[:60]!r}") from None
    return out


def read_sot_boxes(path: str | Path) -> tuple[np.ndarray, str]:
    """Boxes ``(N, 4)`` (0-based, NaN where the target is lost) and the format ("otb" or "tlp")."""
    path = Path(path)
    rows = _rows(path)
    if not rows:
        raise DatasetError(f"{path}: no boxes")
    widths = {len(r) for r in rows}
    if widths == {4}:
        boxes = np.array(rows, np.float64)
        boxes[:, :2] -= 1.0
        return boxes, "otb"
    if widths == {6}:
        table = np.array(rows, np.float64)
        boxes = table[:, 1:5].copy()
        boxes[table[:, 5] != 0] = np.nan
        return boxes, "tlp"
    raise DatasetError(f"{path}: rows of {sorted(widths)} numbers; OTB has 4 (x,y,w,h), TLP 6 (frame,x,y,w,h,lost)")


def read_results_regions(path: str | Path) -> np.ndarray:
    """A tracker's results file: ``x,y,w,h`` per line (OTB layout, 0-based as our tools write it)
    or ``x1,y1,...,x4,y4`` quadrilaterals (TL, TR, BR, BL) -> ``(N, 4, 2)`` quadrilaterals."""
    rows = _rows(Path(path))
    widths = {len(r) for r in rows}
    if widths == {4}:
        return box_to_quad(np.array(rows, np.float64))
    if widths == {8}:
        return np.array(rows, np.float64).reshape(-1, 4, 2)
    raise DatasetError(f"{path}: results need 4 (x,y,w,h) or 8 (quadrilateral) numbers per line, found {sorted(widths)}")


def list_frames(folder: str | Path) -> list[Path]:
    """The image files of a frame folder (its ``img/`` or ``images/`` subfolder if present), sorted."""
    folder = Path(folder)
    for sub in ("img", "images", "img1"):
        if (folder / sub).is_dir():
            folder = folder / sub
            break
    if not folder.is_dir():
        raise DatasetError(f"{folder}: no such folder")
    frames = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not frames:
        raise DatasetError(f"{folder}: no image files ({', '.join(IMAGE_SUFFIXES)})")
    return frames


def read_yolo_labels(path: str | Path, width: int, height: int) -> np.ndarray:
    """YOLO ``class cx cy w h`` (normalised) -> ``DETECTION_DTYPE`` rows in pixels (score 1).

    A missing file means no objects (YOLO's convention for background tiles).
    """
    path = Path(path)
    if not path.exists():
        return np.zeros(0, DETECTION_DTYPE)
    rows = _rows(path)
    out = np.zeros(len(rows), DETECTION_DTYPE)
    for k, r in enumerate(rows):
        if len(r) != 5:
            raise DatasetError(f"{path}: row {k + 1} has {len(r)} numbers, YOLO labels have 5")
        cls, cx, cy, w, h = r
        out[k] = ((cx - w / 2) * width, (cy - h / 2) * height, w * width, h * height, 1.0, int(cls))
    return out


def mot_rows_to_tracks(rows: np.ndarray, previous: dict | None = None, fps: float = 0.0) -> np.ndarray:
    """One frame's MOTChallenge rows (``motchallenge.MOT_ROW_DTYPE``) -> ``TRACK_DTYPE`` rows.

    ``score`` = the row's visibility where the file gives one, else 1; ``state`` 1. With a
    ``previous`` dict carried from frame to frame (and ``fps``), ``vx, vy`` [px/s] and ``age`` come
    from the same id's box one frame earlier.
    """
    table = np.zeros(len(rows), TRACK_DTYPE)
    table["id"] = rows["id"]
    for name in ("x", "y", "w", "h"):
        table[name] = rows[name]
    table["score"] = np.where(rows["visibility"] >= 0, rows["visibility"], 1.0)
    table["class_id"] = np.maximum(rows["cls"], 0)
    table["state"] = 1
    if previous is None:
        return table
    for k, r in enumerate(rows):
        centre = np.array([r["x"] + r["w"] / 2, r["y"] + r["h"] / 2])
        prev = previous.get(int(r["id"]))
        if prev is not None and prev[0] == r["frame"] - 1:
            table["vx"][k], table["vy"][k] = (centre - prev[1]) * fps
            table["age"][k] = prev[2] + 1
        previous[int(r["id"])] = (int(r["frame"]), centre, int(table["age"][k]))
    return table


def dataset_kind(folder: str | Path) -> str:
    """"sot", "mot" or "detect", from what the folder holds."""
    folder = Path(folder)
    if (folder / "det.txt").is_file() or (folder / "gt.txt").is_file() or (folder / "det" / "det.txt").is_file():
        return "mot"
    if (folder / "labels").is_dir():
        return "detect"
    if (folder / "groundtruth_rect.txt").is_file():
        return "sot"
    raise DatasetError(f"{folder}: not a sot (groundtruth_rect.txt), mot (det.txt / gt.txt) or detect "
                       "(images/ + labels/) dataset folder")
