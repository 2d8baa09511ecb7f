"""Start the package's executables as separate processes, the way ``ros2 run`` would (no launch).

``ros2 launch`` is not on PyPI; the demo, the process-level integration tests and the pipeline
benchmark start nodes with this instead: the installed console script (``lib/...`` after colcon,
``.venv/bin`` here), ``--ros-args`` with the node's namespace, a parameter file, single parameters
and remappings; stopped with SIGINT (what Ctrl-C sends), then SIGTERM, then SIGKILL.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path


def executable_path(name: str) -> str:
    """The console script ``name``: next to this Python first (the venv), then on PATH."""
    candidate = Path(sys.executable).parent / name
    if candidate.is_file() and os.access(candidate, os.X_OK):
        return str(candidate)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f"executable {name!r} not found; run `make setup` (or colcon build)")
    return found


def _ros_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_ros_value(v) for v in value) + "]"
    return str(value)


@dataclass
class NodeProcess:
    """One executable with its ``--ros-args``; a context manager that stops it on exit."""

    executable: str
    args: list[str] = field(default_factory=list)  # before --ros-args (the tool's own options)
    namespace: str = ""
    node_name: str | None = None
    params_file: str | Path | None = None
    parameters: dict = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)
    log_path: str | Path | None = None
    env: dict[str, str] | None = None
    prefix: list[str] = field(default_factory=list)  # a wrapper that execs the rest (netns.Host.prefix)
    process: subprocess.Popen | None = None

    def command(self) -> list[str]:
        cmd = [*self.prefix, executable_path(self.executable), *map(str, self.args), "--ros-args"]
        if self.namespace:
            cmd += ["-r", f"__ns:=/{self.namespace.strip('/')}"]
        if self.node_name:
            cmd += ["-r", f"__node:={self.node_name}"]
        if self.params_file:
            cmd += ["--params-file", str(self.params_file)]
        for name, value in self.parameters.items():
            cmd += ["-p", f"{name}:={_ros_value(value)}"]
        for old, new in self.remaps.items():
            cmd += ["-r", f"{old}:={new}"]
        return cmd

    def start(self) -> "NodeProcess":
        out = open(self.log_path, "w") if self.log_path else subprocess.DEVNULL  # noqa: SIM115
        env = dict(os.environ, **(self.env or {}))
        self.process = subprocess.Popen(self.command(), stdout=out, stderr=subprocess.STDOUT, env=env,
                                        start_new_session=True)
        if out is not subprocess.DEVNULL:
            out.close()
        return self

    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def stop(self, timeout_s: float = 10.0) -> int | None:
        """SIGINT, then SIGTERM, then SIGKILL; returns the exit code."""
        if self.process is None:
            return None
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if self.process.poll() is not None:
                break
            try:
                self.process.send_signal(sig)
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                continue
            except ProcessLookupError:
                break
        return self.process.poll()

    def wait(self, timeout_s: float | None = None) -> int:
        return self.process.wait(timeout=timeout_s)

    def __enter__(self) -> "NodeProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def wait_until(predicate, timeout_s: float, step_s: float = 0.1) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step_s)
    return bool(predicate())
