"""Command-line helpers shared by the executables (ROS argument splitting, safe text outputs)."""
from __future__ import annotations

import os
from pathlib import Path


class AtomicFile:
    """A text file written under a temporary name beside ``path`` and moved into place by
    :meth:`close`; :meth:`abort` removes it, so a run that fails leaves the old file (or none)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._partial = self.path.parent / f".{self.path.name}.partial-{os.getpid()}"
        self._stream = open(self._partial, "w")  # noqa: SIM115 (closed in close() / abort())

    def write(self, text: str) -> int:
        return self._stream.write(text)

    def close(self) -> None:
        if not self._stream.closed:
            self._stream.close()
            os.replace(self._partial, self.path)

    def abort(self) -> None:
        if not self._stream.closed:
            self._stream.close()
            self._partial.unlink(missing_ok=True)


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """Split ``argv`` (without the program name) into the tool's own arguments and ROS arguments.

    Everything between ``--ros-args`` and ``--`` (or the end) goes to rcl; the rest is the tool's.
    rcl's ``remove_ros_args`` would also take any ``old:=new`` outside ``--ros-args`` as a legacy
    remap rule, which swallowed options like ``mcap_play --remap image:=/cam/image``.
    """
    own, ros, inside = [], [], False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
            ros.append(arg)
        elif arg == "--" and inside:
            inside = False
        elif inside:
            ros.append(arg)
        else:
            own.append(arg)
    return own, ros


def stopped_by_signal() -> bool:
    """Whether rclpy has been shut down, as its SIGINT/SIGTERM handler does from its own thread. An exception out
    of an executor's spin after that is the stop landing while the executor built its wait set (RCLError "failed
    to initialize wait set: the given context is not valid" instead of ExternalShutdownException; ros2/rclpy#398,
    ros2/ros2cli#854): the stop that was asked for, not a failure."""
    import rclpy  # noqa: PLC0415 - this module stays importable without ROS

    return not rclpy.ok()
