"""2-D overlays that image viewers draw on the picture (issue #16, item 9): one ImageMarker LINE_LIST
per frame with every box / polygon in pixels; the 3-D MarkerArray twins stay for compatibility."""
from __future__ import annotations

import numpy as np
from visualization_msgs.msg import ImageMarker, MarkerArray

from aircraft_docking_tracker.io.bag import BagReader, BagWriter
from aircraft_docking_tracker.ros.markers import boxes_to_image_marker, id_color, polygon_image_marker
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, TRACK_DTYPE, table_to_cloud
from aircraft_docking_tracker.offline import OfflineRun
from aircraft_docking_tracker.scenarios.messages import header
from multi_target_tracker.association_node import AssociationProcessor


def tracks(rows):
    t = np.zeros(len(rows), TRACK_DTYPE)
    for k, (i, x, y, w, h) in enumerate(rows):
        t[k]["id"], t[k]["x"], t[k]["y"], t[k]["w"], t[k]["h"], t[k]["state"] = i, x, y, w, h, 1
    return t


def segments(marker):
    pts = [(p.x, p.y) for p in marker.points]
    return list(zip(pts[0::2], pts[1::2]))


def test_every_box_in_one_line_list_in_pixels_coloured_by_id():
    hdr = header(5_000_000_000, "cam0")
    m = boxes_to_image_marker(tracks([(3, 10, 20, 30, 40), (8, 100, 50, 20, 10)]), hdr, "tracks", label_field="id")
    assert isinstance(m, ImageMarker) and m.type == ImageMarker.LINE_LIST and m.header == hdr
    assert len(m.points) == 16 and len(m.outline_colors) == 16     # 2 boxes x 4 edges x 2 ends
    edges = segments(m)
    assert ((10.0, 20.0), (40.0, 20.0)) in edges and ((120.0, 60.0), (100.0, 60.0)) in edges
    assert all(p.z == 0.0 for p in m.points)
    colours = {(round(c.r, 3), round(c.g, 3), round(c.b, 3)) for c in m.outline_colors}
    assert colours == {tuple(round(v, 3) for v in id_color(3)), tuple(round(v, 3) for v in id_color(8))}
    trailed = boxes_to_image_marker(tracks([(3, 10, 20, 30, 40)]), hdr, "tracks", label_field="id",
                                    trails={3: [(0, 0), (5, 5), (10, 10)]})
    assert len(segments(trailed)) == 4 + 2


def test_empty_frames_clear_the_overlay_and_lost_polygons_draw_nothing():
    hdr = header(0)
    assert len(boxes_to_image_marker(np.zeros(0, DETECTION_DTYPE), hdr, "detections").points) == 0
    assert len(polygon_image_marker(hdr, "docking", None).points) == 0
    assert len(polygon_image_marker(hdr, "docking", np.full((4, 2), np.nan)).points) == 0
    quad = np.array([[10, 10], [50, 12], [48, 40], [8, 38]], float)
    assert len(segments(polygon_image_marker(hdr, "docking", quad))) == 4


def test_association_publishes_the_overlay_and_keeps_the_legacy_markers(tmp_path):
    processor = AssociationProcessor()
    runner = OfflineRun({"association": processor})
    assert processor.outputs["tracks/image_markers"] == "visualization_msgs/msg/ImageMarker"
    det = np.zeros(2, DETECTION_DTYPE)
    det["x"], det["y"], det["w"], det["h"], det["score"] = [10, 200], [10, 50], 20, 20, 1.0
    out = []
    for k in range(5):
        out = dict(runner.feed("detections", table_to_cloud(det, header(k * 100_000_000))))
    assert isinstance(out["tracks/markers"], MarkerArray)
    overlay = out["tracks/image_markers"]
    assert isinstance(overlay, ImageMarker) and len(overlay.points) >= 16
    with BagWriter(tmp_path / "o.mcap") as bag:                  # and it records and reads back
        bag.write("tracks/image_markers", overlay, 1)
    (_, back, _), = BagReader(tmp_path / "o.mcap").ros_messages()
    assert [(p.x, p.y) for p in back.points] == [(p.x, p.y) for p in overlay.points]


def test_the_foxglove_layout_shows_the_demo_recording():
    """config/foxglove_demo_layout.json: each camera's image with its overlays, and rate / latency plots
    from /diagnostics of every demo node; every name it uses is one the demo really records."""
    import json
    import re

    from aircraft_docking_tracker.offline import processor_spec

    from conftest import REPO
    from test_demo_report import load_demo

    layout = json.loads((REPO / "config" / "foxglove_demo_layout.json").read_text())
    panels = layout["configById"]

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])
    assert sorted(leaves(layout["layout"])) == sorted(panels)
    cameras = load_demo().CAMERAS
    node_of_exe = {"detector_node": "detector", "association_node": "association",
                   "docking_tracker_node": "docking_tracker"}
    overlays, nodes = set(), set()
    for ns, (_, _, _, exes, *_rest) in cameras.items():
        for exe in exes:
            name = node_of_exe[exe]
            nodes.add(f"/{ns}/{name}")
            processor = processor_spec(name).build(processor_spec(name).configs_from_parameters({}))
            overlays |= {f"/{ns}/{t}" for t, kind in processor.outputs.items() if kind.endswith("/ImageMarker")}
    images = [p["imageMode"] for k, p in panels.items() if k.startswith("Image!")]
    assert {m["imageTopic"] for m in images} == {f"/{ns}/image" for ns in cameras}
    shown = {t for m in images for t, v in m["annotations"].items()}
    assert shown <= overlays and {f"/{ns}/docking/image_markers" for ns in ["stand"]} <= shown
    plotted = set()
    for key, panel in panels.items():
        if key.startswith("Plot!"):
            for path in panel["paths"]:
                assert path["enabled"] and path["value"].startswith("/diagnostics.status[:]")
                node, value = re.search(r'hardware_id=="([^"]+)"}\.values\[:\]{key=="([^"]+)"}', path["value"]).groups()
                plotted.add((node, value))
    assert {n for n, _ in plotted} == nodes
    assert {"rate_hz", "processing_ms_p50"} <= {v for _, v in plotted}
