"""Thin ROS layer of the scenario and evaluation tools: topic names, ground-truth messages.

Numpy in, messages out (and back), nothing else: quadrilaterals as ``geometry_msgs/PolygonStamped``
(4 points TL, TR, BR, BL of the template), points as ``geometry_msgs/PointStamped``, object tables
as ``sensor_msgs/PointCloud2`` (``object_table``), images as ``sensor_msgs/Image`` (``images``).
Every message carries the image's stamp and ``frame_id`` "camera".
"""
from __future__ import annotations

import numpy as np

from aircraft_docking_tracker.io.bag import ns_to_stamp, stamp_to_ns
from aircraft_docking_tracker.images import numpy_to_image
from aircraft_docking_tracker.object_table import table_to_cloud

FRAME_ID = "camera"

# agreed bag topics (relative names)
IMAGE = "image"
DETECTIONS = "detections"
TRACKS = "tracks"
DOCKING_POLYGON = "docking/polygon"
DOCKING_STATE = "docking/state"
DOCKING_GUIDANCE = "docking/guidance"
GROUND_TRUTH = "ground_truth"
GT_POLYGON = "ground_truth/polygon"
GT_NOSE = "ground_truth/nose"
GT_STAND = "ground_truth/stand"
GT_GUIDANCE = "ground_truth/guidance"


def header(stamp_ns: int, frame_id: str = FRAME_ID):
    from std_msgs.msg import Header  # noqa: PLC0415

    return Header(stamp=ns_to_stamp(int(stamp_ns)), frame_id=frame_id)


def quad_to_polygon(quad, hdr):
    """``(4, 2)`` pixel quadrilateral -> ``PolygonStamped`` (z = 0); NaN quads give an empty polygon."""
    from geometry_msgs.msg import Point32, PolygonStamped  # noqa: PLC0415

    msg = PolygonStamped(header=hdr)
    quad = np.asarray(quad, np.float64).reshape(-1, 2)
    if np.isfinite(quad).all():
        msg.polygon.points = [Point32(x=float(x), y=float(y), z=0.0) for x, y in quad]
    return msg


def polygon_to_quad(msg) -> np.ndarray:
    """``PolygonStamped`` -> ``(4, 2)`` float64; an empty polygon (target absent / lost) -> NaNs."""
    pts = msg.polygon.points
    if len(pts) == 0:
        return np.full((4, 2), np.nan)
    if len(pts) != 4:
        raise ValueError(f"polygon has {len(pts)} points, a tracked quadrilateral has 4")
    return np.array([[p.x, p.y] for p in pts], np.float64)


def point_msg(xy, hdr):
    from geometry_msgs.msg import PointStamped  # noqa: PLC0415

    msg = PointStamped(header=hdr)
    msg.point.x, msg.point.y = float(xy[0]), float(xy[1])
    return msg


def string_msg(text: str):
    from std_msgs.msg import String  # noqa: PLC0415

    return String(data=text)


def image_msg(bgr: np.ndarray, hdr):
    return numpy_to_image(bgr, "bgr8", hdr)


def cloud_msg(table: np.ndarray, hdr):
    return table_to_cloud(table, hdr)


def stamp_ns_of(msg) -> int:
    """The header stamp of a stamped message, in nanoseconds."""
    return stamp_to_ns(msg.header.stamp)
