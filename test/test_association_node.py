"""association_node: in-process over detection messages, the processor's bad-input handling, the YAML file."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp, stamp_to_ns
from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir
from aircraft_docking_tracker.images import image_to_numpy, numpy_to_image
from aircraft_docking_tracker.object_table import (DETECTION_DTYPE, FLAGGED_DETECTION_DTYPE, LOW_CONFIDENCE, TRACK_DTYPE,
                                                   cloud_to_table, confident_rows, table_to_cloud)
from aircraft_docking_tracker.ros.processing import ProcessingStats, process_guarded
from multi_target_tracker.association import AssociationConfig
from multi_target_tracker.association_node import (AssociationNode, AssociationNodeConfig, AssociationOutputConfig,
                                                   AssociationProcessor)
from multi_target_tracker.kalman import KalmanConfig

from ros_helpers import ros_context, spin_until, wait_for_subscribers

FAST = AssociationConfig(confirm_length=2, gate="mahalanobis")


def header(k: int, fps: float = 10.0) -> Header:
    return Header(stamp=ns_to_stamp(int(1e9 + k * 1e9 / fps)), frame_id="uav_cam")


def detections_msg(k: int, rows=None) -> PointCloud2:
    """Two targets moving right at 2 px/frame (20 px/s), optional extra rows."""
    table = np.zeros(2, DETECTION_DTYPE)
    table["x"] = [10 + 2 * k, 10 + 2 * k]
    table["y"] = [20, 120]
    table["w"], table["h"], table["score"] = 10, 8, 0.9
    if rows is not None:
        table = np.concatenate([table, rows])
    return table_to_cloud(table, header(k))


def test_yaml_lists_every_parameter_with_its_default():
    params = load_yaml_parameters(package_config_dir() / "association.yaml", "association")
    expected = {}
    for prefix, cls in (("", AssociationConfig), ("kalman.", KalmanConfig), ("output.", AssociationOutputConfig),
                        ("node.", AssociationNodeConfig)):
        expected.update({prefix + f.name: getattr(cls(), f.name) for f in dataclasses.fields(cls)})
    assert params == pytest.approx(expected)


def test_offline_runner_over_a_bag_matches_the_processor(tmp_path):
    from aircraft_docking_tracker.offline import build_processor, run  # noqa: PLC0415

    assert isinstance(build_processor("association"), AssociationProcessor)
    src, dst = tmp_path / "in.mcap", tmp_path / "out.mcap"
    with BagWriter(src) as writer:
        for k in range(8):
            writer.write("/detections", detections_msg(k), int(1e9 + k * 1e8))
    run(src, dst, ["association"], progress=False)
    reader = BagReader(dst)
    assert reader.topics["/tracks"].count == 8 and "/tracks/markers" in reader.topics
    offline = [cloud_to_table(m, TRACK_DTYPE) for _, m, _ in reader.ros_messages(["/tracks"])]
    proc = AssociationProcessor()                                    # the package defaults, as run_offline
    direct = [cloud_to_table(dict(proc.process("detections", detections_msg(k)))["tracks"], TRACK_DTYPE)
              for k in range(8)]
    assert all((a == b).all() for a, b in zip(offline, direct))
    assert sorted(offline[-1]["id"].tolist()) == [1, 2]


def test_processor_tracks_rejects_and_resets():
    invalid = []
    proc = AssociationProcessor(FAST)
    proc.on_rejected = invalid.append
    stats = ProcessingStats()
    for k in range(4):
        out = dict(process_guarded(proc, "detections", detections_msg(k), stats))
    tracks = cloud_to_table(out["tracks"], TRACK_DTYPE)
    assert out["tracks"].header.frame_id == "uav_cam" and out["tracks"].header.stamp == header(3).stamp
    assert sorted(tracks["id"].tolist()) == [1, 2] and (tracks["state"] == 1).all()
    np.testing.assert_allclose(tracks["vx"], 20.0, atol=3.0)          # px/s from the 10 Hz stamps
    assert isinstance(out["tracks/markers"], MarkerArray) and len(out["tracks/markers"].markers) > 2

    bad = np.zeros(2, DETECTION_DTYPE)
    bad["x"], bad["w"], bad["h"] = [np.nan, 5], [4, -3], [4, 4]
    out = dict(process_guarded(proc, "detections", detections_msg(4, bad), stats))
    assert proc.invalid_detections == 2 and len(invalid) == 1
    assert len(cloud_to_table(out["tracks"], TRACK_DTYPE)) == 2

    broken = detections_msg(5)
    broken.data = broken.data[:5]                                      # truncated cloud: rejected
    assert process_guarded(proc, "detections", broken, stats) == []
    assert stats.rejected_total == 1

    process_guarded(proc, "detections", detections_msg(0), stats)       # looped bag: time jump
    assert stats.time_jumps == 1 and len(proc.tracker.ids) == 2 and proc.tracker.ids.min() > 2


def test_annotated_image_pairs_image_and_tracks_by_stamp():
    proc = AssociationProcessor(FAST, output=AssociationOutputConfig(annotate_image=True, include_tentative=True))
    assert "image" in proc.inputs and "tracks/image" in proc.outputs
    img = numpy_to_image(np.zeros((200, 100, 3), np.uint8), "bgr8", header(0))
    assert proc.process("image", img) == []
    out = dict(proc.process("detections", detections_msg(0)))
    drawn = image_to_numpy(out["tracks/image"])
    assert out["tracks/image"].header.stamp == header(0).stamp
    assert drawn[20:29, 10].any() and not drawn[150:, 50:].any()       # box edges drawn, elsewhere black

    both = AssociationProcessor(FAST, output=AssociationOutputConfig(annotate_image=True, fill_skipped_frames=True))
    for k in range(3):
        both.process("image", numpy_to_image(np.zeros((200, 100, 3), np.uint8), "bgr8", header(k)))
        if k != 1:                                     # frame 1 skipped by the detector: drawn with its prediction
            out = both.process("detections", detections_msg(k))
    assert [m.header.stamp for t, m in out if t == "tracks/image"] == [header(1).stamp, header(2).stamp]


def test_skipped_frames_get_the_predicted_tracks_when_the_next_detections_arrive():
    """fill_skipped_frames: every camera frame gets tracks; a frame the detector skipped gets the tracks predicted to
    its stamp (coasting), with its own header, published before the next detections' tracks."""
    # 8-px boxes: 0.1 heights is below the noise
    trusting = dataclasses.replace(FAST, coast_output_std=1.0, fill_output_std=1.0)
    proc = AssociationProcessor(trusting, output=AssociationOutputConfig(fill_skipped_frames=True))
    assert "image" in proc.inputs and "image" in proc.latest_only and "tracks/image" not in proc.outputs
    plain = AssociationProcessor(trusting)
    assert "image" not in plain.inputs

    def image(k):
        return numpy_to_image(np.zeros((4, 4, 3), np.uint8), "bgr8", header(k))

    tracked = {}
    for k in range(10):
        assert proc.process("image", image(k)) == []
        if k in (0, 1, 2, 5, 6, 9):                   # the detector skipped frames 3, 4, 7 and 8
            out = proc.process("detections", detections_msg(k))
            want = plain.process("detections", detections_msg(k))
            clouds = [m for topic, m in out if topic == "tracks"]
            assert [m.header.stamp for m in clouds] == [header(j).stamp for j in range(k + 1) if j not in tracked]
            assert all(m.header.frame_id == "uav_cam" for m in clouds)
            assert (cloud_to_table(clouds[-1], TRACK_DTYPE) == cloud_to_table(dict(want)["tracks"], TRACK_DTYPE)).all()
            tracked.update({j: cloud_to_table(m, TRACK_DTYPE) for j, m in zip(sorted(set(range(k + 1)) - set(tracked)),
                                                                               clouds)})
    assert sorted(tracked) == list(range(10)) and proc.filled_frames == 4 and proc.status()["skipped frames filled"] == 4
    for k in (3, 4, 7, 8):                            # predicted: 2 px a frame to the right, coasting
        assert sorted(tracked[k]["id"].tolist()) == [1, 2] and (tracked[k]["state"] == 2).all()
        np.testing.assert_allclose(tracked[k]["x"], 10 + 2 * k, atol=0.5)
    assert (tracked[6]["state"] == 1).all()
    broken = detections_msg(10)
    broken.data = broken.data[:5]                     # a malformed message is refused; frame 10 keeps waiting
    proc.process("image", image(10))
    assert process_guarded(proc, "detections", broken, ProcessingStats()) == []
    proc.process("image", image(11))
    out = proc.process("detections", detections_msg(11))
    assert [m.header.stamp for t, m in out if t == "tracks"] == [header(10).stamp, header(11).stamp]
    proc.process("image", image(13))                  # the stream restarts: the frame waiting is forgotten
    proc.reset()
    assert [t for t, _ in proc.process("detections", detections_msg(14))].count("tracks") == 1


