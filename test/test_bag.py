"""rosbag2-compatible MCAP: our reader/writer, rosbags as the independent implementation, recovery."""
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import Point32, PolygonStamped
from sensor_msgs.msg import Image
from std_msgs.msg import String

from aircraft_docking_tracker.io.bag import (
    BagError, BagReader, BagWriter, message_definition, ns_to_stamp, recover, stamp_to_ns, type_hash)
from aircraft_docking_tracker.images import image_to_numpy, numpy_to_image
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, cloud_to_table, table_to_cloud
from ros_helpers import write_with_rosbags

T0 = 1_700_000_000_000_000_000


def sample_messages(n=20):
    """Images, detection tables and polygons with known content, in log-time order."""
    rng = np.random.default_rng(1)
    out = []
    for i in range(n):
        t = T0 + i * 50_000_000
        img = numpy_to_image(rng.integers(0, 255, (12, 16, 3), dtype=np.uint8), "bgr8")
        img.header.stamp, img.header.frame_id = ns_to_stamp(t), "camera"
        out.append(("image", img, t))
        det = table_to_cloud(np.array([(i, 2 * i, 5, 6, 0.5, 1)], DETECTION_DTYPE), img.header)
        out.append(("detections", det, t + 1))
        poly = PolygonStamped()
        poly.header = img.header
        poly.polygon.points = [Point32(x=float(i), y=1.0, z=0.0)] * 4
        out.append(("docking/polygon", poly, t + 2))
    return out


def write_sample(path, n=20, **kwargs):
    msgs = sample_messages(n)
    with BagWriter(path, **kwargs) as writer:
        for topic, msg, t in msgs:
            writer.write(topic, msg, t)
    return msgs


def test_schema_text_has_all_dependencies():
    text = message_definition("sensor_msgs/msg/Image")
    assert text.startswith("# This message contains an uncompressed image")
    assert "MSG: std_msgs/Header" in text and "MSG: builtin_interfaces/Time" in text
    assert type_hash("sensor_msgs/msg/Image").startswith("RIHS01_")


def test_round_trip_through_our_reader(tmp_path):
    msgs = write_sample(tmp_path / "a.mcap")
    reader = BagReader(tmp_path / "a.mcap")
    assert not reader.truncated
    assert {n: t.count for n, t in reader.topics.items()} == {"image": 20, "detections": 20, "docking/polygon": 20}
    assert reader.topics["image"].type_name == "sensor_msgs/msg/Image"
    got = list(reader.ros_messages())
    assert [(t, ts) for t, _, ts in got] == [(t, ts) for t, _, ts in msgs]
    np.testing.assert_array_equal(image_to_numpy(got[0][1]), image_to_numpy(msgs[0][1]))
    assert cloud_to_table(got[4][1], DETECTION_DTYPE)["y"][0] == 2.0
    assert stamp_to_ns(got[3][1].header.stamp) == T0 + 50_000_000
    only = list(reader.messages(topics=["docking/polygon"], start_ns=T0 + 100_000_000))
    assert len(only) == 18 and all(m.topic == "docking/polygon" for m in only)


