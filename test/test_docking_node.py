"""docking_tracker_node: the YAML file, the processor (start, re-acquire, stop, bad input), the
offline runner, and the node in-process over a small bag (polygons carry the input stamps)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import Point32, PolygonStamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import Header

from aircraft_docking_tracker.docking import affine_group as ag
from aircraft_docking_tracker import offline
from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp, stamp_to_ns
from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir
from aircraft_docking_tracker.config import ConfigError
from aircraft_docking_tracker.docking.guidance import GUIDANCE_DTYPE, GuidanceConfig
from aircraft_docking_tracker.docking.guidance import TRACKING as GUIDANCE_TRACKING
from aircraft_docking_tracker.docking.tracker import LOST, STATE_DTYPE, TRACKING, WAITING, DockingConfig
from aircraft_docking_tracker.docking_tracker_node import (DockingNodeConfig, DockingProcessor,
                                                           DockingTrackerNode)
from aircraft_docking_tracker.evaluation.sot_metrics import polygon_iou
from aircraft_docking_tracker.images import numpy_to_compressed, numpy_to_image
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, cloud_to_table, table_to_cloud
from aircraft_docking_tracker.ros.processing import ProcessingStats, process_guarded
from aircraft_docking_tracker.scenarios.messages import polygon_to_quad

from ros_helpers import ros_context, spin_until, wait_for_subscribers
from test_docking_filter import moving_target_scene


def header(k: int) -> Header:
    return Header(stamp=ns_to_stamp(int(5e9 + k * 1e8)), frame_id="stand_cam")


def image_msg(frame, k):
    return numpy_to_image(np.dstack([frame] * 3), "bgr8", header(k))


def iou(msg, truth) -> float:
    quad = polygon_to_quad(msg)
    return 0.0 if not np.isfinite(quad).all() else float(polygon_iou(quad[None], ag.to_quad(truth)[None])[0])


def test_yaml_lists_every_parameter_with_its_default():
    params = load_yaml_parameters(package_config_dir() / "docking_tracker.yaml", "docking_tracker")
    expected = {f.name: getattr(DockingConfig(), f.name) for f in dataclasses.fields(DockingConfig)}
    expected.update({"node." + f.name: getattr(DockingNodeConfig(), f.name)
                     for f in dataclasses.fields(DockingNodeConfig)})
    expected.update({"guidance." + f.name: getattr(GuidanceConfig(), f.name) for f in dataclasses.fields(GuidanceConfig)})
    assert params == expected


def test_processor_waits_starts_from_detections_stops_and_rejects():
    scene = list(moving_target_scene(40))[:8]
    proc = DockingProcessor(DockingConfig(detection_class=4), DockingNodeConfig(annotate_image=True))
    stats = ProcessingStats()
    out = process_guarded(proc, "image", image_msg(scene[0][0], 0), stats)
    assert [t for t, _ in out] == ["docking/polygon", "docking/state", "docking/markers", "docking/image_markers",
                                   "docking/image"]
    assert len(out[0][1].polygon.points) == 0                                    # waiting: empty polygon
    assert cloud_to_table(out[1][1], STATE_DTYPE)["state"][0] == WAITING
    det = np.array([(*ag.to_box(scene[1][1]), 0.9, 4)], DETECTION_DTYPE)
    assert process_guarded(proc, "detections", table_to_cloud(det, header(1)), stats) == []
    for k in range(1, 8):
        out = process_guarded(proc, "image", image_msg(scene[k][0], k), stats)
        state = cloud_to_table(out[1][1], STATE_DTYPE)[0]
        assert state["state"] == TRACKING and iou(out[0][1], scene[k][1]) > 0.6
        assert out[0][1].header == header(k) and out[3][1].header == header(k)
    assert state["particles"] >= 20 and 0.5 < state["score"] <= 1.0
    assert np.isclose(state["cx"], ag.to_params(scene[7][1])[0], atol=8)
    process_guarded(proc, "docking/init", PolygonStamped(header=header(8)), stats)  # empty: stop
    out = process_guarded(proc, "image", image_msg(scene[7][0], 9), stats)
    assert cloud_to_table(out[1][1], STATE_DTYPE)["state"][0] == WAITING
    bad = Image(header=header(10), height=4, width=4, encoding="nonsense", step=4, data=bytes(16))
    assert process_guarded(proc, "image", bad, stats) == [] and stats.rejected_total == 1
    three = PolygonStamped(header=header(11))
    three.polygon.points = [Point32(x=1.0, y=2.0), Point32(x=3.0, y=4.0), Point32(x=5.0, y=1.0)]
    assert process_guarded(proc, "docking/init", three, stats) == [] and stats.rejected_total == 2


def test_init_topic_box_corners_and_compressed_input():
    scene = list(moving_target_scene(40))[:3]
    proc = DockingProcessor(DockingConfig(), DockingNodeConfig(compressed=True))
    assert proc.inputs["image"] == "sensor_msgs/msg/CompressedImage"
    x, y, w, h = ag.to_box(scene[0][1])
    init = PolygonStamped(header=header(0))
    init.polygon.points = [Point32(x=float(x), y=float(y)), Point32(x=float(x + w), y=float(y + h))]
    proc.process("docking/init", init)
    for k in range(3):
        out = proc.process("image", numpy_to_compressed(scene[k][0], "png", header(k)))
    assert cloud_to_table(out[1][1], STATE_DTYPE)["state"][0] == TRACKING
    assert iou(out[0][1], scene[2][1]) > 0.6


def test_lost_track_publishes_an_empty_polygon_and_the_lost_state():
    scene = list(moving_target_scene(20, visible=lambda i: i < 5))
    proc = DockingProcessor(DockingConfig(initial_box=list(ag.to_box(scene[0][1])), lost_after=3))
    states = []
    for k, (frame, _) in enumerate(scene):
        out = proc.process("image", image_msg(frame, k))
        states.append(cloud_to_table(out[1][1], STATE_DTYPE)["state"][0])
    assert states[:5] == [TRACKING] * 5 and states[-1] == LOST
    assert len(out[0][1].polygon.points) == 0


def test_offline_runner_uses_the_same_processor(tmp_path):
    scene = list(moving_target_scene(40))[:6]
    bag, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    with BagWriter(bag) as writer:
        for k, (frame, _) in enumerate(scene):
            writer.write("image", image_msg(frame, k), stamp_to_ns(header(k).stamp))
    box = [float(v) for v in ag.to_box(scene[0][1])]
    proc = offline.build_processor("docking_tracker", overrides={"initial_box": box})
    offline.run(bag, out, ["docking_tracker"], processors={"docking_tracker": proc}, progress=False)
    polygons = [m for _, m, _ in BagReader(out).ros_messages(["/docking/polygon"])]
    assert len(polygons) == 6
    assert [m.header.stamp for m in polygons] == [header(k).stamp for k in range(6)]
    assert min(iou(m, truth) for m, (_, truth) in zip(polygons, scene)) > 0.6


def test_node_in_process_over_a_bag(tmp_path):
    scene = list(moving_target_scene(40))[:8]
    bag = tmp_path / "images.mcap"
    with BagWriter(bag) as writer:
        for k, (frame, _) in enumerate(scene):
            writer.write("image", image_msg(frame, k), stamp_to_ns(header(k).stamp))
    box = [float(v) for v in ag.to_box(scene[0][1])]
    with ros_context() as (ctx, executor):
        node = DockingTrackerNode(context=ctx, parameter_overrides=[Parameter("initial_box", value=box)])
        probe = rclpy.create_node("probe", context=ctx)
        executor.add_node(node)
        executor.add_node(probe)
        polygons, states = [], []
        probe.create_subscription(PolygonStamped, "docking/polygon", polygons.append, 10)
        probe.create_subscription(PointCloud2, "docking/state", states.append, 10)
        pub = probe.create_publisher(Image, "image", 10)
        try:
            assert wait_for_subscribers(executor, pub)
            refused = node.set_parameters([Parameter("n_initial", value=0)])[0]
            assert refused.successful is False and "range" in refused.reason
            for k, (_, msg, _) in enumerate(BagReader(bag).ros_messages(["image"])):
                pub.publish(msg)
                assert spin_until(executor, lambda: len(polygons) == k + 1, timeout_s=20)
            assert spin_until(executor, lambda: len(states) == 8, timeout_s=5)
            assert [m.header.stamp for m in polygons] == [header(k).stamp for k in range(8)]
            assert all(m.header.frame_id == "stand_cam" for m in polygons)
            assert min(iou(m, truth) for m, (_, truth) in zip(polygons, scene)) > 0.6
            assert cloud_to_table(states[-1], STATE_DTYPE)["state"][0] == TRACKING
            assert node.stats.rejected_total == 0
        finally:
            node.destroy_node()
            probe.destroy_node()


def test_seed_preset_selects_the_seeds_choices():
    params = load_yaml_parameters(package_config_dir() / "docking_tracker_seed.yaml", "docking_tracker")
    config = DockingConfig(**params)
    assert (config.chart, config.ar_dims, config.estimate, config.update_rule) == ("unit", "all", "best", "background")
    assert config.skew_pull == config.aspect_pull == config.tune_min_gain == config.anchor_weight == 0.0
    assert config.extent_gain == config.motion_gain == 0.0


def test_status_reports_the_static_camera_extent_counts():
    """The diagnostics say how often the foreground's extent corrected X̂ and why it did not."""
    scene = list(moving_target_scene(15))
    proc = DockingProcessor(DockingConfig(initial_box=list(ag.to_box(scene[0][1]))))
    for k, (frame, _) in enumerate(scene):
        proc.process("image", image_msg(frame, k))
    status = proc.status()
    counts = {k: v for k, v in status.items() if k.startswith("extent ")}
    assert set(counts) == {"extent measured", "extent moving", "extent untrusted", "extent filling", "extent still", "extent none",
                           "extent implausible", "extent refused"}
    assert sum(counts.values()) == len(scene) - 1          # every frame after the start
    assert counts["extent measured"] >= 3                  # a static camera and a clear target (7-12 here)
    # started from an axis-aligned box: the start re-fit is tried once, after start_refit frames, and says how it went
    starts = {k: v for k, v in status.items() if k.startswith("start re-fit ")}
    assert set(starts) == {f"start re-fit {name}" for name in
                           ("refitted", "no silhouette", "hidden", "no axis", "outside", "moved", "untrusted",
                            "invalid", "disagree", "steep")}
    assert sum(starts.values()) == 1