def test_node_in_process_over_detection_messages_and_bag(tmp_path):
    with ros_context() as (ctx, executor):
        node = AssociationNode(context=ctx, parameter_overrides=[
            Parameter("confirm_length", value=2), Parameter("gate", value="mahalanobis")])
        probe = rclpy.create_node("probe", context=ctx)
        executor.add_node(node)
        executor.add_node(probe)
        got = []
        probe.create_subscription(PointCloud2, "tracks", got.append, 50)
        pub = probe.create_publisher(PointCloud2, "detections", 50)
        try:
            assert wait_for_subscribers(executor, pub)
            assert node.set_parameters([Parameter("cost_gate", value=-1.0)])[0].successful is False
            bag = tmp_path / "in.mcap"
            with BagWriter(bag) as writer:
                for k in range(6):
                    writer.write("detections", detections_msg(k), int(1e9 + k * 1e8))
            for _, msg, _ in BagReader(bag).ros_messages(["detections"]):
                pub.publish(msg)
            assert spin_until(executor, lambda: len(got) == 6, timeout_s=15)
            last = cloud_to_table(got[-1], TRACK_DTYPE)
            assert sorted(last["id"].tolist()) == [1, 2]
            assert got[-1].header.stamp == header(5).stamp and got[-1].header.frame_id == "uav_cam"
            first = cloud_to_table(got[0], TRACK_DTYPE)
            assert sorted(first["id"].tolist()) == [1, 2] and (first["state"] == 1).all()   # confirm_first_frame
        finally:
            node.destroy_node()
            probe.destroy_node()


