"""PerceptionNode: parameters with ranges, processors, keep-newest frames, rejections, diagnostics."""
import time
from dataclasses import dataclass

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Point32, PolygonStamped
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from aircraft_docking_tracker.io.bag import ns_to_stamp
from aircraft_docking_tracker.config import param
from aircraft_docking_tracker.images import numpy_to_image, to_mono8
from aircraft_docking_tracker.ros.node_base import PerceptionNode
from aircraft_docking_tracker.ros.processing import MessageProcessor, ProcessingStats, process_guarded

from ros_helpers import ros_context, spin_until, wait_for_subscribers

pytestmark = pytest.mark.ros


@dataclass
class ToyConfig:
    threshold: float = param(0.5, "brightness threshold", low=0.0, high=1.0)
    delay_s: float = param(0.0, "artificial processing time", low=0.0, high=1.0)
    mode: str = param("mean", "statistic", choices=("mean", "max"))
    box: tuple = param((), "optional box [x, y, w, h]")


class ToyProcessor(MessageProcessor):
    """Publishes the image's bright-pixel fraction as a polygon x coordinate."""

    inputs = {"image": "sensor_msgs/msg/Image"}
    outputs = {"out": "geometry_msgs/msg/PolygonStamped"}
    latest_only = frozenset({"image"})

    def __init__(self, config):
        self.config = config
        self.resets = 0

    def process(self, topic, msg):
        grey = to_mono8(msg)
        time.sleep(self.config.delay_s)
        poly = PolygonStamped()
        poly.header = msg.header
        poly.polygon.points = [Point32(x=float((grey > 255 * self.config.threshold).mean()))]
        return [("out", poly)]

    def reset(self):
        self.resets += 1


class ToyNode(PerceptionNode):
    def __init__(self, **kwargs):
        super().__init__("toy", **kwargs)
        self.attach_processor(ToyProcessor(self.declare_config(ToyConfig)))

    def on_config_changed(self, cfg):
        self.processor.config = cfg


def image(value: int, stamp_ns: int, encoding="mono8"):
    msg = numpy_to_image(np.full((4, 4), value, np.uint8), encoding)
    msg.header.stamp, msg.header.frame_id = ns_to_stamp(stamp_ns), "cam"
    return msg


def test_parameters_refuse_bad_values_and_apply_good_ones():
    with ros_context() as (ctx, executor):
        node = ToyNode(context=ctx, parameter_overrides=[Parameter("threshold", value=7.0)])
        try:
            assert node.config().threshold == 0.5  # out-of-range override refused, default kept
            result = node.set_parameters([Parameter("threshold", value=1.5)])[0]
            assert not result.successful
            result = node.set_parameters([Parameter("mode", value="median")])[0]
            assert not result.successful and "not one of" in result.reason
            assert node.set_parameters([Parameter("threshold", value=0.25)])[0].successful
            assert node.processor.config.threshold == 0.25
            descriptor = node.describe_parameter("threshold")
            assert descriptor.floating_point_range[0].to_value == 1.0 and "brightness" in descriptor.description
            assert node.set_parameters([Parameter("box", value=[1.0, 2.0, 3.0, 4.0])])[0].successful
            assert node.processor.config.box == (1.0, 2.0, 3.0, 4.0)
        finally:
            node.destroy_node()


def test_live_processing_rejections_and_diagnostics():
    with ros_context() as (ctx, executor):
        node = ToyNode(context=ctx)
        probe = rclpy.create_node("probe", context=ctx)
        executor.add_node(node)
        executor.add_node(probe)
        got, diags = [], []
        probe.create_subscription(PolygonStamped, "out", got.append, 10)
        probe.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
        pub = probe.create_publisher(Image, "image", qos_profile_sensor_data)
        try:
            assert wait_for_subscribers(executor, pub)
            bad = image(0, 5)
            bad.encoding = "bgr9"
            pub.publish(bad)
            assert spin_until(executor, lambda: node.stats.rejected_total == 1)
            pub.publish(image(255, 10))
            assert spin_until(executor, lambda: len(got) == 1)
            assert got[0].header.frame_id == "cam" and got[0].header.stamp.nanosec == 10
            assert got[0].polygon.points[0].x == 1.0
            assert spin_until(executor, lambda: any(d.status[0].values for d in diags), timeout_s=5)
            values = {kv.key: kv.value for kv in diags[-1].status[0].values}
            assert values["rejected"] == "1" and values["processed"] == "1"
            assert any("unknown image encoding" in k for k in values)
        finally:
            node.destroy_node()
            probe.destroy_node()


