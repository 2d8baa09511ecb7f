"""MOTChallenge text files: ``det.txt`` / ``gt.txt`` in, tracking results out (no ROS here).

The one place in the repository that reads and writes the MOTChallenge format
(Milan et al., "MOT16: A Benchmark for Multi-Object Tracking", arXiv:1603.00831, §3.3):

    frame, id, bb_left, bb_top, bb_width, bb_height, conf, x|class, y|visibility, z

one row per box, frames 1-based, boxes in pixels with (bb_left, bb_top) the top-left corner.
``det.txt`` has ``id = -1`` and the detector score in ``conf``; ``gt.txt`` has the target id and in
``conf`` a flag (0 = ignore this box in evaluation); MOT16+ also give the class in column 8.
Results files use the ``det.txt`` layout with the track id and ``-1`` in columns 8-10.
"""
from __future__ import annotations

import configparser
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..geometry import box_iou
from ..object_table import table_boxes as boxes  # noqa: F401 (MOT rows: x, y, w, h)

#: One MOTChallenge row. ``cls`` and ``visibility`` are -1 where the file does not give them.
MOT_ROW_DTYPE = np.dtype([
    ("frame", np.int32), ("id", np.int32),
    ("x", np.float64), ("y", np.float64), ("w", np.float64), ("h", np.float64),
    ("score", np.float64), ("cls", np.int32), ("visibility", np.float64),
])


class MotFormatError(ValueError):
    """A MOTChallenge file that cannot be read (missing columns, non-numbers, frames out of range)."""


#: Largest frame number read by default: 1,000,000 frames are 9 h at 30 fps (MOTChallenge
#: sequences have at most a few thousand). A tracker steps through every frame up to the last, so
#: one row with frame 2,000,000,000 would otherwise mean two billion steps.
MAX_FRAME = 1_000_000


def read_mot(path: str | Path, max_frame: int = MAX_FRAME) -> np.ndarray:
    """Read a MOTChallenge ``det.txt`` / ``gt.txt`` / results file into ``MOT_ROW_DTYPE`` rows.

    Commas or whitespace separate the columns; at least the first six are required. Frame numbers
    must be whole numbers from 0 to ``max_frame``, ids whole numbers (else MotFormatError with the line).
    Rows are returned sorted by frame (stable, so the file's order within a frame is kept).
    """
    path = Path(path)
    rows = []
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise MotFormatError(f"{path}: cannot read ({exc})") from None
    limit = 2**31 - 1
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        if len(fields) < 6:
            raise MotFormatError(f"{path}:{number}: {len(fields)} columns, MOTChallenge needs at least 6")
        try:
            values = [float(v) for v in fields[:9]]
        except ValueError as exc:
            raise MotFormatError(f"{path}:{number}: {exc}") from None
        values += [-1.0] * (9 - len(values))
        if len(fields) < 7:
            values[6] = 1.0
        frame, ident, cls = values[0], values[1], values[7]
        if not (np.isfinite(frame) and frame == int(frame) and 0 <= frame <= max_frame):
            raise MotFormatError(f"{path}:{number}: frame {fields[0]} is not a whole number from 0 to {max_frame}")
        for name, v in (("id", ident), ("class", cls)):
            if not (np.isfinite(v) and v == int(v) and -limit <= v <= limit):
                raise MotFormatError(f"{path}:{number}: {name} {v:g} is not a 32-bit whole number")
        rows.append((int(values[0]), int(values[1]), *values[2:7], int(values[7]), values[8]))
    table = np.array(rows, dtype=MOT_ROW_DTYPE)
    return table[np.argsort(table["frame"], kind="stable")]


def read_detections(path: str | Path, min_score: float | None = None, max_frame: int = MAX_FRAME) -> np.ndarray:
    """``det.txt`` rows, keeping only those with ``score >= min_score`` when it is given."""
    rows = read_mot(path, max_frame)
    if min_score is not None:
        rows = rows[rows["score"] >= min_score]
    return rows


def read_ground_truth(path: str | Path, classes: Iterable[int] | None = None, max_frame: int = MAX_FRAME) -> np.ndarray:
    """``gt.txt`` rows that count in evaluation: ``conf`` flag not 0, and class in ``classes``.

    MOT15 files (TUD-Campus) have flag 1 and class -1 throughout, so everything is kept; MOT16+
    files mark distractors with flag 0. ``classes=None`` keeps every class.
    """
    rows = read_mot(path, max_frame)
    rows = rows[rows["score"] != 0]
    if classes is not None:
        rows = rows[np.isin(rows["cls"], list(classes)) | (rows["cls"] == -1)]
    return rows



