"""Launch-free ROS 2 test helpers: an isolated context, an executor, waiting for messages."""
from __future__ import annotations

import contextlib
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor


@contextlib.contextmanager
def ros_context(domain_id: int | None = None):
    """A fresh rclpy context (own domain if given) that is shut down whatever happens."""
    context = Context()
    kwargs = {"context": context}
    if domain_id is not None:
        kwargs["domain_id"] = domain_id
    rclpy.init(**kwargs)
    executor = SingleThreadedExecutor(context=context)
    try:
        yield context, executor
    finally:
        executor.shutdown(timeout_sec=2.0)
        if context.ok():
            rclpy.shutdown(context=context)


def spin_until(executor, predicate, timeout_s: float = 10.0, step_s: float = 0.02) -> bool:
    """Spin ``executor`` until ``predicate()`` is true or the time runs out; return the predicate."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        executor.spin_once(timeout_sec=step_s)
    return bool(predicate())


def wait_for_subscribers(executor, publisher, count: int = 1, timeout_s: float = 10.0) -> bool:
    return spin_until(executor, lambda: publisher.get_subscription_count() >= count, timeout_s)


def write_with_rosbags(folder, stamps_ns, texts, topic: str = "/chatter") -> None:
    """A rosbag2 MCAP bag written by the third-party ``rosbags`` library: std_msgs/String ``texts`` on
    ``topic`` at ``stamps_ns`` (the test is skipped where rosbags is not installed)."""
    import pytest  # noqa: PLC0415

    rosbags = pytest.importorskip("rosbags.rosbag2")
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415

    store = get_typestore(Stores.ROS2_JAZZY)
    string_type = store.types["std_msgs/msg/String"]
    with rosbags.Writer(folder, version=9, storage_plugin=rosbags.StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(topic, "std_msgs/msg/String", typestore=store)
        for stamp, text in zip(stamps_ns, texts):
            writer.write(conn, stamp, store.serialize_cdr(string_type(data=text), "std_msgs/msg/String"))


class FakePublisher:
    """A publisher that keeps what it was given."""

    def __init__(self):
        self.sent = []

    def publish(self, data):
        self.sent.append(data)


class FakePlayerNode:
    """All that mcap_play's Player needs of a node, without DDS: publishers that keep their messages, and a
    logger that keeps its lines."""

    def __init__(self):
        self.publishers: dict[str, FakePublisher] = {}
        self.lines: list[str] = []

    def create_publisher(self, cls, topic, qos):
        return self.publishers.setdefault(topic, FakePublisher())

    def get_logger(self):
        return self

    def info(self, text):
        self.lines.append(text)

    warning = info