def test_overload_keeps_the_newest_frame_and_counts_skipped():
    with ros_context() as (ctx, executor):
        node = ToyNode(context=ctx, parameter_overrides=[Parameter("delay_s", value=0.2)])
        probe = rclpy.create_node("probe", context=ctx)
        executor.add_node(node)
        executor.add_node(probe)
        got = []
        probe.create_subscription(PolygonStamped, "out", got.append, 50)
        pub = probe.create_publisher(Image, "image", qos_profile_sensor_data)
        try:
            assert wait_for_subscribers(executor, pub)
            for i in range(10):
                pub.publish(image(255, 1000 + i))
                executor.spin_once(timeout_sec=0.01)
            # the newest frame always comes out; the ones replaced while busy are counted
            assert spin_until(executor, lambda: got and got[-1].header.stamp.nanosec == 1009, timeout_s=10)
            assert node.stats.skipped >= 3, node.stats
            assert len(got) == node.stats.processed < 10
        finally:
            node.destroy_node()
            probe.destroy_node()


def test_guard_resets_on_time_jump_and_survives_internal_errors():
    class Fragile(ToyProcessor):
        def process(self, topic, msg):
            if msg.header.stamp.nanosec == 99:
                raise RuntimeError("boom")
            return super().process(topic, msg)

    proc, stats = Fragile(ToyConfig()), ProcessingStats()
    assert process_guarded(proc, "image", image(1, 50), stats)
    assert process_guarded(proc, "image", image(1, 20), stats)  # backwards: a looped bag
    assert stats.time_jumps == 1 and proc.resets == 1
    assert process_guarded(proc, "image", image(1, 99), stats) == []
    assert any("internal error RuntimeError: boom" in r for r in stats.rejected)


def test_image_qos_is_best_effort_and_overridable_to_reliable_by_the_standard_parameter():
    """Sensor-data QoS by default; ``qos_overrides./image.subscription.reliability: reliable`` (the
    ROS 2 override point, read only) makes the image subscription reliable for a lossy link, and a
    node built from a spec does not list that override as an unknown parameter."""
    from rclpy.qos import ReliabilityPolicy

    from aircraft_docking_tracker.ros.processing import ProcessorSpec

    class SpecNode(PerceptionNode):
        def __init__(self, **kwargs):
            super().__init__("spec_toy", **kwargs)
            self.attach_spec(ProcessorSpec("spec_toy", {"": ToyConfig}, lambda c: ToyProcessor(c[""])))

    override = Parameter("qos_overrides./image.subscription.reliability", value="reliable")
    with ros_context() as (ctx, executor):
        plain = ToyNode(context=ctx)
        tuned = SpecNode(context=ctx, parameter_overrides=[override, Parameter("thresold", value=0.3)])
        try:
            reliability = {n.get_name(): [s.qos_profile.reliability for s in n.subscriptions if s.topic_name == "/image"]
                           for n in (plain, tuned)}
            assert reliability == {"toy": [ReliabilityPolicy.BEST_EFFORT], "spec_toy": [ReliabilityPolicy.RELIABLE]}
            assert tuned.unknown_parameters == ["thresold"]  # a typo is still caught
        finally:
            plain.destroy_node()
            tuned.destroy_node()


def test_latency_is_reported_for_live_stamps_and_explained_for_stamps_on_another_clock():
    """Stamp-to-output latency on the node's clock; a bag replayed without use_sim_time (stamps hours
    old) or a camera clock ahead gives no latency figure but the offset, instead of 1e11 ms."""
    from aircraft_docking_tracker.ros.node_base import _latency_text

    def median_latency(stamp_age_s: float) -> tuple[dict, str]:
        stats, now_ns = ProcessingStats(), 5_000_000_000_000
        for i in range(5):
            stamp = now_ns - int(stamp_age_s * 1e9) + i
            process_guarded(ToyProcessor(ToyConfig()), "image", image(100, stamp), stats, now_ns=lambda: now_ns)
        summary = stats.summary()
        return summary, _latency_text(summary)

    live, text = median_latency(0.040)
    assert live["latency_ms_p50"] == pytest.approx(40.0, abs=0.01) and "stamp_offset_s" not in live and text == "40.00"
    replayed, text = median_latency(3 * 3600.0)
    assert np.isnan(replayed["latency_ms_p50"]) and replayed["stamp_offset_s"] == pytest.approx(10800.0)
    assert text.startswith("n/a") and "1.08e+04 s behind" in text and "use_sim_time" in text
    ahead, text = median_latency(-30.0)
    assert np.isnan(ahead["latency_ms_p50"]) and "30 s ahead of" in text
    slightly_ahead, text = median_latency(-0.2)  # within the skew allowed between hosts: latency 0
    assert slightly_ahead["latency_ms_p50"] == 0.0 and text == "0.00"



