"""Visual twins of our outputs: 2-D ``ImageMarker`` overlays, and the legacy 3-D ``MarkerArray``.

**Image overlays** (``*/image_markers``, ``visualization_msgs/ImageMarker``): pixel coordinates on
the image they came from (same header), which image viewers draw over the picture — Foxglove's
Image panel (pick the topic under "annotations"), ``rqt_image_overlay``, ``image_view``-style
tools. One ``LINE_LIST`` per frame carries every box or polygon (two points per edge, one colour
per point: by track id for tracks), so each message replaces the previous overlay whole and an empty
one clears it. ``ImageMarker`` has no text: track ids are told apart by colour (the same colour as
in ``tracks/image`` and the MarkerArray labels), and a track's trail is drawn as more segments.

**3-D markers** (``*/markers``, ``MarkerArray``): the same shapes with x, y in pixels and z = 0 in
the camera frame — they do not mean metres, so RViz's 3-D view shows them hundreds of "metres"
wide. Kept only for compatibility with set-ups that already subscribe to them; new set-ups should
use the image overlays. Every array starts with a DELETEALL marker so that objects gone since the
last message disappear.
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


# ----------------------------------------------------------------------------------------------
# 2-D overlays: visualization_msgs/ImageMarker
def _rgba(rgb, alpha: float = 1.0):
    from std_msgs.msg import ColorRGBA  # noqa: PLC0415

    r, g, b = (float(c) for c in rgb)
    return ColorRGBA(r=r, g=g, b=b, a=float(alpha))


def box_segments(x: float, y: float, w: float, h: float) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The four edges of an axis-aligned box (pixels, top-left corner and size)."""
    return polygon_segments([(x, y), (x + w, y), (x + w, y + h), (x, y + h)])


def polygon_segments(xy) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The edges of a closed polygon (pixels)."""
    pts = [(float(x), float(y)) for x, y in xy]
    return [(pts[k], pts[(k + 1) % len(pts)]) for k in range(len(pts))] if len(pts) > 1 else []


def image_line_list(header, ns: str, segments, colors, width: float = 2.0, marker_id: int = 0):
    """One ``ImageMarker`` LINE_LIST: ``segments`` [((x0, y0), (x1, y1)), ...] in pixels, ``colors``
    one RGB per segment. Non-finite segments are left out (a lost track's NaN corners)."""
    from geometry_msgs.msg import Point  # noqa: PLC0415
    from visualization_msgs.msg import ImageMarker  # noqa: PLC0415

    m = ImageMarker()
    m.header = header
    m.ns = ns
    m.id = int(marker_id)
    m.type = ImageMarker.LINE_LIST
    m.action = ImageMarker.ADD
    m.scale = float(width)
    m.outline_color = _rgba(colors[0] if len(colors) else (0.1, 1.0, 0.2))
    for (p0, p1), rgb in zip(segments, colors):
        if not np.isfinite([*p0, *p1]).all():
            continue
        m.points += [Point(x=float(p0[0]), y=float(p0[1]), z=0.0), Point(x=float(p1[0]), y=float(p1[1]), z=0.0)]
        m.outline_colors += [_rgba(rgb), _rgba(rgb)]
    return m


def boxes_to_image_marker(table: np.ndarray, header, ns: str, *, label_field: str | None = None,
                          trails: dict[int, Sequence[tuple[float, float]]] | None = None, color=None,
                          width: float = 2.0):
    """Every row of an object table (x, y, w, h in pixels) as one LINE_LIST overlay; with
    ``label_field`` (``"id"``) coloured by that value, ``trails`` (id -> centres) drawn as segments."""
    segments, colors = [], []
    for row in table:
        key = int(row[label_field]) if label_field else 0
        rgb = color or (id_color(key) if label_field else (0.1, 1.0, 0.2))
        edges = box_segments(*(float(row[f]) for f in ("x", "y", "w", "h")))
        if trails and label_field and key in trails and len(trails[key]) > 1:
            pts = [(float(x), float(y)) for x, y in trails[key]]
            edges += list(zip(pts[:-1], pts[1:]))
        segments += edges
        colors += [rgb] * len(edges)
    return image_line_list(header, ns, segments, colors, width)


def polygon_image_marker(header, ns: str, xy=None, color=(0.1, 1.0, 0.2), width: float = 2.0):
    """A closed polygon (pixels) as a LINE_LIST overlay; ``xy`` None: an empty one (clears the overlay)."""
    segments = polygon_segments(xy) if xy is not None else []
    return image_line_list(header, ns, segments, [color] * len(segments), width)


def line_strip_marker(header, ns: str, marker_id: int, xyz, color, width: float = 0.2):
    """An open LINE_STRIP through 3-D points (the header's frame, e.g. metres on a stand)."""
    from geometry_msgs.msg import Point  # noqa: PLC0415
    from visualization_msgs.msg import Marker  # noqa: PLC0415

    m = _marker(header, ns, marker_id, Marker.LINE_STRIP, color, width)
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in xyz]
    return m


def sphere_marker(header, ns: str, marker_id: int, xyz, color, diameter: float = 1.0):
    from visualization_msgs.msg import Marker  # noqa: PLC0415

    m = _marker(header, ns, marker_id, Marker.SPHERE, color, diameter)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in xyz)
    return m