def test_node_fills_the_frames_without_detections_over_ros():
    """The live node with output.fill_skipped_frames (a read-only parameter, as at start-up): images in on the
    sensor-data subscription, detections for some of them; tracks come out for every image, in stamp order."""
    from rclpy.qos import qos_profile_sensor_data  # noqa: PLC0415

    with ros_context() as (ctx, executor):
        node = AssociationNode(context=ctx, parameter_overrides=[
            Parameter("confirm_length", value=2), Parameter("gate", value="mahalanobis"),
            Parameter("coast_output_std", value=1.0), Parameter("fill_output_std", value=1.0),
            Parameter("output.fill_skipped_frames", value=True)])
        probe = rclpy.create_node("probe", context=ctx)
        executor.add_node(node)
        executor.add_node(probe)
        got = []
        probe.create_subscription(PointCloud2, "tracks", got.append, 50)
        images = probe.create_publisher(Image, "image", qos_profile_sensor_data)
        detections = probe.create_publisher(PointCloud2, "detections", 50)
        try:
            assert wait_for_subscribers(executor, images) and wait_for_subscribers(executor, detections)
            handled = 0
            for k in range(8):                  # one message at a time: the image slot is keep-newest
                images.publish(numpy_to_image(np.zeros((4, 4), np.uint8), "mono8", header(k)))
                handled += 1
                assert spin_until(executor, lambda: node.stats.received >= handled, timeout_s=10)
                if k not in (1, 3, 5):          # the detector skipped frames 1, 3 and 5
                    detections.publish(detections_msg(k))
                    handled += 1
                    assert spin_until(executor, lambda: node.stats.received >= handled, timeout_s=10)
            assert spin_until(executor, lambda: len(got) == 8, timeout_s=15)
            assert [m.header.stamp for m in got] == [header(k).stamp for k in range(8)]
            assert all(m.header.frame_id == "uav_cam" for m in got)
            filled = {k: cloud_to_table(got[k], TRACK_DTYPE) for k in (1, 3, 5)}
            assert all(sorted(t["id"].tolist()) == [1, 2] for t in filled.values())
            assert (filled[1]["state"] == 4).all()          # one detection: its velocity unknown, not trusted
            assert (filled[3]["state"] == 2).all() and (filled[5]["state"] == 2).all()   # coasting, published
            assert node.processor.filled_frames == 3
        finally:
            node.destroy_node()
            probe.destroy_node()


def test_tracks_table_keeps_every_state_and_markers_show_the_published():
    proc = AssociationProcessor(AssociationConfig(confirm_first_frame=False, confirm_length=3))
    out = dict(proc.process("detections", detections_msg(0)))
    table = cloud_to_table(out["tracks"], TRACK_DTYPE)
    assert sorted(table["id"].tolist()) == [1, 2] and (table["state"] == 0).all()     # tentative, in the table
    assert proc.status()["tracks published"] == 0
    assert len(out["tracks/markers"].markers) == 1                                   # only the delete-all


def test_seed_yaml_is_seed_config():
    from aircraft_docking_tracker.config import from_mapping  # noqa: PLC0415
    from multi_target_tracker.association import seed_config  # noqa: PLC0415

    params = load_yaml_parameters(package_config_dir() / "association_seed.yaml", "association")
    assoc = from_mapping(AssociationConfig, {k: v for k, v in params.items() if "." not in k})
    kalman = from_mapping(KalmanConfig, {k[len("kalman."):]: v for k, v in params.items() if k.startswith("kalman.")})
    assert assoc == seed_config()
    assert kalman.missed_update == "prediction"          # §3.3 rule 1: a missed target is updated with its prediction
    assert kalman.acceleration_noise_per_px == 0.0 and kalman.measurement_noise_per_px == 0.0


