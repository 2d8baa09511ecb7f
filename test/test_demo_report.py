"""`make demo`'s report: summary.md holds the tables, not only headings (issue #16, item 8)."""
from __future__ import annotations

import importlib.util
import re

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from aircraft_docking_tracker.io.bag import BagWriter
from aircraft_docking_tracker.evaluation.report import format_markdown
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, TRACK_DTYPE
from aircraft_docking_tracker.scenarios import messages as m

from conftest import REPO


def load_demo():
    spec = importlib.util.spec_from_file_location("demo", REPO / "tools" / "demo.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_recording(path, frames=8):
    """What the demo records, small: both cameras' images, outputs, ground truth and /diagnostics."""
    rng = np.random.default_rng(0)
    with BagWriter(path) as bag:
        for k in range(frames):
            t = 1_000_000_000 + k * 100_000_000
            hdr = m.header(t)
            for ns in ("stand", "uav"):
                bag.write(f"/{ns}/image", m.image_msg(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), hdr), t)
            quad = np.array([[10, 10], [30, 10], [30, 25], [10, 25]], float) + k
            bag.write("/stand/ground_truth/polygon", m.quad_to_polygon(quad, hdr), t)
            bag.write("/stand/docking/polygon", m.quad_to_polygon(quad + 1.0, hdr), t + 20_000_000)
            truth = np.zeros(2, TRACK_DTYPE)
            truth["id"], truth["x"], truth["y"], truth["w"], truth["h"], truth["state"] = [1, 2], [5 + k, 40], 8, 10, 10, 1
            bag.write("/uav/ground_truth", m.cloud_msg(truth, hdr), t)
            dets = np.zeros(2, DETECTION_DTYPE)
            dets["x"], dets["y"], dets["w"], dets["h"], dets["score"] = truth["x"], 8, 10, 10, 1.0
            bag.write("/uav/detections", m.cloud_msg(dets, hdr), t + 30_000_000)
            bag.write("/uav/tracks", m.cloud_msg(truth, hdr), t + 40_000_000)
        status = DiagnosticStatus(name="/uav/detector: processing", hardware_id="/uav/detector",
                                  values=[KeyValue(key="processed", value="8"), KeyValue(key="skipped", value="1"),
                                          KeyValue(key="processing_ms_p50", value="12.50")])
        bag.write("/diagnostics", DiagnosticArray(header=m.header(t), status=[status]), t)
    return path


def table_rows(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| run")
            and not line.startswith("| node")]


def test_summary_md_has_every_table_with_numbers(tmp_path):
    demo = load_demo()
    recording = write_recording(tmp_path / "recording.mcap")
    results = demo.report(recording, {}, tmp_path)
    text = (tmp_path / "report" / "summary.md").read_text()
    for heading in ("## /stand", "## /uav", "single target (OTB)", "multi target (HOTA / CLEAR MOT / IDF1)",
                    "detection (seed 003 Table 1)", "speed (per output topic)", "## Nodes"):
        assert heading in text, heading
    rows = table_rows(text)
    stand = next(r for r in rows if r.startswith("| stand |"))
    assert re.search(r"\| 8 \| 0\.\d{3} \|", stand), stand  # 8 scored frames, an AUC
    assert sum(r.startswith("| uav | 8 |") for r in rows) == 2  # the MOT and the detection rows, 8 frames
    assert any(r.startswith("| uav:tracks |") for r in rows)
    assert any(r.startswith("| /uav/detector | - | 8 | 1 |") for r in rows)
    assert results["stand"]["sot"]["scored_frames"] == 8


def test_markdown_tables_say_when_nothing_was_scored():
    assert "nothing scored" in format_markdown({})
    table = format_markdown({"run1": {"mot": {"mota": 0.5, "num_switches": 2}}})
    assert "| run1 |" in table and "0.500" in table and "| 2 |" in table