def test_processing_time_is_that_of_the_input_the_node_works_on():
    """A node with two inputs (the docking tracker: images it tracks in, ~12 ms, and detection tables it only keeps,
    ~0.2 ms) reports the processing time of the input with the most processing time, whichever kind has one message
    more; each input's own median is reported beside (over all messages the median flipped between the two)."""
    for images, tables in ((208, 210), (210, 208)):
        stats = ProcessingStats()
        for _ in range(images):
            stats.record(0.012, None, "image")
        for _ in range(tables):
            stats.record(0.0002, None, "detections")
        summary = stats.summary()
        assert summary["main_topic"] == "image" and summary["processing_ms_p50"] == pytest.approx(12.0)
        assert summary["processing_ms_p50 detections"] == pytest.approx(0.2)
        assert summary["processing_ms_p50 image"] == pytest.approx(12.0)
    single = ProcessingStats()
    single.record(0.005, None, "image")
    assert "processing_ms_p50 image" not in single.summary() and single.summary()["processing_ms_p50"] == 5.0

def test_a_failed_warm_up_is_logged_by_the_node_and_the_node_still_runs(monkeypatch):
    """MessageProcessor.warm_up keeps the failure; attach_processor logs it as a warning (every node alike)."""
    class ColdProcessor(ToyProcessor):
        def warm_up_work(self):
            raise RuntimeError("kernel cache unreadable")

    processor = ColdProcessor(ToyConfig())
    processor.warm_up()
    assert processor.warm_up_error == "RuntimeError: kernel cache unreadable"
    with ros_context() as (ctx, executor):
        node = PerceptionNode("cold", context=ctx)
        warnings = []
        monkeypatch.setattr(type(node.get_logger()), "warning", lambda self, text, **kw: warnings.append(text))
        try:
            node.attach_processor(processor)
            assert any("warm-up failed (RuntimeError: kernel cache unreadable)" in w for w in warnings)
            assert node.processor is processor
        finally:
            node.destroy_node()


def test_a_signal_landing_while_the_executor_builds_its_wait_set_is_a_clean_stop(monkeypatch, capsys):
    """rclpy's signal handler shuts the context down from another thread; landing while the executor builds its
    wait set, spin raises RCLError "the given context is not valid" rather than ExternalShutdownException (a
    `make test` run saw association_node exit 1 so). run_node exits 0 then, and still 1 on a failure while rclpy
    is up."""
    from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: PLC0415
    from rclpy.node import Node  # noqa: PLC0415

    from aircraft_docking_tracker.ros import node_base  # noqa: PLC0415

    class SignalledExecutor:
        def add_node(self, node):
            self.node = node

        def spin(self):
            rclpy.shutdown()          # what the signal handler's thread does
            raise rclpy_implementation.RCLError("failed to initialize wait set: the given context is not valid, "
                                                "either rcl_init() was not called or rcl_shutdown() was called.")

    class BrokenExecutor(SignalledExecutor):
        def spin(self):
            raise RuntimeError("a bug in a callback")

    monkeypatch.setattr(node_base, "SingleThreadedExecutor", SignalledExecutor)
    assert node_base.run_node(Node, ["toy_node"], node_name="toy_node") == 0
    assert "stopped" not in capsys.readouterr().err
    monkeypatch.setattr(node_base, "SingleThreadedExecutor", BrokenExecutor)
    with pytest.raises(SystemExit) as stopped:
        node_base.run_node(Node, ["toy_node"], node_name="toy_node")
    assert stopped.value.code == 1
    assert "toy_node: stopped: RuntimeError: a bug in a callback" in capsys.readouterr().err
    assert not rclpy.ok()
