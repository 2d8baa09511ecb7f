"""Launch-free integration: live topics -> mcap_record's Recorder -> file -> mcap_play's Player -> live."""
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import String

from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp
from aircraft_docking_tracker.images import image_to_numpy, numpy_to_image
from aircraft_docking_tracker.io.mcap_play import Player, PlayOptions
from aircraft_docking_tracker.io.mcap_record import Recorder
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, cloud_to_table, table_to_cloud

from ros_helpers import ros_context, spin_until, wait_for_subscribers, write_with_rosbags

pytestmark = pytest.mark.ros
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def make_image(i):
    msg = numpy_to_image(np.full((24, 32, 3), i, np.uint8), "bgr8")
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(1_000_000_000 + i * 100_000_000), "camera"
    return msg


def test_live_record_then_replay_delivers_every_message_intact_and_in_order(tmp_path):
    bag_path = tmp_path / "live"
    n = 30
    with ros_context() as (ctx, executor):
        talker = rclpy.create_node("talker", context=ctx)
        recorder_node = rclpy.create_node("recorder", context=ctx)
        executor.add_node(talker)
        executor.add_node(recorder_node)
        writer = BagWriter(bag_path)
        recorder = Recorder(recorder_node, writer, topics=["image", "detections", "chatter"])
        pubs = {"image": talker.create_publisher(Image, "image", RELIABLE),
                "detections": talker.create_publisher(PointCloud2, "detections", RELIABLE),
                "chatter": talker.create_publisher(String, "chatter", RELIABLE)}
        assert spin_until(executor, lambda: (recorder.discover(), len(recorder.subscriptions) == 3)[1])
        for pub in pubs.values():
            assert wait_for_subscribers(executor, pub)
        for i in range(n):
            img = make_image(i)
            pubs["image"].publish(img)
            pubs["detections"].publish(table_to_cloud(np.array([(i, i, 4, 4, 0.5, 1)], DETECTION_DTYPE), img.header))
            pubs["chatter"].publish(String(data=f"msg {i}"))
            executor.spin_once(timeout_sec=0.005)
        assert spin_until(executor, lambda: writer.message_count == 3 * n)
        writer.close()
        talker.destroy_node()
        recorder_node.destroy_node()

    reader = BagReader(bag_path)
    assert {t: i.count for t, i in reader.topics.items()} == {"/image": n, "/detections": n, "/chatter": n}
    assert "reliable" in reader.topics["/image"].qos_text
    assert reader.topics["/image"].type_hash.startswith("RIHS01_")

    with ros_context() as (ctx, executor):
        listener = rclpy.create_node("listener", context=ctx)
        player_node = rclpy.create_node("player", context=ctx)
        executor.add_node(listener)
        received = {"image": [], "detections": [], "chatter": []}
        listener.create_subscription(Image, "/replayed/image", received["image"].append, RELIABLE)
        listener.create_subscription(PointCloud2, "/detections", received["detections"].append, RELIABLE)
        listener.create_subscription(String, "/chatter", received["chatter"].append, RELIABLE)
        player = Player(player_node, reader, PlayOptions(rate=5.0, remap={"/image": "/replayed/image"},
                                                         wait_for_subscribers_s=10.0))
        thread = threading.Thread(target=player.run)
        thread.start()
        assert spin_until(executor, lambda: sum(map(len, received.values())) == 3 * n, timeout_s=20)
        thread.join()
        player_node.destroy_node()
        listener.destroy_node()
    assert [m.data for m in received["chatter"]] == [f"msg {i}" for i in range(n)]
    for i, img in enumerate(received["image"]):
        assert img.header.frame_id == "camera" and img.header.stamp.nanosec == (i * 100_000_000) % 1_000_000_000
        assert int(image_to_numpy(img)[0, 0, 0]) == i
    assert [float(cloud_to_table(m, DETECTION_DTYPE)["x"][0]) for m in received["detections"]] == list(range(n))
    assert player.report.published == 3 * n


