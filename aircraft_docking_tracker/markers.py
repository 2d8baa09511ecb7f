"""``visualization_msgs/MarkerArray`` twins of our outputs, for RViz and Foxglove.

Markers are drawn in the image plane of the camera frame: x, y are pixels, z is 0. Every array
starts with a DELETEALL marker so that objects gone since the last message disappear.
"""
from __future__ import annotations

import colorsys
from typing import Iterable, Sequence

import numpy as np


def id_color(object_id: int) -> tuple[float, float, float]:
    """A stable, well-spread RGB colour for an id (golden-ratio hue steps)."""
    hue = (int(object_id) * 0.618033988749895) % 1.0
    return colorsys.hsv_to_rgb(hue, 0.85, 1.0)


def _marker(header, ns: str, marker_id: int, kind: int, color, scale: float = 2.0):
    from visualization_msgs.msg import Marker  # noqa: PLC0415

    m = Marker()
    m.header = header
    m.ns = ns
    m.id = int(marker_id)
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = float(scale)
    m.color.r, m.color.g, m.color.b = (float(c) for c in color)
    m.color.a = 1.0
    return m


def _points(xy: Iterable[Sequence[float]], closed: bool):
    from geometry_msgs.msg import Point  # noqa: PLC0415

    pts = [Point(x=float(x), y=float(y), z=0.0) for x, y in xy]
    if closed and pts:
        pts.append(pts[0])
    return pts


def polygon_marker(header, ns: str, marker_id: int, xy, color=(0.1, 1.0, 0.2), width: float = 2.0):
    """A closed LINE_STRIP through the polygon's vertices (pixels)."""
    from visualization_msgs.msg import Marker  # noqa: PLC0415

    m = _marker(header, ns, marker_id, Marker.LINE_STRIP, color, width)
    m.points = _points(xy, closed=True)
    return m


def text_marker(header, ns: str, marker_id: int, x: float, y: float, text: str, color=(1.0, 1.0, 1.0),
                height: float = 12.0):
    from visualization_msgs.msg import Marker  # noqa: PLC0415

    m = _marker(header, ns, marker_id, Marker.TEXT_VIEW_FACING, color, height)
    m.pose.position.x, m.pose.position.y = float(x), float(y)
    m.text = text
    return m


def delete_all(header, ns: str = ""):
    from visualization_msgs.msg import Marker  # noqa: PLC0415

    m = Marker()
    m.header = header
    m.ns = ns
    m.action = Marker.DELETEALL
    return m


def boxes_to_markers(table: np.ndarray, header, ns: str, *, label_field: str | None = None,
                     trails: dict[int, Sequence[tuple[float, float]]] | None = None, color=None):
    """A MarkerArray with one box per row of an object table (x, y, w, h in pixels).

    ``label_field`` (e.g. ``"id"``) adds a text label and colours boxes by that value;
    ``trails`` maps an id to its recent centre points, drawn as open line strips.
    """
    from visualization_msgs.msg import Marker, MarkerArray  # noqa: PLC0415

    array = MarkerArray()
    array.markers.append(delete_all(header, ns))
    for index, row in enumerate(table):
        key = int(row[label_field]) if label_field else index
        rgb = color or (id_color(key) if label_field else (0.1, 1.0, 0.2))
        x, y, w, h = (float(row[f]) for f in ("x", "y", "w", "h"))
        array.markers.append(polygon_marker(header, ns, 3 * index, [(x, y), (x + w, y), (x + w, y + h), (x, y + h)], rgb))
        if label_field:
            array.markers.append(text_marker(header, ns, 3 * index + 1, x, y - 4.0, f"{label_field} {key}", rgb))
        if trails and label_field and key in trails and len(trails[key]) > 1:
            trail = _marker(header, ns, 3 * index + 2, Marker.LINE_STRIP, rgb, 1.0)
            trail.points = _points(trails[key], closed=False)
            array.markers.append(trail)
    return array