def _flagged_msg(k: int, low_first: bool) -> PointCloud2:
    """:func:`detections_msg`'s two targets with the low_confidence field, the first target flagged when asked,
    plus a flagged clutter row far from both."""
    plain = cloud_to_table(detections_msg(k), DETECTION_DTYPE)
    table = np.zeros(3, FLAGGED_DETECTION_DTYPE)
    for name in DETECTION_DTYPE.names:
        table[name][:2] = plain[name]
    table[2] = (400.0, 300.0, 10.0, 8.0, 0.99, 0, 1)
    table[LOW_CONFIDENCE][:2] = (int(low_first), 0)
    return table_to_cloud(table, header(k))


def test_low_confidence_field_round_trips_and_reaches_the_second_pass():
    msg = _flagged_msg(0, True)
    back = cloud_to_table(msg, FLAGGED_DETECTION_DTYPE)
    assert back[LOW_CONFIDENCE].tolist() == [1, 0, 1] and len(confident_rows(back)) == 1
    assert len(cloud_to_table(msg, DETECTION_DTYPE)) == 3       # a reader of the plain table ignores the field

    def run(low_confidence: bool):
        proc = AssociationProcessor(dataclasses.replace(FAST, low_confidence=low_confidence))
        for k in range(12):                                      # the first target flagged in frames 4-11
            out = dict(proc.process("detections", _flagged_msg(k, 4 <= k)))
        return cloud_to_table(out["tracks"], TRACK_DTYPE)

    with_stage, without = run(True), run(False)
    assert sorted(with_stage["id"].tolist()) == [1, 2]           # the flagged clutter row started nothing
    assert with_stage["state"][with_stage["id"] == 1].tolist() == [1]   # kept confirmed by its flagged detections
    assert without["state"][without["id"] == 1].tolist() != [1] and 3 not in without["id"]


def test_bench_live_case_is_what_the_node_publishes():
    """bench/uav_tracking.py --busy: its keep-newest schedule, and its filled tracks equal the node's (the UAV set-up's
    association, images for every frame, detections for the frames the schedule processes)."""
    import importlib.util  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    spec = importlib.util.spec_from_file_location("bench_uav_tracking",
                                                  Path(__file__).resolve().parents[1] / "bench" / "uav_tracking.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.keep_newest(10, 0.5) == set(range(10)) and bench.keep_newest(10, 1.0) == set(range(10))
    assert sorted(bench.keep_newest(10, 1.25)) == [0, 1, 2, 3, 5, 6, 7, 8, 9]      # one frame in five skipped
    assert sorted(bench.keep_newest(9, 2.0)) == [0, 2, 4, 6, 8]

    frames = 12
    processed = bench.keep_newest(frames, 2.0)
    tables = []
    for k in range(frames):                             # two 40-px vehicles driving apart at 10 Hz
        table = np.zeros(2, DETECTION_DTYPE)
        table["x"], table["y"] = [100 + 6 * k, 300 - 4 * k], [200, 100 + 3 * k]
        table["w"], table["h"], table["score"] = 40, 40, 0.95
        tables.append(table)
    stamps = [stamp_to_ns(header(k).stamp) * 1e-9 for k in range(frames)]
    from_bench = bench.track(stamps, tables, {}, processed, fill=True)

    from aircraft_docking_tracker.offline import build_processor  # noqa: PLC0415
    node = build_processor("association", package_config_dir() / "uav_camera.yaml")
    assert node.output.fill_skipped_frames
    published = {}
    for k in range(frames):
        node.process("image", numpy_to_image(np.zeros((4, 4, 3), np.uint8), "bgr8", header(k)))
        if k in processed:
            for topic, msg in node.process("detections", table_to_cloud(tables[k], header(k))):
                if topic == "tracks":
                    published[stamp_to_ns(msg.header.stamp)] = cloud_to_table(msg, TRACK_DTYPE)
    assert sorted(processed) == [0, 2, 4, 6, 8, 10, 11] and len(published) == frames
    for k in range(frames):
        mine, theirs = from_bench[k], published[stamp_to_ns(header(k).stamp)]
        assert len(mine) == len(theirs) == 2
        for name in ("id", "x", "y", "w", "h", "state"):
            np.testing.assert_array_equal(mine[name], theirs[name])
    # skipped frames 1 and 5: coasting; frame 1's targets, one detection old, are trusted to the set-up's
    # fill_output_std (0.3 box heights), not to coast_output_std's 0.1
    assert (from_bench[1]["state"] == 2).all() and (from_bench[5]["state"] == 2).all()
    assert node.tracker.config.fill_output_std > node.tracker.config.coast_output_std