def frames(rows: np.ndarray, first: int | None = None, last: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame, rows of that frame)`` for every frame from ``first`` to ``last`` inclusive.

    Frames without rows yield an empty array, so a tracker sees every frame (and its misses).
    Defaults: 1 (MOTChallenge frames are 1-based) to the last frame present.
    """
    rows = rows[np.argsort(rows["frame"], kind="stable")]
    first = 1 if first is None else int(first)
    if last is None:
        last = int(rows["frame"].max()) if len(rows) else first - 1
    frame_numbers = rows["frame"]
    start = int(np.searchsorted(frame_numbers, first))
    for frame in range(first, last + 1):     # no per-frame table: memory does not grow with ``last``
        end = int(np.searchsorted(frame_numbers, frame + 1, side="left"))
        yield frame, rows[start:end]
        start = end


def read_seqinfo(path: str | Path) -> dict:
    """The ``[Sequence]`` section of a ``seqinfo.ini`` as a dict (frameRate, seqLength as numbers).

    ``path`` may be the file or the sequence folder; a missing file gives an empty dict.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "seqinfo.ini"
    if not path.is_file():
        return {}
    parser = configparser.ConfigParser()
    parser.optionxform = str
    try:
        parser.read(path)
    except (configparser.Error, UnicodeDecodeError) as exc:
        raise MotFormatError(f"{path}: not a seqinfo.ini ({str(exc).splitlines()[0]})") from None
    if "Sequence" not in parser:
        return {}
    info: dict = dict(parser["Sequence"])
    for key in ("frameRate", "seqLength", "imWidth", "imHeight"):
        if key in info:
            try:
                info[key] = float(info[key]) if key == "frameRate" else int(info[key])
            except ValueError:
                raise MotFormatError(f"{path}: {key}={info[key]!r} is not a number") from None
    return info


def seqinfo_disagreements(info: dict, rows: np.ndarray, what: str = "det.txt") -> list[str]:
    """Where a ``seqinfo.ini`` (:func:`read_seqinfo`) contradicts the rows of a MOTChallenge file.

    Checked: ``seqLength`` against the last frame, ``imWidth`` / ``imHeight`` against the boxes
    (a box lying wholly outside the image). An empty list when they agree or nothing is given.
    """
    out = []
    if not len(rows):
        return out
    last = int(rows["frame"].max())
    length = info.get("seqLength")
    if length is not None and last > length:
        beyond = int((rows["frame"] > length).sum())
        out.append(f"seqinfo.ini says seqLength={length} but {what} has frames up to {last} "
                   f"({beyond} rows after frame {length}); every frame of the data is used")
    width, height = info.get("imWidth"), info.get("imHeight")
    if width and height:
        outside = (rows["x"] >= width) | (rows["y"] >= height) | (rows["x"] + rows["w"] <= 0) | \
            (rows["y"] + rows["h"] <= 0)
        if outside.any():
            out.append(f"seqinfo.ini says the image is {width}x{height} but {int(outside.sum())} boxes of {what} "
                       f"lie wholly outside it")
    return out


def score_scale_of(scores: np.ndarray) -> float:
    """What detection scores are out of: 1 for fractions (all finite scores in [0, 1]), 100 for percent
    (some above 1, none above 100). Raises :class:`MotFormatError` for anything else (negative
    or above 100), which the caller must declare."""
    scores = np.asarray(scores, dtype=np.float64)
    scores = scores[np.isfinite(scores)]
    if not len(scores) or (scores.min() >= 0 and scores.max() <= 1):
        return 1.0
    if scores.min() >= 0 and scores.max() <= 100:
        return 100.0
    raise MotFormatError(f"detection scores from {scores.min():g} to {scores.max():g} are neither fractions nor "
                         "percent: declare their scale (--score-scale)")


def make_rows(frame: int, ids: np.ndarray, xywh: np.ndarray, scores: np.ndarray | None = None) -> np.ndarray:
    """Build ``MOT_ROW_DTYPE`` rows for one frame from ids and ``(N, 4)`` boxes (results, tests)."""
    xywh = np.asarray(xywh, dtype=np.float64).reshape(-1, 4)
    out = np.zeros(len(xywh), dtype=MOT_ROW_DTYPE)
    out["frame"] = frame
    out["id"] = np.asarray(ids).reshape(-1)
    out["x"], out["y"], out["w"], out["h"] = xywh.T
    out["score"] = 1.0 if scores is None else np.asarray(scores, dtype=np.float64).reshape(-1)
    out["cls"] = -1
    out["visibility"] = -1
    return out


def write_results(path: str | Path, rows: np.ndarray) -> None:
    """Write tracking results in the MOTChallenge layout ``frame,id,x,y,w,h,conf,-1,-1,-1``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = rows[np.lexsort((rows["id"], rows["frame"]))]
    with path.open("w") as out:
        for r in rows:
            out.write(f"{r['frame']},{r['id']},{r['x']:.2f},{r['y']:.2f},{r['w']:.2f},{r['h']:.2f},"
                      f"{r['score']:.4g},-1,-1,-1\n")


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every box in ``a`` (M, 4) with every box in ``b`` (N, 4), x, y, w, h: an (M, N) array."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    return box_iou(a[:, None, :], b[None, :, :])
