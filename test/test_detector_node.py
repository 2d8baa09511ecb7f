"""detector_node: the YAML file, the processor (stride, bad input, bad model), in-process over a bag."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp
from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir
from aircraft_docking_tracker.geometry import box_iou
from aircraft_docking_tracker.images import numpy_to_compressed, numpy_to_image
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, cloud_to_table
from aircraft_docking_tracker.ros.processing import ProcessingStats, process_guarded
from multi_target_tracker import detect
from multi_target_tracker.detector import DetectorConfig
from multi_target_tracker.detector_node import DetectorNode, DetectorNodeConfig, DetectorProcessor

from ros_helpers import ros_context, spin_until, wait_for_subscribers
from test_detector_cascade import TINY_DETECTOR, _scene, train_tiny_model


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("node_model") / "tiny.json"
    train_tiny_model(path)
    return str(path)


@pytest.fixture(scope="module")
def scenes():
    rng = np.random.default_rng(99)
    return [_scene(rng, 3) for _ in range(3)]


def header(k: int) -> Header:
    return Header(stamp=ns_to_stamp(int(2e9 + k * 1e8)), frame_id="uav_cam")


def hits(table, truth) -> int:
    boxes = np.column_stack([table["x"], table["y"], table["w"], table["h"]])
    return int((box_iou(boxes[:, None], truth[None]).max(axis=0) >= 0.5).sum()) if len(boxes) else 0


def test_yaml_lists_every_parameter_with_its_default():
    params = load_yaml_parameters(package_config_dir() / "detector.yaml", "detector")
    expected = {f.name: getattr(DetectorConfig(), f.name) for f in dataclasses.fields(DetectorConfig)}
    expected.update({"node." + f.name: getattr(DetectorNodeConfig(), f.name)
                     for f in dataclasses.fields(DetectorNodeConfig)})
    # the settings of the file that are not the dataclass defaults: the drone-view model's box regressor (a
    # default would break the opencv backend and every other model); test_box_regression checks that it loads
    expected["box_regressor"] = "drone_vehicles_box_regressor.json"
    # ... and its scan: the colour blobs' views, framed as the drone-view model's boxes, looked for at a quarter size
    expected.update({"blob_views": True, "blob_context": 1.0, "blob_scale": 0.25})
    # ... and its grouping, chosen over the prefix folds of three training seeds (bench/detector.py node_grouping)
    expected.update({"min_neighbors": 5, "window_margin": -1.0})
    assert params == expected


def test_processor_detects_strides_and_rejects(model, scenes):
    proc = DetectorProcessor(DetectorConfig(model=model, class_id=7, **TINY_DETECTOR),
                             DetectorNodeConfig(frame_stride=2, annotate_image=True))
    stats = ProcessingStats()
    outputs = []
    for k, (image, _) in enumerate(scenes):
        bgr = np.dstack([image] * 3)
        outputs.append(process_guarded(proc, "image", numpy_to_image(bgr, "bgr8", header(k)), stats))
    assert [len(o) for o in outputs] == [4, 0, 4]           # every 2nd frame passed over
    topics = [t for t, _ in outputs[0]]
    assert topics == ["detections", "detections/markers", "detections/image_markers", "detections/image"]
    table = cloud_to_table(outputs[2][0][1], DETECTION_DTYPE)
    assert hits(table, scenes[2][1]) >= 2 and (table["class_id"] == 7).all()
    assert outputs[2][0][1].header.frame_id == "uav_cam" and outputs[2][0][1].header.stamp == header(2).stamp
    bad = Image(header=header(5), height=4, width=4, encoding="nonsense", step=4, data=bytes(16))
    assert process_guarded(proc, "image", bad, stats) == [] and stats.rejected_total == 0  # passed over
    assert process_guarded(proc, "image", bad, stats) == [] and stats.rejected_total == 1
    broken = DetectorProcessor(DetectorConfig(model="/nonexistent/model.json"))
    assert process_guarded(broken, "image", numpy_to_image(scenes[0][0], "mono8", header(6)), stats) == []
    assert stats.rejected_total == 2 and "no detector model" in next(reversed(stats.rejected))


def test_colour_verifier_set_up_publishes_only_declared_topics():
    """The UAV set-up's verifier reads colour; without annotate_image no annotated image is produced (the node
    logged every such frame as an undeclared topic and drew it for nothing)."""
    from aircraft_docking_tracker.offline import build_processor  # noqa: PLC0415

    proc = build_processor("detector", package_config_dir() / "uav_camera.yaml")
    assert proc.detector.needs_colour and not proc.node.annotate_image
    image = np.random.default_rng(3).integers(0, 255, (120, 160, 3), np.uint8)
    out = process_guarded(proc, "image", numpy_to_image(image, "bgr8", header(0)), ProcessingStats())
    assert [t for t, _ in out] == ["detections", "detections/markers", "detections/image_markers"]
    assert set(proc.outputs) == {t for t, _ in out}


def test_uav_set_up_publishes_low_confidence_rows_flagged_and_leaves_them_out_of_the_markers():
    """Detector processor -> cloud -> association processor, the UAV files: the flagged rows travel in the
    low_confidence field, the markers draw only the detections proper, and the association reads the flag."""
    from aircraft_docking_tracker.object_table import FLAGGED_DETECTION_DTYPE, LOW_CONFIDENCE  # noqa: PLC0415
    from aircraft_docking_tracker.offline import build_processor  # noqa: PLC0415
    from aircraft_docking_tracker.scenarios.uav import (UAV_EVAL_SEEDS, UAV_SETUP_GROUND_RESOLUTION,  # noqa: PLC0415
                                                        UavScene, UavSceneConfig)

    setup = package_config_dir() / "uav_camera.yaml"
    assert build_processor("detector", setup).detector.config.low_confidence_band > 0
    # a wider band than the set-up's, so that these few frames surely hold flagged rows: with the patch network the
    # boxes of a vehicle's weaker groups fall onto its detection's, and containment drops them
    proc = build_processor("detector", setup, {"low_confidence_band": 6.0})
    tracker = build_processor("association", setup)
    assert tracker.tracker.config.low_confidence
    config = UavSceneConfig(frames=80, fps=10.0, difficulty=1, ground_resolution=UAV_SETUP_GROUND_RESOLUTION)
    flagged = shown = 0
    for k, frame in enumerate(UavScene(config, seed=UAV_EVAL_SEEDS[900]).frames()):
        if k % 8 != 4:
            continue
        out = dict(process_guarded(proc, "image", numpy_to_image(frame.image, "bgr8", header(k)), ProcessingStats()))
        assert LOW_CONFIDENCE in [f.name for f in out["detections"].fields]
        table = cloud_to_table(out["detections"], FLAGGED_DETECTION_DTYPE)
        low = table[LOW_CONFIDENCE] == 1
        assert len(out["detections/markers"].markers) - 1 == int((~low).sum()) == proc.last_count   # - delete-all
        flagged += int(low.sum())
        shown += int((~low).sum())
        assert "tracks" in dict(tracker.process("detections", out["detections"]))
    assert flagged > 0 and shown > 0


def test_compressed_input(model, scenes):
    proc = DetectorProcessor(DetectorConfig(model=model, **TINY_DETECTOR), DetectorNodeConfig(compressed=True))
    assert proc.inputs == {"image": "sensor_msgs/msg/CompressedImage"}
    out = proc.process("image", numpy_to_compressed(scenes[0][0], "png", header(0)))
    assert hits(cloud_to_table(out[0][1], DETECTION_DTYPE), scenes[0][1]) >= 2


def test_node_in_process_over_a_bag(model, scenes, tmp_path):
    bag = tmp_path / "images.mcap"
    with BagWriter(bag) as writer:
        for k, (image, _) in enumerate(scenes):
            writer.write("image", numpy_to_image(image, "mono8", header(k)), int(2e9 + k * 1e8))
    with ros_context() as (ctx, executor):
        overrides = [Parameter("model", value=model)] + [Parameter(k, value=v) for k, v in TINY_DETECTOR.items()]
        node = DetectorNode(context=ctx, parameter_overrides=overrides)
        probe = rclpy.create_node("probe", context=ctx)
        executor.add_node(node)
        executor.add_node(probe)
        got, markers = [], []
        probe.create_subscription(PointCloud2, "detections", got.append, 10)
        probe.create_subscription(MarkerArray, "detections/markers", markers.append, 10)
        pub = probe.create_publisher(Image, "image", 10)
        try:
            assert wait_for_subscribers(executor, pub)
            assert node.set_parameters([Parameter("scale_factor", value=0.5)])[0].successful is False
            for k, (_, msg, _) in enumerate(BagReader(bag).ros_messages(["image"])):
                pub.publish(msg)
                assert spin_until(executor, lambda: len(got) == k + 1, timeout_s=20)
            assert spin_until(executor, lambda: len(markers) == 3, timeout_s=5)
            for msg, (_, truth) in zip(got, scenes):
                assert hits(cloud_to_table(msg, DETECTION_DTYPE), truth) >= 2
            assert [m.header.stamp for m in got] == [header(k).stamp for k in range(3)]
        finally:
            node.destroy_node()
            probe.destroy_node()


def test_detect_tool_over_folder_and_bag(model, scenes, tmp_path, capsys):
    import cv2

    folder = tmp_path / "frames"
    folder.mkdir()
    for k, (image, _) in enumerate(scenes):
        cv2.imwrite(str(folder / f"f{k}.png"), image)
    # config/detector.yaml's box regressor belongs to the drone-view model: refused with another one
    assert detect.main([str(folder), "-o", str(tmp_path / "refused.txt"), "--model", model, "--no-progress"]) == 2
    refused = capsys.readouterr().err
    assert "was trained for drone_vehicles_fused.json" in refused
    assert "min_neighbors" in refused and "blob views" in refused    # the set-up's other model-bound choices
    args = ["--model", model, "--box-regressor", "", "--no-progress"] + [x for k, v in TINY_DETECTOR.items()
                                                 for x in ("--" + k.replace("_", "-"), str(v))]
    assert detect.main([str(folder), "-o", str(tmp_path / "boxes.txt"), "--bag", str(tmp_path / "out.mcap")] + args) == 0
    lines = (tmp_path / "boxes.txt").read_text().splitlines()
    assert {line.split()[0] for line in lines} == {"f0.png", "f1.png", "f2.png"}
    reader = BagReader(tmp_path / "out.mcap")
    assert set(reader.topics) == {"image", "detections"}
    tables = [cloud_to_table(m, DETECTION_DTYPE) for _, m, _ in reader.ros_messages(["detections"])]
    assert sum(len(t) for t in tables) == len(lines)
    assert hits(tables[1], scenes[1][1]) >= 2
    assert detect.main([str(tmp_path / "missing_dir_or_bag")] + args) == 2


def test_a_detector_with_a_colour_verifier_gets_colour_from_any_encoding(model, scenes, tmp_path):
    """The node hands BGR to a detector whose verifier needs it (mono8 input converted); a verifier that
    accepts every group keeps the cascade's groups, scored by its probability."""
    from multi_target_tracker.verifier import FEATURES, Verifier  # noqa: PLC0415

    path = tmp_path / "accept_all.json"
    n = len(FEATURES)
    Verifier(np.zeros(n), np.ones(n), np.zeros(n), 5.0).save(path)
    plain = DetectorProcessor(DetectorConfig(model=model, **TINY_DETECTOR))
    verified = DetectorProcessor(DetectorConfig(model=model, verifier=str(path), **TINY_DETECTOR))
    stats = ProcessingStats()
    image = scenes[0][0]
    tables = []
    for proc, encoding, pixels in ((plain, "mono8", image), (verified, "mono8", image),
                                   (verified, "bgr8", np.dstack([image] * 3))):
        out = process_guarded(proc, "image", numpy_to_image(pixels, encoding, header(0)), stats)
        tables.append(cloud_to_table(out[0][1], DETECTION_DTYPE))
    assert stats.rejected_total == 0 and len(tables[0]) >= 2
    key = lambda t: np.sort(np.round(np.column_stack([t["x"], t["y"]]), 3), axis=0)  # noqa: E731
    for table in tables[1:]:
        assert np.allclose(key(table), key(tables[0]))
        assert np.allclose(table["score"], 1 / (1 + np.exp(-5.0)))


def test_a_failing_warm_up_frame_is_reported_not_swallowed(model, monkeypatch):
    """The warm-up frame's failure is kept (the node logs it) and the processor is still built."""
    from multi_target_tracker.detector import Detector  # noqa: PLC0415

    def broken(self, image, *args, **kwargs):
        raise RuntimeError("kernel cache unreadable")

    monkeypatch.setattr(Detector, "detect", broken)
    proc = DetectorProcessor(DetectorConfig(model=model, **TINY_DETECTOR))
    assert proc.warm_up_error == "RuntimeError: kernel cache unreadable"
    monkeypatch.undo()
    proc.warm_up()
    assert proc.warm_up_error == ""