def test_a_rosbags_written_file_plays_onto_live_topics(tmp_path):
    write_with_rosbags(tmp_path / "theirs", [5_000_000_000 + i * 10_000_000 for i in range(10)],
                       [f"from rosbags {i}" for i in range(10)])
    with ros_context() as (ctx, executor):
        listener = rclpy.create_node("listener", context=ctx)
        executor.add_node(listener)
        got = []
        listener.create_subscription(String, "/chatter", got.append, RELIABLE)
        player = Player(rclpy.create_node("player", context=ctx), BagReader(tmp_path / "theirs"),
                        PlayOptions(wait_for_subscribers_s=10.0))
        thread = threading.Thread(target=player.run)
        thread.start()
        assert spin_until(executor, lambda: len(got) == 10, timeout_s=15)
        thread.join()
    assert [m.data for m in got] == [f"from rosbags {i}" for i in range(10)]
    assert max(abs(e) for e in player.report.timing_errors_ns) < 1e9  # sanity only, not a speed claim


def test_player_waits_for_every_expected_subscriber_before_the_first_message(tmp_path):
    """--min-subscribers: a node and a recorder that joins late both get the first, volatile message."""
    path = tmp_path / "t.mcap"
    with BagWriter(path) as writer:
        for i in range(3):
            writer.write("/chatter", String(data=str(i)), 1_000_000_000 + i * 10_000_000)
    with ros_context() as (ctx, executor):
        early, late = (rclpy.create_node(name, context=ctx) for name in ("early", "late"))
        executor.add_node(early)
        executor.add_node(late)
        got = {"early": [], "late": []}
        early.create_subscription(String, "/chatter", lambda m: got["early"].append(m.data), RELIABLE)
        player = Player(rclpy.create_node("player", context=ctx), BagReader(path),
                        PlayOptions(wait_for_subscribers_s=20.0, min_subscribers=2))
        assert not player.wait_for_subscribers(0.3, 2), "one subscriber is not two"
        thread = threading.Thread(target=player.run)
        thread.start()
        time.sleep(0.5)  # the player is still waiting: nothing published yet
        assert player.report.published == 0
        late.create_subscription(String, "/chatter", lambda m: got["late"].append(m.data), RELIABLE)
        assert spin_until(executor, lambda: len(got["early"]) == len(got["late"]) == 3, timeout_s=15), got
        thread.join()
    assert got["early"] == got["late"] == ["0", "1", "2"]


def test_player_honours_start_duration_and_loop(tmp_path):
    path = tmp_path / "t.mcap"
    with BagWriter(path) as writer:
        for i in range(10):
            writer.write("/chatter", String(data=str(i)), 1_000_000_000 + i * 10_000_000)
    with ros_context() as (ctx, executor):
        node = rclpy.create_node("player", context=ctx)
        listener = rclpy.create_node("listener", context=ctx)
        executor.add_node(listener)
        got = []
        listener.create_subscription(String, "/chatter", lambda m: got.append(m.data), RELIABLE)
        options = PlayOptions(start_offset_s=0.02, duration_s=0.05, wait_for_subscribers_s=10.0)
        Player(node, BagReader(path), options).run()
        assert spin_until(executor, lambda: len(got) == 5)
        assert got == ["2", "3", "4", "5", "6"]
        looping = Player(node, BagReader(path), PlayOptions(loop=True, rate=10.0, clock_hz=50.0))
        thread = threading.Thread(target=looping.run)
        thread.start()
        assert spin_until(executor, lambda: looping.report.loops >= 3, timeout_s=10)
        looping.stop()
        thread.join()


@pytest.mark.parametrize("content, message", [(None, "no such file"), (b"garbage", "not an MCAP")])
def test_cli_errors_are_clear_and_do_not_trace(tmp_path, content, message):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    result = subprocess.run([sys.executable, "-m", "aircraft_docking_tracker.io.mcap_play", str(path)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr
