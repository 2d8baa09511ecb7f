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


def test_the_demo_stand_is_guided_to_its_mark_as_the_nodes_run_it(tmp_path):
    """`make demo`'s stand camera through the nodes' own processors (run_offline's path: the detector and the docking
    tracker on config/stand_camera.yaml, the operator's box, config/stands/demo_stand.yaml): within the last 15 m
    the figures meet issue 15's targets with margin (measured: lateral p95 0.02 m, distance p95 0.32 m) and STOP
    comes at the mark. Session 32 tried a rule that moved the bench's figures by a hundredth and ran these 36 m off."""
    import yaml

    from aircraft_docking_tracker import offline
    from aircraft_docking_tracker.config import package_config_dir
    from aircraft_docking_tracker.docking.guidance import GUIDANCE_DTYPE
    from aircraft_docking_tracker.evaluation.guidance_metrics import guidance_errors
    from aircraft_docking_tracker.io.bag import BagReader
    from aircraft_docking_tracker.object_table import cloud_to_table
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
    from aircraft_docking_tracker.scenarios.make_scenario import write_docking_bag

    demo = load_demo()
    _, seed, options, *_ = demo.CAMERAS["stand"]
    bag = tmp_path / "stand.mcap"
    write_docking_bag(DockingScene(DockingSceneConfig(**options), seed=seed), bag, overwrite=True)
    setup = yaml.safe_load((package_config_dir() / "stand_camera.yaml").read_text())
    setup["/**/docking_tracker"]["ros__parameters"].update(
        {"initial_box": [float(v) for v in demo.first_box(bag)], "guidance.stand_file": "demo_stand.yaml"})
    params = tmp_path / "stand_camera.yaml"
    params.write_text(yaml.safe_dump(setup))
    offline.run(bag, tmp_path / "out.mcap", ["detector", "docking_tracker"], params_file=params, progress=False)
    rows = {"docking/guidance": {}, "ground_truth/guidance": {}}
    for path, topic, name in ((tmp_path / "out.mcap", "docking/guidance", "/docking/guidance"),
                              (bag, "ground_truth/guidance", "ground_truth/guidance")):    # the scenario's: relative
        for _, msg, _ in BagReader(path).ros_messages([name]):
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            rows[topic][stamp] = cloud_to_table(msg, GUIDANCE_DTYPE)[0]
    stamps = sorted(rows["ground_truth/guidance"])
    assert len(stamps) == options["frames"] and set(stamps) == set(rows["docking/guidance"])
    errors = guidance_errors(np.array([rows["docking/guidance"][s] for s in stamps]),
                             np.array([rows["ground_truth/guidance"][s] for s in stamps]))
    assert errors["lateral_near_p95"] < 0.15 and errors["distance_near_p95"] < 0.8
    assert errors["stop_within"] and not errors["stop_early"]
