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