def test_rosbags_reads_our_file_and_directory(tmp_path):
    rosbags = pytest.importorskip("rosbags.rosbag2")
    from rosbags.typesys import Stores, get_typestore

    msgs = write_sample(tmp_path / "bagdir")  # directory mode: metadata.yaml + bagdir_0.mcap
    info = yaml.safe_load((tmp_path / "bagdir" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == 60 and info["storage_identifier"] == "mcap"
    store = get_typestore(Stores.ROS2_JAZZY)
    for path in (tmp_path / "bagdir", tmp_path / "bagdir" / "bagdir_0.mcap"):
        with rosbags.Reader(path) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            assert types == {"image": "sensor_msgs/msg/Image", "detections": "sensor_msgs/msg/PointCloud2",
                             "docking/polygon": "geometry_msgs/msg/PolygonStamped"}
            assert reader.message_count == 60
            assert all(c.ext.offered_qos_profiles for c in reader.connections)
            rows = list(reader.messages())
            assert [ts for _, ts, _ in rows] == [t for _, _, t in msgs]
            conn, _, raw = rows[0]
            img = store.deserialize_cdr(raw, conn.msgtype)
            assert (img.width, img.height, img.encoding, img.header.frame_id) == (16, 12, "bgr8", "camera")
            assert bytes(img.data) == bytes(msgs[0][1].data)
            conn, _, raw = rows[2]
            poly = store.deserialize_cdr(raw, conn.msgtype)
            assert poly.polygon.points[0].x == 0.0 and len(poly.polygon.points) == 4


def test_we_read_a_file_that_rosbags_wrote(tmp_path):
    write_with_rosbags(tmp_path / "theirs", [T0 + i for i in range(5)], [f"hello {i}" for i in range(5)])
    reader = BagReader(tmp_path / "theirs")
    assert reader.topics["/chatter"].count == 5
    assert [m.data for _, m, _ in reader.ros_messages()] == [f"hello {i}" for i in range(5)]


def test_hard_killed_recording_recovers_up_to_last_chunk(tmp_path):
    path = tmp_path / "killed.mcap"
    writer = BagWriter(path, chunk_size=4096)
    for i in range(40):
        writer.write("chatter", String(data=f"m{i}"), T0 + i)
        if i == 29:
            writer.flush()
    writer._stream.flush()  # what the OS has at the moment of a SIGKILL: no summary, no footer
    size = path.stat().st_size
    reader = BagReader(path)
    assert reader.truncated and reader.topics["chatter"].count >= 30
    assert recover(path, tmp_path / "fixed.mcap") == reader.topics["chatter"].count
    fixed = BagReader(tmp_path / "fixed.mcap")
    assert not fixed.truncated
    assert [m.data for _, m, _ in fixed.ros_messages()][:30] == [f"m{i}" for i in range(30)]
    # cut the file in the middle of a chunk: still readable up to the last complete one
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: size - 7])
    assert BagReader(cut).topics["chatter"].count >= 1


@pytest.mark.parametrize("content, reason", [(None, "no such file"), (b"hello world", "not an MCAP")])
def test_missing_and_foreign_files_are_clear_errors(tmp_path, content, reason):
    path = tmp_path / "x.mcap"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(BagError, match=reason):
        BagReader(path)


def test_non_ros_profile_is_refused(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "json.mcap"
    with open(path, "wb") as stream:
        w = Writer(stream)
        w.start(profile="", library="test")
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("t", "json", sid)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()
    with pytest.raises(BagError, match="not a ROS 2 bag"):
        BagReader(path)


def test_writer_refuses_to_overwrite(tmp_path):
    write_sample(tmp_path / "a.mcap", n=1)
    with pytest.raises(BagError, match="exists"):
        BagWriter(tmp_path / "a.mcap")


def test_replay_qos_from_recorded_metadata_and_from_damaged_metadata():
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from aircraft_docking_tracker.io.bag import qos_from_metadata

    good = ("- history: 1\n  depth: 5\n  reliability: 1\n  durability: 2\n"
            "- history: 1\n  depth: 20\n  reliability: 1\n  durability: 2\n")
    qos = qos_from_metadata(good)
    assert qos.depth == 20 and qos.reliability == ReliabilityPolicy.RELIABLE
    assert qos.durability == DurabilityPolicy.VOLATILE
    # a flipped bit in a bag's channel metadata (found by test_fuzz_bags): unknown QoS, never an exception
    for damaged in ("- history: 1\n  depth: q0\n  reliability: 1\n", "- depth: -3\n", "- depth: 99999999999\n",
                    "- [1, 2]\n", "- 7\n", "{depth: 5}\n", ":\n  - :"):
        assert qos_from_metadata(damaged) is None, damaged


def test_an_empty_recording_is_told_apart_from_a_truncated_one(tmp_path):
    """A complete MCAP with no message (mcap_record stopped before any came) says so; the same file cut short is
    still a truncated one, with where the reading stopped."""
    writer = BagWriter(tmp_path / "empty.mcap")
    writer.close()
    with pytest.raises(BagError, match="holds no message"):
        BagReader(tmp_path / "empty.mcap")
    data = (tmp_path / "empty.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[:len(data) // 2])
    with pytest.raises(BagError, match="truncated MCAP with no readable message .stopped at a damaged"):
        BagReader(tmp_path / "cut.mcap")
