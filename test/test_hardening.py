"""Issue 16 (items 1, 2, 3, 5, 6): no bad value, oversized input or careless command crashes, hangs or
silently misconfigures a node. Each test is one case of the issue; each failed before the fix."""
from __future__ import annotations

import json
import struct
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import cv2
import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from aircraft_docking_tracker.ros import node_base
from aircraft_docking_tracker.io.bag import ns_to_stamp
from aircraft_docking_tracker.config import ConfigError, from_mapping, package_config_dir
from aircraft_docking_tracker.docking.tracker import DockingConfig
from aircraft_docking_tracker.docking_tracker_node import DockingProcessor, DockingTrackerNode
from aircraft_docking_tracker.images import ImageConversionError, compressed_dimensions, numpy_to_image, to_mono8
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, cloud_to_table, table_to_cloud
from aircraft_docking_tracker.ros.processing import MessageProcessor, ProcessingStats, process_guarded
from aircraft_docking_tracker.scenarios.faults import png_bomb
from aircraft_docking_tracker.io import motchallenge as mc
from multi_target_tracker.association_node import AssociationProcessor
from multi_target_tracker.cascade import Cascade, CascadeError
from multi_target_tracker.detector import MODELS_DIR, DetectorConfig
from multi_target_tracker.detector_node import DetectorNode, DetectorNodeConfig, DetectorProcessor

from ros_helpers import ros_context

REPO = Path(__file__).resolve().parent.parent
MODEL = MODELS_DIR / "docking_aircraft_fused.json"


def header(k: int = 0) -> Header:
    return Header(stamp=ns_to_stamp(int(1e9 + k * 1e8)), frame_id="cam")


