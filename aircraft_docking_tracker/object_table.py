"""Lists of objects as ``sensor_msgs/PointCloud2`` with named, typed fields (one point per object).

A table is a numpy structured array; its field names and types become the cloud's ``PointField``
entries, so any ROS tool reads it with ``sensor_msgs_py.point_cloud2.read_points(msg,
field_names=...)`` and we read it back with :func:`cloud_to_table` (no sensor_msgs_py on PyPI).
"""
from __future__ import annotations

import numpy as np

# PointField datatype constants (sensor_msgs/PointField).
_POINTFIELD_TO_DTYPE = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_DTYPE_TO_POINTFIELD = {np.dtype(v).newbyteorder("<").str: k for k, v in _POINTFIELD_TO_DTYPE.items()}

#: A detection: top-left corner x, y and size w, h in pixels, a score, a class id.
DETECTION_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("w", "<f4"), ("h", "<f4"),
                            ("score", "<f4"), ("class_id", "<i4")])
#: A detection with the optional ``low_confidence`` flag (uint8, 1: a group the detector's verifier scored between
#: its low threshold and ``verifier_threshold``, published only for the association's second pass, never to start a
#: track; 0: a detection as any other). Only a detector with ``low_confidence_band`` > 0 adds the field; a reader
#: asking for :data:`DETECTION_DTYPE` ignores it, so a reader that does not know it must drop flagged rows with
#: :func:`confident_rows` first.
LOW_CONFIDENCE = "low_confidence"
FLAGGED_DETECTION_DTYPE = np.dtype(DETECTION_DTYPE.descr + [(LOW_CONFIDENCE, "u1")])
#: A track: stable id, box (px), velocity (px/s), score, class, age and missed frames, state.
TRACK_DTYPE = np.dtype([("id", "<i4"), ("x", "<f4"), ("y", "<f4"), ("w", "<f4"), ("h", "<f4"),
                        ("vx", "<f4"), ("vy", "<f4"), ("score", "<f4"), ("class_id", "<i4"),
                        ("age", "<i4"), ("misses", "<i4"), ("state", "<i4")])
TRACK_STATES = {0: "tentative", 1: "confirmed", 2: "coasting", 3: "lost"}


class ObjectTableError(ValueError):
    """A cloud or array that is not a valid object table; the message says why."""


def empty(dtype: np.dtype) -> np.ndarray:
    return np.zeros(0, dtype=dtype)


def table_boxes(table: np.ndarray) -> np.ndarray:
    """``(N, 4)`` float64 array ``x, y, w, h`` (top-left corner, pixels) of any table with those fields
    (detections, tracks, MOTChallenge rows)."""
    return np.stack([table["x"], table["y"], table["w"], table["h"]], axis=1).astype(np.float64)


def low_confidence(table: np.ndarray) -> np.ndarray:
    """Boolean mask of the rows flagged ``low_confidence`` (all False for a table without the field)."""
    if table.dtype.names is None or LOW_CONFIDENCE not in table.dtype.names:
        return np.zeros(len(table), dtype=bool)
    return np.asarray(table[LOW_CONFIDENCE]) != 0


def confident_rows(table: np.ndarray) -> np.ndarray:
    """The rows not flagged ``low_confidence`` (the detections proper; the table itself without the field)."""
    low = low_confidence(table)
    return table[~low] if low.any() else table


def table_to_cloud(table: np.ndarray, header=None):
    """A PointCloud2 (height 1, one point per row, little-endian, dense) holding ``table``."""
    from sensor_msgs.msg import PointCloud2, PointField  # noqa: PLC0415

    table = np.asarray(table)
    if table.dtype.names is None:
        raise ObjectTableError("object table must be a numpy structured array")
    fields, offset, packed_types = [], 0, []
    for name in table.dtype.names:
        base = table.dtype.fields[name][0]
        count = 1
        if base.subdtype is not None:
            base, shape = base.subdtype
            count = int(np.prod(shape))
        key = base.newbyteorder("<").str
        if key not in _DTYPE_TO_POINTFIELD:
            raise ObjectTableError(f"field {name!r} has type {base}, which PointCloud2 cannot carry")
        fields.append(PointField(name=name, offset=offset, datatype=_DTYPE_TO_POINTFIELD[key], count=count))
        packed_types.append((name, key, (count,)) if count > 1 else (name, key))
        offset += base.itemsize * count
    packed = np.empty(len(table), dtype=np.dtype(packed_types))
    for name in table.dtype.names:
        packed[name] = table[name]
    msg = PointCloud2()
    if header is not None:
        msg.header = header
    msg.height, msg.width = 1, len(table)
    msg.fields = fields
    msg.is_bigendian = False
    msg.point_step = packed.dtype.itemsize
    msg.row_step = msg.point_step * len(table)
    msg.data = packed.tobytes()
    msg.is_dense = True
    return msg


def cloud_to_table(msg, dtype: np.dtype | None = None) -> np.ndarray:
    """The rows of a PointCloud2 as a packed structured array (native byte order).

    With ``dtype``, the named fields are required and returned in that dtype (extra fields in the
    cloud are ignored); without, every field of the cloud is returned with its own type.
    """
    point_step, count = int(msg.point_step), int(msg.width) * int(msg.height)
    if count and point_step <= 0:
        raise ObjectTableError("cloud has points but point_step is 0")
    data = bytes(msg.data)
    if len(data) < point_step * count:
        raise ObjectTableError(f"cloud data has {len(data)} bytes, {count} points of {point_step} need {point_step * count}")
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if f.datatype not in _POINTFIELD_TO_DTYPE:
            raise ObjectTableError(f"field {f.name!r} has unknown PointField datatype {f.datatype}")
        base = np.dtype(_POINTFIELD_TO_DTYPE[f.datatype]).newbyteorder(order)
        names.append(f.name)
        formats.append((base, (int(f.count),)) if f.count > 1 else base)
        offsets.append(int(f.offset))
    if any(o + np.dtype(fm).itemsize > point_step for o, fm in zip(offsets, formats)):
        raise ObjectTableError("a field lies outside point_step")
    wire = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": max(point_step, 1)})
    rows = np.frombuffer(data, dtype=wire, count=count) if count else np.zeros(0, dtype=wire)
    target = dtype if dtype is not None else np.dtype(
        [(n, wire.fields[n][0].newbyteorder("=")) for n in names])
    missing = [n for n in target.names if n not in names]
    if missing:
        raise ObjectTableError(f"cloud lacks field(s) {', '.join(missing)}")
    out = np.empty(count, dtype=target)
    for name in target.names:
        out[name] = rows[name]
    return out


def records(table: np.ndarray) -> list[dict]:
    """Rows as plain dicts (for printing and JSON)."""
    return [{name: row[name].item() for name in table.dtype.names} for row in table]
