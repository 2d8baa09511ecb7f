"""mcap_record with use_sim_time subscribes at once and keeps the messages before the first /clock;
it splits a recording by size or duration as `ros2 bag record` does (issue #16, item 7)."""
from __future__ import annotations

import subprocess
import sys
import time

import pytest
import rclpy
import yaml
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp
from aircraft_docking_tracker.io.mcap_record import Recorder

from ros_helpers import ros_context, spin_until, wait_for_subscribers

pytestmark = pytest.mark.ros
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def test_sim_time_recorder_subscribes_before_the_first_clock_and_keeps_early_messages(tmp_path):
    path = tmp_path / "sim.mcap"
    with ros_context() as (ctx, executor):
        talker = rclpy.create_node("talker", context=ctx)
        node = rclpy.create_node("recorder", context=ctx,
                                 parameter_overrides=[Parameter("use_sim_time", value=True)])
        executor.add_node(talker)
        executor.add_node(node)
        pub = talker.create_publisher(String, "chatter", RELIABLE)
        clock = talker.create_publisher(Clock, "/clock", 10)
        writer = BagWriter(path)
        recorder = Recorder(node, writer, topics=["chatter"])
        recorder.start(discovery_interval=0.1)
        # no /clock yet: discovery must still run (it used to wait on sim time)
        assert spin_until(executor, lambda: "/chatter" in recorder.subscriptions, timeout_s=10)
        assert wait_for_subscribers(executor, pub)
        for i in range(5):
            pub.publish(String(data=f"early {i}"))
        assert spin_until(executor, lambda: len(recorder.pending) == 5)
        assert writer.message_count == 0
        assert wait_for_subscribers(executor, clock)
        clock.publish(Clock(clock=ns_to_stamp(50_000_000_000)))
        assert spin_until(executor, lambda: node.get_clock().now().nanoseconds >= 50_000_000_000)
        for i in range(5):
            pub.publish(String(data=f"late {i}"))
        assert spin_until(executor, lambda: writer.message_count == 10)
        writer.close()
        talker.destroy_node()
        node.destroy_node()
    got = [(m.deserialize().data, m.log_time_ns) for m in BagReader(path).messages()]
    assert [d for d, _ in got] == [f"early {i}" for i in range(5)] + [f"late {i}" for i in range(5)]
    assert all(t >= 50_000_000_000 for _, t in got)  # sim time, not 0 and not wall time


def test_recorder_cli_splits_by_duration(tmp_path):
    out = tmp_path / "run"
    script = (
        "import rclpy, time\n"
        "from std_msgs.msg import String\n"
        "rclpy.init()\n"
        "n = rclpy.create_node('talker')\n"
        "p = n.create_publisher(String, 'split_chatter', 10)\n"
        "i = 0\n"
        "while True:\n"
        "    p.publish(String(data=str(i))); i += 1; time.sleep(0.05)\n"
    )
    talker = subprocess.Popen([sys.executable, "-c", script])  # publishes until stopped
    try:
        result = subprocess.run([sys.executable, "-m", "aircraft_docking_tracker.io.mcap_record", "split_chatter",
                                 "-o", str(out), "--max-bag-duration", "1", "--max-duration", "6"],
                                capture_output=True, text=True, timeout=60)
    finally:
        talker.kill()
        talker.wait(timeout=30)
    assert result.returncode == 0, result.stderr
    files = sorted(out.glob("*.mcap"))
    assert len(files) >= 2, result.stdout
    meta = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert len(meta["relative_file_paths"]) == len(files)
    reader = BagReader(out)
    assert reader.message_count == meta["message_count"] > 10
    values = [int(m.deserialize().data) for m in reader.messages()]
    assert values == sorted(values)


def test_split_options_need_a_directory_output(tmp_path):
    result = subprocess.run([sys.executable, "-m", "aircraft_docking_tracker.io.mcap_record", "-a",
                             "-o", str(tmp_path / "x.mcap"), "--max-bag-size", "1000000"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "bag directory" in result.stderr and "Traceback" not in result.stderr