def test_the_warm_up_track_is_thrown_away_and_its_failure_reported(monkeypatch):
    """The warm-up runs a throwaway tracker (the processor's own still waits, nothing started or counted) and a
    failure is kept for the node's log, the processor still built."""
    from aircraft_docking_tracker.docking.tracker import DockingTracker  # noqa: PLC0415

    proc = DockingProcessor(DockingConfig())
    assert proc.warm_up_error == ""
    assert proc.tracker.state == WAITING and proc.starts == 0 and proc.last.state == WAITING

    def broken(self, frame, where, detected=False):
        raise RuntimeError("kernel cache unreadable")

    monkeypatch.setattr(DockingTracker, "start", broken)
    assert DockingProcessor(DockingConfig()).warm_up_error == "RuntimeError: kernel cache unreadable"


def test_guidance_outputs_with_a_stand_file(tmp_path):
    """With a stand file the node also publishes docking/guidance (one row, the image's header), its markers in
    metres on the stand, and the panel on docking/image; a broken stand file stops the start with its reason."""
    from aircraft_docking_tracker.docking.stand import stand_file_text
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig

    scene = DockingScene(DockingSceneConfig(frames=200, width=320, height=240), seed=4)
    stand = tmp_path / "stand.yaml"
    stand.write_text(stand_file_text(scene.stand_calibration()))
    frames = [f for _, f in zip(range(4), scene.frames())]
    proc = DockingProcessor(DockingConfig(), DockingNodeConfig(annotate_image=True),
                            GuidanceConfig(stand_file=str(stand)))
    assert {"docking/guidance", "docking/guidance_markers"} <= set(proc.outputs)
    stats = ProcessingStats()
    start = PolygonStamped(header=header(0))                  # the true quadrilateral: the template is the aircraft's
    start.polygon.points = [Point32(x=float(x), y=float(y)) for x, y in frames[0].quad]
    process_guarded(proc, "docking/init", start, stats)
    for k, frame in enumerate(frames):
        out = dict(process_guarded(proc, "image", numpy_to_image(frame.image, "bgr8", header(k)), stats))
    row = cloud_to_table(out["docking/guidance"], GUIDANCE_DTYPE)
    assert len(row) == 1 and row["state"][0] == GUIDANCE_TRACKING and out["docking/guidance"].header == header(3)
    assert abs(row["distance_m"][0] - frames[-1].guidance[0]) < 0.1 * frames[-1].guidance[0]   # 240 m out: coarse
    markers = out["docking/guidance_markers"].markers
    assert {m.header.frame_id for m in markers} == {"stand"} and len(markers) == 5
    panel = np.frombuffer(bytes(out["docking/image"].data), np.uint8).reshape(240, 320, 3)[8:40, -100:]
    assert (panel < 30).mean() > 0.5                                          # the dark panel, top right
    assert proc.status()["guidance state"] == "tracking"
    along, across = map(float, proc.status()["survey at the stop mark, along / across the line (95 %) m"].split(" / "))
    assert 0 < across < along < 1.0                        # half-pixel clicks: tenths of a metre along the line
    (level, note), = proc.start_up_notes                   # logged once by the node at start-up
    assert f"+-{along:.2f} m along the lead-in line" in note
    proc.reset()
    assert proc.last_guidance.state == 0
    (tmp_path / "broken.yaml").write_text("camera: {image_size: [320, 240], points: []}\n")
    with pytest.raises(ConfigError, match="at least 4 apron marks"):
        DockingProcessor(DockingConfig(), DockingNodeConfig(), GuidanceConfig(stand_file=str(tmp_path / "broken.yaml")))


def test_guidance_measures_the_nose_wheel_near_the_stop(tmp_path):
    """Near the stop the node measures the nose wheel in each frame (counted in the status), and the distance to
    go comes out within a metre (a 60-frame approach: 10 m/s 15 m out, the smoothing lags a little)."""
    from aircraft_docking_tracker.docking.stand import stand_file_text
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig

    scene = DockingScene(DockingSceneConfig(frames=60, weather="clear", occluder="none"), seed=5)
    stand = tmp_path / "stand.yaml"
    stand.write_text(stand_file_text(scene.stand_calibration()))
    frames = [f for f in scene.frames() if f.index >= 44]
    proc = DockingProcessor(DockingConfig(), DockingNodeConfig(), GuidanceConfig(stand_file=str(stand)))
    stats = ProcessingStats()
    start = PolygonStamped(header=header(0))
    start.polygon.points = [Point32(x=float(x), y=float(y)) for x, y in frames[0].quad]
    process_guarded(proc, "docking/init", start, stats)
    errors = []
    for k, frame in enumerate(frames):
        out = dict(process_guarded(proc, "image", numpy_to_image(frame.image, "bgr8", header(k)), stats))
        errors.append(cloud_to_table(out["docking/guidance"], GUIDANCE_DTYPE)["distance_m"][0] - frame.guidance[0])
    assert proc.status()["guidance frames measured at the nose wheel"] >= len(frames) - 2
    assert proc.status()["guidance nose-wheel contacts refused (far from the size's range)"] == 0
    assert np.nanmax(np.abs(errors[2:])) < 1.0