def params_file(tmp_path, text: str, name: str = "p.yaml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def params_of(node, names):
    return {p.name: p.value for p in node.get_parameters(names)}


def levels_and_values(node):
    status = node.diagnostic_status()
    return status.level[0] if isinstance(status.level, bytes) else status.level, \
        {kv.key: kv.value for kv in status.values}, status.message


# ---------------------------------------------------------------- 1. one bad value in a params file
@pytest.mark.ros
def test_one_bad_value_in_a_params_file_keeps_the_rest_of_the_section(tmp_path):
    extra = params_file(tmp_path, '/**/detector:\n  ros__parameters:\n    orientation: "upright "\n', "extra.yaml")
    stand = str(package_config_dir() / "stand_camera.yaml")
    with ros_context() as (ctx, _):
        node = DetectorNode(context=ctx, cli_args=["--ros-args", "--params-file", stand, "--params-file", extra])
        try:
            cfg = node.config()
            # the stand camera's values are applied, the bad orientation alone is refused
            assert cfg.model == "docking_aircraft_fused.json" and cfg.class_id == 1 and cfg.min_neighbors == 2
            assert cfg.orientation == "model"
            assert node.processor.detector.config.model == "docking_aircraft_fused.json"
            # get_parameters reports what runs
            reported = params_of(node, ["model", "orientation", "class_id"])
            assert reported == {"model": "docking_aircraft_fused.json", "orientation": "model", "class_id": 1}
            level, values, message = levels_and_values(node)
            assert level == 1 and "parameter refused: orientation" in values and "refused" in message
            assert "not one of" in values["parameter refused: orientation"]
        finally:
            node.destroy_node()


@pytest.mark.ros
def test_a_typo_in_a_parameter_name_is_reported(tmp_path):
    path = params_file(tmp_path, "detector:\n  ros__parameters:\n    max_sise: 80.0\n    scale_factor: 2\n")
    with ros_context() as (ctx, _):
        node = DetectorNode(context=ctx, cli_args=["--ros-args", "--params-file", path])
        try:
            assert node.config().scale_factor == 2.0           # an integer for a float parameter is taken
            level, values, _ = levels_and_values(node)
            assert "parameter unknown: max_sise" in values
        finally:
            node.destroy_node()


# ---------------------------------------------------------------- 2. values that disable or kill a node
def bad_model(tmp_path, change) -> str:
    d = json.loads(MODEL.read_text())
    change(d)
    path = tmp_path / "bad_model.json"
    path.write_text(json.dumps(d))
    return str(path)


@pytest.mark.ros
def test_runtime_values_that_would_disable_the_detector_are_refused(tmp_path):
    huge = bad_model(tmp_path, lambda d: d["stages"][0]["thresholds"].__setitem__(0, 1e30))
    with ros_context() as (ctx, _):
        node = DetectorNode(context=ctx, parameter_overrides=[Parameter("model", value=str(MODEL))])
        try:
            before = node.processor.detector
            for name, value, why in [("model", str(tmp_path / "missing.json"), "not found"),
                                     ("model", huge, "stump threshold"),
                                     ("roi", [1, 2, 3], "roi"), ("roi", [0, 0, -5, 10], "roi"),
                                     ("backend", "opencv", "XML"),
                                     ("min_size", 200.0, None)]:
                if name == "min_size":
                    assert node.set_parameters([Parameter("max_size", value=100.0)])[0].successful
                    why = "must not exceed"
                result = node.set_parameters([Parameter(name, value=value)])[0]
                assert not result.successful and why in result.reason, (name, value, result.reason)
            assert node.processor.detector is not None and node.processor.model_error == ""
            assert node.get_parameter("model").value == str(MODEL) and node.config().model == str(MODEL)
            assert before.config.model == node.processor.detector.config.model
        finally:
            node.destroy_node()


@pytest.mark.ros
def test_a_bad_model_or_size_range_in_a_params_file_is_refused_at_start_up(tmp_path):
    huge = bad_model(tmp_path, lambda d: d["stages"][0]["thresholds"].__setitem__(0, 1e30))
    path = params_file(tmp_path, f"detector:\n  ros__parameters:\n    model: {huge}\n    min_size: 90.0\n"
                       "    max_size: 30.0\n    class_id: 4\n")
    with ros_context() as (ctx, _):
        node = DetectorNode(context=ctx, cli_args=["--ros-args", "--params-file", path])
        try:
            cfg = node.config()
            assert cfg.model == DetectorConfig().model and cfg.class_id == 4
            assert (cfg.min_size, cfg.max_size) == (0.0, 0.0)
            assert node.processor.detector is not None
            assert params_of(node, ["model", "min_size"]) == {"model": cfg.model, "min_size": 0.0}
            level, values, _ = levels_and_values(node)
            assert level == 1 and {"parameter refused: model", "parameter refused: min_size"} <= set(values)
        finally:
            node.destroy_node()


def test_bad_models_are_refused_with_a_reason(tmp_path):
    cases = [(lambda d: d["stages"][0]["thresholds"].__setitem__(0, 1e30), "threshold"),
             (lambda d: d["stages"][0].__setitem__("threshold", 1e30), "beyond"),
             (lambda d: d["stages"][0]["left"].__setitem__(0, float("nan")), "finite"),
             (lambda d: d.__setitem__("window", [4, 4]), "window"),
             (lambda d: d.__setitem__("stages", "x"), "stages"),
             (lambda d: d["stages"][0].__setitem__("features", [[1]]), "equally many")]
    for change, why in cases:
        with pytest.raises(CascadeError, match=why):
            Cascade.load(bad_model(tmp_path, change))
    with pytest.raises(ConfigError, match="max_model_stumps"):
        from_mapping(DetectorConfig, {"model": str(MODEL), "max_model_stumps": 100})
    # the limit is a parameter: the same model loads when allowed
    assert from_mapping(DetectorConfig, {"model": str(MODEL), "max_model_stumps": 1000}).max_model_stumps == 1000


@pytest.mark.ros
def test_a_nan_initial_box_in_a_params_file_does_not_crash_start_up(tmp_path):
    path = params_file(tmp_path, "docking_tracker:\n  ros__parameters:\n    initial_box: [.nan, 10.0, 20.0, 20.0]\n"
                       "    n_initial: 400\n    n_total: 300\n    lost_after: 7\n")
    with ros_context() as (ctx, _):
        node = DockingTrackerNode(context=ctx, cli_args=["--ros-args", "--params-file", path])
        try:
            cfg = node.config()
            assert cfg.initial_box == [] and cfg.lost_after == 7
            assert cfg.n_initial <= cfg.n_total
            assert node._parameters["initial_box"].type_ == Parameter.Type.NOT_SET   # the empty default
            _, values, _ = levels_and_values(node)
            assert "parameter refused: initial_box" in values
            assert any(k.startswith("parameter refused: n_") for k in values)
            for params in ([Parameter("initial_box", value=[float("nan"), 1.0, 2.0, 2.0])],
                           [Parameter("n_initial", value=400)]):
                assert not node.set_parameters(params)[0].successful
        finally:
            node.destroy_node()


def test_cross_field_rules():
    with pytest.raises(ConfigError, match="n_initial") as err:
        from_mapping(DockingConfig, {"n_initial": 500, "n_total": 300})
    assert set(err.value.fields) == {"n_initial", "n_total"}
    with pytest.raises(ConfigError, match="initial_box"):
        from_mapping(DockingConfig, {"initial_box": [float("inf"), 0, 10, 10]})
    with pytest.raises(ConfigError, match="min_size"):
        from_mapping(DetectorConfig, {"min_size": 100.0, "max_size": 50.0})
    with pytest.raises(ConfigError, match="must be"):
        from_mapping(DetectorConfig, {"scale_factor": "fast"})


class Brittle(MessageProcessor):
    inputs = {"image": "sensor_msgs/msg/Image"}

    def process(self, topic, msg):
        return []

    def reset(self):
        raise ValueError("cannot restart at a NaN box")


def test_a_failing_reset_on_a_backwards_stamp_is_counted_not_raised():
    stats, jumps = ProcessingStats(), []
    msg = numpy_to_image(np.zeros((4, 4), np.uint8), "mono8", header(5))
    assert process_guarded(Brittle(), "image", msg, stats) == []
    msg.header = header(1)
    assert process_guarded(Brittle(), "image", msg, stats, on_time_jump=jumps.append) == []
    assert stats.time_jumps == 1 and len(jumps) == 1 and "went back" in jumps[0]
    assert any("internal error on reset" in r for r in stats.rejected)


def test_the_image_thread_survives_a_raising_handler():
    stats = ProcessingStats()
    seen = []

    def handler(msg):
        seen.append(msg)
        if msg == 1:
            raise RuntimeError("boom")

    slot = node_base._LatestSlot(handler, stats, "image")
    try:
        slot.offer(1)
        deadline = time.monotonic() + 5
        while not seen and time.monotonic() < deadline:
            time.sleep(0.01)
        slot.offer(2)
        while len(seen) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert seen == [1, 2] and stats.rejected_total == 1
    finally:
        slot.stop()


# ---------------------------------------------------------------- 3. bounds on work
def test_a_png_decompression_bomb_is_refused_from_its_header():
    data = png_bomb(6000, 6000)                       # 36 MP of zeros in a file of some ten kB
    assert len(data) < 200_000 and compressed_dimensions(data) == ("png", 6000, 6000)
    msg = CompressedImage(header=header(), format="png", data=data)
    tracemalloc.start()
    try:
        with pytest.raises(ImageConversionError, match="exceeds max_image_pixels"):
            to_mono8(msg)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * len(data) + 1_000_000          # never decoded
    # the same header check for a JPEG whose frame header claims 60000 x 60000
    ok, jpg = cv2.imencode(".jpg", np.zeros((8, 8), np.uint8))
    jpg = bytearray(jpg.tobytes())
    sof = next(i for i in range(2, len(jpg) - 1) if jpg[i] == 0xFF and jpg[i + 1] in (0xC0, 0xC2))
    jpg[sof + 5:sof + 9] = struct.pack(">HH", 60000, 60000)
    with pytest.raises(ImageConversionError, match="60000x60000"):
        to_mono8(CompressedImage(format="jpeg", data=bytes(jpg)))
    with pytest.raises(ImageConversionError, match="could not be decoded"):
        to_mono8(CompressedImage(format="tiff", data=b"II*\0" + bytes(100)))
    # a 1 kB PNG whose chunk length claims 512 MB: OpenCV's reader would allocate it before checking
    ok, png = cv2.imencode(".png", np.zeros((32, 48), np.uint8))
    png = bytearray(png.tobytes())
    png[33:37] = struct.pack(">I", 2**29)
    with pytest.raises(ImageConversionError, match="chunk"):
        to_mono8(CompressedImage(format="png", data=bytes(png)))


def test_oversized_frames_are_refused_by_each_image_processor():
    big = numpy_to_image(np.zeros((3200, 3200), np.uint8), "mono8", header())  # 10.24 MP > 10 MP
    for processor, topic in ((DetectorProcessor(DetectorConfig(model=str(MODEL))), "image"),
                             (DockingProcessor(), "image")):
        stats = ProcessingStats()
        assert process_guarded(processor, topic, big, stats) == []
        assert any("exceeds max_image_pixels" in r for r in stats.rejected), stats.rejected
    small = DetectorProcessor(DetectorConfig(model=str(MODEL)), DetectorNodeConfig(max_image_pixels=100))
    stats = ProcessingStats()
    process_guarded(small, "image", numpy_to_image(np.zeros((20, 20), np.uint8), "mono8", header()), stats)
    assert stats.rejected_total == 1


def many_detections(n: int, k: int = 0):
    table = np.zeros(n, DETECTION_DTYPE)
    rng = np.random.default_rng(1)
    table["x"], table["y"] = rng.uniform(0, 1000, n), rng.uniform(0, 1000, n)
    table["w"] = table["h"] = 20
    table["score"] = np.arange(n)
    return table_to_cloud(table, header(k))


def test_detection_messages_are_capped_best_rows_kept():
    processor = AssociationProcessor()
    stats = ProcessingStats()
    processor.on_rejected = stats.reject
    tracemalloc.start()
    try:
        process_guarded(processor, "detections", many_detections(10000), stats)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert stats.processed == 1 and any("more than the limit of" in r for r in stats.rejected)
    assert peak < 200e6, peak                       # was 1.7 GB
    docking = DockingProcessor()
    docking.on_rejected = stats.reject
    process_guarded(docking, "detections", many_detections(5000), stats)
    assert len(docking._detections[1]) == 1000 and docking._detections[1]["score"].min() == 4000


def test_mot_frames_far_apart_are_refused_or_cheap(tmp_path):
    det = tmp_path / "det.txt"
    det.write_text("1,-1,10,10,20,20,0.9\n2000000000,-1,10,10,20,20,0.9\n")
    with pytest.raises(mc.MotFormatError, match="2000000000"):
        mc.read_detections(det)
    result = subprocess.run([sys.executable, "-m", "multi_target_tracker.mot_track", str(det)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "frame 2000000000" in result.stderr and "Traceback" not in result.stderr
    # iterating frames allocates nothing per frame up to ``last``
    rows = mc.read_detections(det, max_frame=2**31 - 1)
    tracemalloc.start()
    try:
        frames = mc.frames(rows)
        first = [next(frames) for _ in range(3)]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [f for f, _ in first] == [1, 2, 3] and len(first[0][1]) == 1 and peak < 1e6


# ---------------------------------------------------------------- 5. errors as messages
@pytest.mark.parametrize("content, why", [("1,-1,1,2\n", "at least 6"), ("1,-1,a,b,c,d\n", "could not convert"),
                                          ("1.5,-1,1,2,3,4\n", "whole number")])
def test_mot_track_on_a_malformed_det_file_says_why(tmp_path, content, why):
    from multi_target_tracker import mot_track  # noqa: PLC0415

    det = tmp_path / "det.txt"
    det.write_text(content)
    assert mot_track.main([str(det)]) == 2
    assert mot_track.main([str(det.parent / "det_missing.txt")]) == 2
    missing_params = tmp_path / "none.yaml"
    det.write_text("1,-1,1,2,3,4\n")
    assert mot_track.main([str(det), "--params", str(missing_params)]) == 2


@pytest.mark.parametrize("node", ["multi_target_tracker.detector_node", "multi_target_tracker.association_node",
                                  "aircraft_docking_tracker.docking_tracker_node"])
def test_node_help_prints_usage_and_exits_0(node):
    result = subprocess.run([sys.executable, "-m", node, "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.startswith("usage:"), result.stderr
    assert "max_image_pixels" in result.stdout and "--params-file" in result.stdout


@pytest.mark.parametrize("content, why", [(None, "No such file"), ("a: [", "not valid YAML"),
                                          ("- 1\n- 2\n", "not a ROS 2 parameter file")])
def test_a_broken_or_missing_params_file_is_one_line_not_a_traceback(tmp_path, content, why):
    path = tmp_path / "params.yaml"
    if content is not None:
        path.write_text(content)
    result = subprocess.run([sys.executable, "-m", "multi_target_tracker.detector_node", "--ros-args",
                             "--params-file", str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and why in result.stderr and "Traceback" not in result.stderr, result.stderr


# ---------------------------------------------------------------- 6. diagnostics that tell the truth
class Picky(MessageProcessor):
    inputs = {"image": "sensor_msgs/msg/Image"}

    def process(self, topic, msg):
        raise ValueError(f"reason {msg.header.frame_id}")


class Logged:
    def __init__(self):
        self.lines = []

    def warning(self, text, **_):
        self.lines.append(text)

    error = info = warning


@pytest.fixture
def logged_node(monkeypatch):
    """A bare PerceptionNode whose log lines are collected in ``node.log.lines``."""
    with ros_context() as (ctx, _):
        node = node_base.PerceptionNode("logged", context=ctx)
        node.log = Logged()
        monkeypatch.setattr(node, "get_logger", lambda: node.log)
        try:
            yield node
        finally:
            node.destroy_node()


@pytest.mark.ros
def test_every_reason_shown_logged_and_warn_clears(logged_node, monkeypatch):
    node, log = logged_node, logged_node.log
    node.processor = Picky()
    for k in range(6):
        for _ in range(3 if k == 0 else 1):
            msg = Image(header=Header(frame_id=f"kind-{'abcdef'[k]}"))
            process_guarded(node.processor, "image", msg, node.stats, on_error=node.reject_logged)
    level, values, message = levels_and_values(node)
    shown = [k for k in values if k.startswith("rejected: ")]
    assert len(shown) == 6 and level == 1                 # every reason, not the top 3
    assert len(log.lines) == 6                            # one line per reason (throttled per reason)
    assert all(any(f"kind-{c}" in line for line in log.lines) for c in "abcdef")
    monkeypatch.setattr(node_base, "HOLD_S", 0.05)
    time.sleep(0.1)
    level, values, message = levels_and_values(node)
    assert level == 0 and values["rejected"] == "8"       # back to OK; the counts remain


@pytest.mark.ros
def test_warn_when_skipping_most_frames_and_error_without_a_model(tmp_path):
    with ros_context() as (ctx, _):
        node = DetectorNode(context=ctx, parameter_overrides=[Parameter("model", value=str(MODEL))])
        try:
            for _ in range(9):
                node.stats.skip()
            node.stats.receive()
            level, _, message = levels_and_values(node)
            assert level == 1 and "skipping 90%" in message
            node.processor.configure(DetectorConfig(model=str(tmp_path / "gone.json")))
            level, _, message = levels_and_values(node)
            assert level == 2 and "detector disabled" in message
        finally:
            node.destroy_node()


@pytest.mark.ros
def test_tracker_resets_on_stamp_jumps_are_logged(logged_node):
    node = logged_node
    node.attach_processor(AssociationProcessor())
    handler = node._make_handler("detections")
    handler(many_detections(3, 5))
    handler(many_detections(3, 1))
    assert node.stats.time_jumps == 1 and any("went back" in line for line in node.log.lines)


@pytest.mark.parametrize("tool, args", [("multi_target_tracker.detect", ["in"]),
                                        ("aircraft_docking_tracker.sot_track", ["in"]),
                                        ("multi_target_tracker.mot_track", ["det.txt"])])
def test_tools_refuse_a_missing_params_file_instead_of_using_defaults(tmp_path, capsys, tool, args):
    import importlib  # noqa: PLC0415

    (tmp_path / "det.txt").write_text("1,-1,1,2,3,4\n")
    (tmp_path / "in").mkdir()
    module = importlib.import_module(tool)
    flag = "--params" if tool.endswith("mot_track") else "--params-file"
    code = module.main([str(tmp_path / a) for a in args] + [flag, str(tmp_path / "typo.yaml")])
    assert code and "typo.yaml not found" in capsys.readouterr().err
