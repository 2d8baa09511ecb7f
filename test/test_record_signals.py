"""mcap_record as a separate process, the way `ros2 run` starts it: Ctrl-C and a hard kill."""
import os
import shutil
import signal
import subprocess
import time

import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from aircraft_docking_tracker.io.bag import BagReader, recover

from ros_helpers import ros_context, spin_until

pytestmark = pytest.mark.ros
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def recorder_command():
    exe = shutil.which("mcap_record")
    if exe is None:
        pytest.skip("mcap_record is not installed (run `make setup`)")
    return exe


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_recorder_process_stopped_by_signal(tmp_path, sig):
    out = tmp_path / "rec.mcap"
    proc = subprocess.Popen([recorder_command(), "/sig_chatter", "-o", str(out), "--flush-interval", "0.2",
                             "--ros-args", "-r", "__node:=recorder_under_test"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        with ros_context() as (ctx, executor):
            node = rclpy.create_node("talker", context=ctx)
            executor.add_node(node)
            pub = node.create_publisher(String, "/sig_chatter", RELIABLE)
            assert spin_until(executor, lambda: pub.get_subscription_count() > 0, timeout_s=20), "recorder never subscribed"
            for i in range(50):
                pub.publish(String(data=f"m{i}"))
                executor.spin_once(timeout_sec=0.01)
            time.sleep(1.0)  # at least one flush interval: the chunk reaches the disk
            proc.send_signal(sig)
            output, _ = proc.communicate(timeout=20)
            node.destroy_node()
    finally:
        if proc.poll() is None:
            proc.kill()
    reader = BagReader(out)
    if sig == signal.SIGKILL:
        assert reader.truncated
        assert recover(out, tmp_path / "fixed.mcap") == 50
        reader = BagReader(tmp_path / "fixed.mcap")
    else:
        assert proc.returncode == 0, output
        assert not reader.truncated and "wrote 50 messages" in output
    assert [m.data for _, m, _ in reader.ros_messages()] == [f"m{i}" for i in range(50)]


def test_a_signal_landing_while_the_executor_builds_its_wait_set_closes_the_bag_and_exits_0(tmp_path, monkeypatch,
                                                                                          capsys):
    """The signal handler's shutdown can race the executor's wait set (RCLError "the given context is not valid"
    from spin_once, not ExternalShutdownException): the recorder closes its bag and exits 0 as on any Ctrl-C."""
    import rclpy.executors  # noqa: PLC0415
    from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: PLC0415

    from aircraft_docking_tracker.io import mcap_record  # noqa: PLC0415

    class SignalledExecutor(rclpy.executors.SingleThreadedExecutor):
        def spin_once(self, timeout_sec=None):
            rclpy.shutdown()          # what the signal handler's thread does
            raise rclpy_implementation.RCLError("failed to initialize wait set: the given context is not valid")

    monkeypatch.setattr(rclpy.executors, "SingleThreadedExecutor", SignalledExecutor)
    out = tmp_path / "rec.mcap"
    assert mcap_record.main(["/nobody", "-o", str(out), "--ros-args", "-r", "__node:=racing_recorder"]) == 0
    assert "wrote 0 messages" in capsys.readouterr().out
    assert out.read_bytes().endswith(b"\x89MCAP0\r\n")     # closed: the footer and the closing magic written