def test_a_broken_stand_file_is_refused_at_start_and_the_node_tracks_without_guidance(tmp_path):
    """guidance.stand_file is start-up only (read-only): a file that does not load is refused as any bad value is
    (logged, listed, its default kept), the node runs without the guidance topics; a good one publishes them."""
    from aircraft_docking_tracker.docking.stand import stand_file_text
    from aircraft_docking_tracker.scenarios.docking import DockingScene

    (tmp_path / "broken.yaml").write_text("camera: {image_size: [320, 240], points: []}\n")
    good = tmp_path / "good.yaml"
    good.write_text(stand_file_text(DockingScene(seed=1).stand_calibration()))
    with ros_context() as (ctx, _):
        node = DockingTrackerNode(context=ctx, parameter_overrides=[
            Parameter("guidance.stand_file", value=str(tmp_path / "broken.yaml"))])
        try:
            assert "at least 4 apron marks" in node.config_errors["guidance.stand_file"]
            assert node.get_parameter("guidance.stand_file").value == ""
            assert "docking/guidance" not in node.processor.outputs
            assert any(kv.key == "parameter refused: guidance.stand_file" for kv in node.diagnostic_status().values)
        finally:
            node.destroy_node()
        node = DockingTrackerNode(context=ctx, parameter_overrides=[Parameter("guidance.stand_file", value=str(good))])
        try:
            assert not node.config_errors and "docking/guidance" in node.processor.outputs
            refused = node.set_parameters([Parameter("guidance.stand_file", value="")])[0]
            assert refused.successful is False                                 # start-up only
        finally:
            node.destroy_node()
