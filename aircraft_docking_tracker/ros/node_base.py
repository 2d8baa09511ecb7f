"""The base every node of this package shares: parameters, QoS, frame dropping, diagnostics.

A node is thin::

    class DetectorNode(PerceptionNode):
        def __init__(self, **kwargs):
            super().__init__("detector", **kwargs)
            self.attach_spec(SPEC)   # ROS parameters with ranges from SPEC's configs; topics, QoS

        def on_config_changed(self, config):                     # a parameter was set at runtime
            self.processor.configure(config)

    def main(args=None):
        run_node(DetectorNode, args)

* ``declare_config`` turns a config dataclass (``config.param`` fields) into parameters with
  descriptors and ranges; every value goes through ``config.validate`` (type, finiteness, range,
  then the config's cross-field ``validate()``). A bad value from ``--params-file`` is refused on
  its own (logged, listed in diagnostics, its parameter back to the default), the rest applies; a
  runtime ``ros2 param set`` that fails is refused with the reason and the previous configuration
  kept; the node keeps running.
* ``attach_processor`` subscribes to the processor's inputs (images: sensor-data QoS, keep the
  newest frame, processed off the executor thread, skipped frames counted; other inputs: reliable,
  in order), publishes its outputs (reliable) and runs everything through
  ``processing.process_guarded`` — the same call the offline runner makes.
* ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``) at 1 Hz: rate, processing time, stamp
  latency, received / skipped / rejected inputs with every reason, time jumps, refused parameters
  and processor status. Level: ERROR while the processor cannot work (``health()``) or after
  recent internal errors, WARN after recent rejections, when most frames are skipped or when
  parameter values were refused, else OK (see ``HOLD_S``).
* ``run_node``: ``--help`` prints usage and parameters; bad ``--params-file`` is one line, exit 2.
"""
from __future__ import annotations

import array
import copy
import dataclasses
import logging
import os
import sys
import threading
import time
import traceback
from typing import Any, Callable

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import InvalidParameterValueException, ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions

from .. import config as config_module
from ..io.bag import get_message_class
from .processing import (ERROR, MAX_REASONS, OK, OTHER_REASONS, WARN, MessageProcessor, ProcessingStats, reason_key,
                         process_guarded)

OUTPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
INPUT_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
_DOUBLE_MAX = sys.float_info.max
_INT_MAX = 2**62
#: A rejection keeps the status at WARN (an internal error at ERROR) for this long; then, after that
#: many seconds of good frames, it returns to OK (the counts stay in the values).
HOLD_S = 10.0
#: Each kind of rejection reason is logged at most this often.
LOG_EVERY_S = 2.0
#: WARN when more than this fraction of the frames of the last few seconds were skipped (overload).
SKIP_WARN_FRACTION = 0.5


class _LatestSlot:
    """Holds the newest message only; a message replaced before it was taken counts as skipped."""

    def __init__(self, handler: Callable[[Any], None], stats: ProcessingStats, name: str):
        self._handler = handler
        self._stats = stats
        self._condition = threading.Condition()
        self._message = None
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name=f"latest:{name}", daemon=True)
        self._thread.start()

    def offer(self, msg: Any) -> None:
        with self._condition:
            if self._message is not None:
                self._stats.skip()
            self._message = msg
            self._condition.notify()

    def _run(self) -> None:
        while True:
            with self._condition:
                while self._message is None and not self._stopped:
                    self._condition.wait(0.5)
                if self._stopped:
                    return
                msg, self._message = self._message, None
            try:
                self._handler(msg)
            except Exception:  # the handler guards processing; this keeps the thread alive whatever
                self._stats.reject("internal error in the frame handler")
                traceback.print_exc()

    def stop(self) -> None:
        with self._condition:
            self._stopped = True
            self._condition.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)


class PerceptionNode(Node):
    """rclpy Node with config-backed parameters, a processor, and diagnostics."""

    def __init__(self, node_name: str, **kwargs):
        super().__init__(node_name, **kwargs)
        self.stats = ProcessingStats()
        self.processor: MessageProcessor | None = None
        self._configs: dict[str, tuple[type, Any]] = {}  # prefix -> (class, current instance)
        self._slots: list[_LatestSlot] = []
        self._publishers_by_topic: dict[str, Any] = {}
        self._process_lock = threading.Lock()
        self.config_errors: dict[str, str] = {}   # parameter -> why its value was refused at start-up
        self.unknown_parameters: list[str] = []   # overrides naming no parameter (typos, other nodes')
        self._logged_at: dict[str, float] = {}   # rejection kind -> when it was last logged
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._diagnostics_timer = self.create_timer(1.0, self.publish_diagnostics)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

    # ------------------------------------------------------------------ parameters
    def declare_config(self, cls: type, prefix: str = ""):
        """Declare one parameter per field of the config dataclass ``cls``; return the config.

        Values from ``--params-file`` / ``-p`` go through the one validation every config has
        (``config.validate``: each field's type, finiteness and range, then the config's cross-field
        rules, e.g. a model that loads). Each bad value is refused on its own: logged with the
        reason, listed in ``/diagnostics`` (WARN) and its parameter set back to the default, so
        ``get_parameters`` reports what the node runs; every other value of the file is applied.
        """
        defaults = cls()
        fields = {f.name: f for f in dataclasses.fields(cls)}
        refused = self._refused_by_cross_field_rules(cls, prefix, fields, defaults)
        values = {}
        for name, f in fields.items():
            full = prefix + name
            default = getattr(defaults, name)
            descriptor = _descriptor(f, default)
            override = self._parameter_overrides.get(full)
            problem = None
            if name in refused:    # a cross-field rule refused it before declaring: a read-only parameter
                # cannot be undeclared to take its default afterwards, as the loop below does
                param = self.declare_parameter(full, _ros_default(default), descriptor, ignore_override=True)
                values[name] = _from_ros(param.value, default)
                continue
            if override is not None:
                coerced = _coerce_override(override.value, default)
                try:   # checked before declaring: a refused value never becomes the parameter's value
                    config_module.check_field(f, _from_ros(coerced, default), default)
                    self._parameter_overrides[full] = Parameter(full, value=coerced)
                except (config_module.ConfigError, TypeError, ValueError) as exc:
                    problem = exc
            if problem is None:
                try:
                    param = self.declare_parameter(full, _ros_default(default), descriptor)
                except (InvalidParameterValueException, ParameterException, TypeError, ValueError) as exc:
                    problem = exc   # rclpy refused the type (declaration did not happen)
            if problem is not None:
                self._refuse_at_start(full, f"{full}={override.value!r} refused: {_short(problem)}; keeping the "
                                      f"default {default!r}")
                param = self.declare_parameter(full, _ros_default(default), descriptor, ignore_override=True)
            value = _from_ros(param.value, default)
            values[name] = value
        # cross-field rules: refuse the values the rule names (back to their defaults), keep the rest
        for _ in range(len(fields) + 1):
            try:
                cfg = config_module.from_mapping(cls, values)
                break
            except config_module.ConfigError as exc:
                named = [n for n in exc.fields if n in values and values[n] != getattr(defaults, n)]
                if not named:   # the defaults themselves fail (e.g. the default model is missing)
                    self._refuse_at_start(prefix or cls.__name__, f"{cls.__name__}: {exc}")
                    cfg = cls(**values)
                    break
                for n in named:
                    self._refuse_at_start(prefix + n, f"{prefix + n}={values[n]!r} refused: {exc}; keeping the "
                                          f"default {getattr(defaults, n)!r}")
                    values[n] = getattr(defaults, n)
                    self.undeclare_parameter(prefix + n)
                    self.declare_parameter(prefix + n, _ros_default(values[n]), _descriptor(fields[n], values[n]),
                                           ignore_override=True)
        else:
            cfg = defaults
        self._configs[prefix] = (cls, cfg)
        return cfg

    def _refused_by_cross_field_rules(self, cls: type, prefix: str, fields: dict, defaults) -> set[str]:
        """The fields whose start-up override a cross-field rule of ``cls`` refuses (a stand file that does not load,
        ``min_size > max_size``), found before any is declared; each is logged and listed as in
        :meth:`declare_config`. Overrides that fail their own field's check are left to the per-field step."""
        candidates = {}
        for name, f in fields.items():
            override = self._parameter_overrides.get(prefix + name)
            if override is None:
                continue
            default = getattr(defaults, name)
            try:
                value = _from_ros(_coerce_override(override.value, default), default)
                config_module.check_field(f, value, default)
            except (config_module.ConfigError, TypeError, ValueError):
                continue
            candidates[name] = value
        values = {name: getattr(defaults, name) for name in fields} | candidates
        refused: set[str] = set()
        for _ in range(len(fields) + 1):
            try:
                config_module.from_mapping(cls, values)
                break
            except config_module.ConfigError as exc:
                named = [n for n in exc.fields if n in candidates and n not in refused]
                if not named:
                    break
                for n in named:
                    self._refuse_at_start(prefix + n, f"{prefix + n}={values[n]!r} refused: {exc}; keeping the "
                                          f"default {getattr(defaults, n)!r}")
                    values[n] = getattr(defaults, n)
                    refused.add(n)
        return refused

    def _refuse_at_start(self, name: str, reason: str) -> None:
        self.config_errors[name] = reason
        self.get_logger().error(reason)

    def check_unknown_parameters(self) -> None:
        """Warn about (and list in diagnostics) overrides that name no parameter: a typo in a
        parameter file would otherwise be ignored without a word. They do not raise the level: a
        ``/**`` section shared by several nodes legitimately holds other nodes' parameters."""
        for name in sorted(set(self._parameter_overrides) - set(self._parameters)):
            self.unknown_parameters.append(name)
            self.get_logger().warning(f"{name}: no such parameter of {self.get_name()} (ignored; a typo?)")

    def config(self, prefix: str = ""):
        return self._configs[prefix][1]

    def on_config_changed(self, cfg: Any) -> None:
        """Called with a new validated config after parameters of it were set at runtime."""

    def _candidate_configs(self, params: list[Parameter]) -> dict[str, Any]:
        changed: dict[str, dict[str, Any]] = {}
        for p in params:
            for prefix, (cls, current) in self._configs.items():
                field_name = p.name[len(prefix):] if p.name.startswith(prefix) else None
                if field_name and field_name in {f.name for f in dataclasses.fields(cls)}:
                    values = changed.setdefault(prefix, dataclasses.asdict(current))
                    values[field_name] = _from_ros(p.value, getattr(current, field_name))
        return {prefix: config_module.from_mapping(self._configs[prefix][0], values)
                for prefix, values in changed.items()}

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        try:
            self._candidate_configs(params)
        except (config_module.ConfigError, TypeError, ValueError) as exc:
            self.get_logger().warning(f"refused parameter change: {exc}; keeping the previous values")
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        for prefix, cfg in self._candidate_configs(params).items():
            self._configs[prefix] = (self._configs[prefix][0], cfg)
            for p in params:
                self.config_errors.pop(p.name, None)
            with self._process_lock:
                try:
                    self.on_config_changed(cfg)
                except Exception as exc:  # validated, yet the processor failed: say so, keep running
                    self._refuse_at_start(prefix or type(cfg).__name__,
                                          f"applying {type(cfg).__name__} failed: {type(exc).__name__}: {exc}")

    # ------------------------------------------------------------------ processing
    def attach_spec(self, spec) -> MessageProcessor:
        """Declare every config of a ``processing.ProcessorSpec`` and attach the processor it builds:
        the same construction ``run_offline`` uses, so live and offline cannot drift apart."""
        configs = {prefix: self.declare_config(cls, prefix) for prefix, cls in spec.configs.items()}
        processor = self.attach_processor(spec.build(configs))
        self.check_unknown_parameters()  # after the subscriptions: they declare the qos_overrides.* parameters
        return processor

    def attach_processor(self, processor: MessageProcessor) -> MessageProcessor:
        """Subscribe to the processor's inputs and publish its outputs (see module docstring)."""
        self.processor = processor
        if processor.warm_up_error:
            self.get_logger().warning(f"warm-up failed ({processor.warm_up_error}): the first frame loads the "
                                      "compiled kernels instead")
        for level, note in processor.start_up_notes:
            (self.get_logger().warning if level >= logging.WARNING else self.get_logger().info)(note)
        processor.on_rejected = self.reject
        processor.on_event = self.time_jumped
        for topic, type_name in processor.outputs.items():
            self._publishers_by_topic[topic] = self.create_publisher(get_message_class(type_name), topic, OUTPUT_QOS)
        for topic, type_name in processor.inputs.items():
            msg_class = get_message_class(type_name)
            handler = self._make_handler(topic)
            if topic in processor.latest_only:
                self.create_latest_subscription(msg_class, topic, handler)
            else:
                self.create_subscription(msg_class, topic, handler, INPUT_QOS)
        return processor

    def create_latest_subscription(self, msg_class: type, topic: str, callback: Callable[[Any], None],
                                   qos: QoSProfile = qos_profile_sensor_data):
        """Sensor-data QoS; only the newest message is kept and handled off the executor thread.

        The QoS is the standard ROS 2 override point (``qos_overrides.<topic>.subscription.reliability``
        etc., read-only parameters): best effort by default, as a camera driver publishes; ``reliable``
        on a lossy link where a lost UDP fragment must not drop a whole frame."""
        slot = _LatestSlot(callback, self.stats, topic)
        self._slots.append(slot)
        # a copy: rclpy writes the overridden policies into the profile it is given (here a module constant)
        return self.create_subscription(msg_class, topic, slot.offer, copy.copy(qos),
                                        qos_overriding_options=QoSOverridingOptions.with_default_policies())

    def create_image_subscription(self, topic: str, callback: Callable[[Any], None], compressed: bool = False):
        """An image subscription (``sensor_msgs/Image`` or ``CompressedImage``), keep-newest."""
        type_name = "sensor_msgs/msg/CompressedImage" if compressed else "sensor_msgs/msg/Image"
        return self.create_latest_subscription(get_message_class(type_name), topic, callback)

    def _make_handler(self, topic: str) -> Callable[[Any], None]:
        def handle(msg: Any) -> None:
            with self._process_lock:
                outputs = process_guarded(self.processor, topic, msg, self.stats,
                                          now_ns=lambda: self.get_clock().now().nanoseconds,
                                          on_error=self.reject_logged, on_time_jump=self.time_jumped)
            for out_topic, out_msg in outputs:
                publisher = self._publishers_by_topic.get(out_topic)
                if publisher is None:
                    self.get_logger().error(f"processor produced undeclared output topic {out_topic}")
                    continue
                publisher.publish(out_msg)
        return handle

    def reject(self, reason: str) -> None:
        """Count a rejected input and log a throttled warning with the reason."""
        self.stats.reject(reason)
        self.reject_logged(reason)

    def reject_logged(self, reason: str) -> None:
        """Log a rejection, throttled per kind of reason (every kind is seen; each at most every
        ``LOG_EVERY_S`` seconds, with its count so far)."""
        key = reason_key(reason)
        if key not in self.stats.rejected:
            key = OTHER_REASONS if OTHER_REASONS in self.stats.rejected else key
        now = time.monotonic()
        last = self._logged_at.get(key)
        if last is not None and now - last < LOG_EVERY_S:
            return
        if last is None and len(self._logged_at) >= 4 * MAX_REASONS:
            self._logged_at.clear()
        self._logged_at[key] = now
        count = self.stats.rejected.get(key, 0)
        self.get_logger().warning(f"rejected input: {reason}" + (f" ({count} so far)" if count > 1 else ""))

    def time_jumped(self, note: str) -> None:
        """Log a reset of the processor's state (stamp jumps back, or the core's own reset)."""
        self.get_logger().warning(note, throttle_duration_sec=1.0)

    def processed(self, input_stamp_ns: int | None, processing_s: float = 0.0) -> None:
        """Feed rate / latency diagnostics (for nodes that do not use a processor)."""
        age = None
        if input_stamp_ns is not None:
            age = (self.get_clock().now().nanoseconds - input_stamp_ns) / 1e9
        self.stats.record(processing_s, age)

    # ------------------------------------------------------------------ diagnostics
    def diagnostic_status(self) -> DiagnosticStatus:
        summary = self.stats.summary()
        values = {
            "rate_hz": f"{summary['rate_hz']:.2f}",
            "processing_ms_p50": f"{summary['processing_ms_p50']:.2f}",
            "processing_ms_p95": f"{summary['processing_ms_p95']:.2f}",
            "processing_ms_max": f"{summary['processing_ms_max']:.2f}",
            "latency_ms_p50": _latency_text(summary),
            "received": str(self.stats.received),
            "processed": str(self.stats.processed),
            "skipped": str(self.stats.skipped),
            "rejected": str(self.stats.rejected_total),
            "time_jumps": str(self.stats.time_jumps),
        }
        if "main_topic" in summary:                  # the input the processing figures are of (several inputs)
            values["processing_topic"] = summary["main_topic"]
        values.update({k: f"{v:.2f}" for k, v in summary.items() if k.startswith("processing_ms_p50 ")})
        for reason, count in self.stats.rejected.most_common():   # every kind, not just the top few
            values[f"rejected: {reason}"] = str(count)
        for name, why in self.config_errors.items():
            values[f"parameter refused: {name}"] = why
        for name in self.unknown_parameters:
            values[f"parameter unknown: {name}"] = "ignored: no such parameter (a typo?)"
        health = None
        if self.processor is not None:
            values.update({k: str(v) for k, v in self.processor.status().items()})
            try:
                health = self.processor.health()
            except Exception as exc:  # noqa: BLE001 - diagnostics must never fail
                health = (ERROR, f"processor health check failed: {exc}")
        problems: list[tuple[int, str]] = []
        if health is not None and health[0] != OK:
            problems.append(health)
        recent = self.stats.recent_rejections(HOLD_S)
        internal = sum(c for r, c in recent.items() if "internal error" in r)
        if internal:
            problems.append((ERROR, f"internal errors ({internal})"))
        if recent:
            problems.append((WARN, f"inputs rejected in the last {HOLD_S:g} s: " + "; ".join(sorted(recent))[:200]))
        skip = self.stats.skip_fraction()
        if skip > SKIP_WARN_FRACTION:
            problems.append((WARN, f"skipping {100 * skip:.0f}% of frames (processing slower than input)"))
        if self.config_errors:
            problems.append((WARN, f"{len(self.config_errors)} parameter value(s) refused (see values)"))
        status = DiagnosticStatus()
        status.name = f"{self.get_fully_qualified_name()}: processing"
        status.hardware_id = self.get_fully_qualified_name()
        if problems:
            level = max(level for level, _ in problems)
            status.level = {WARN: DiagnosticStatus.WARN, ERROR: DiagnosticStatus.ERROR}[level]
            status.message = "; ".join(m for lv, m in sorted(problems, key=lambda p: -p[0]))
        elif self.stats.received == 0:
            status.level, status.message = DiagnosticStatus.OK, "waiting for input"
        else:
            status.level, status.message = DiagnosticStatus.OK, "ok"
        status.level = bytes([status.level]) if isinstance(status.level, int) else status.level
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        return status

    def publish_diagnostics(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [self.diagnostic_status()]
        self._diagnostics.publish(msg)

    def destroy_node(self) -> None:
        for slot in self._slots:
            slot.stop()
        super().destroy_node()


# ---------------------------------------------------------------------- helpers
def _descriptor(f: dataclasses.Field, default: Any) -> ParameterDescriptor:
    spec = config_module.spec_of(f)
    descriptor = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.choices is not None:
        descriptor.additional_constraints = "one of: " + ", ".join(str(c) for c in spec.choices)
    if isinstance(default, bool):
        return descriptor
    if isinstance(default, float) and (spec.low is not None or spec.high is not None):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low if spec.low is not None else -_DOUBLE_MAX),
            to_value=float(spec.high if spec.high is not None else _DOUBLE_MAX), step=0.0)]
    elif isinstance(default, int) and (spec.low is not None or spec.high is not None):
        descriptor.integer_range = [IntegerRange(
            from_value=int(spec.low if spec.low is not None else -_INT_MAX),
            to_value=int(spec.high if spec.high is not None else _INT_MAX), step=1)]
    return descriptor


def _ros_default(default: Any) -> Any:
    """The value to declare; an empty sequence declares a typed (double array) parameter."""
    if isinstance(default, (list, tuple)):
        if not default:
            return Parameter.Type.DOUBLE_ARRAY
        return list(default)
    return default


def _short(exc: Exception) -> str:
    text = str(exc) or type(exc).__name__
    return text.splitlines()[0][:300]


def _coerce_override(value: Any, default: Any) -> Any:
    """A parameter-file value in the declared type where nothing is lost: ``2`` for a float
    parameter, ``[1, 2, 3, 4]`` for a float list, ``[0.0, 8.0]`` for an integer list. Else unchanged
    (the declaration then refuses it with the type error)."""
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, (list, tuple)) and isinstance(value, (list, tuple, array.array)) and len(value):
        items = list(value)
        if all(isinstance(v, int) and not isinstance(v, bool) for v in items) and \
                not (default and all(isinstance(v, int) for v in default)):
            return [float(v) for v in items]
        if default and all(isinstance(v, int) and not isinstance(v, bool) for v in default) and \
                all(isinstance(v, float) and v.is_integer() for v in items):
            return [int(v) for v in items]
    return value


def _from_ros(value: Any, default: Any) -> Any:
    """A ROS parameter value in the type of the dataclass default."""
    if value is None:
        return default
    if isinstance(default, tuple) and isinstance(value, (list, tuple, array.array)):
        return tuple(value)
    if isinstance(default, list) and isinstance(value, (list, tuple, array.array)):
        return list(value)
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def node_usage(node_class: type, prog: str) -> str:
    """``--help`` text of a node executable: how to pass ROS arguments, what the node does (its
    module's docstring) and every parameter with default, range and description."""
    import importlib  # noqa: PLC0415

    module = importlib.import_module(node_class.__module__)
    lines = [f"usage: {prog} [-h] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] [-r FROM:=TO ...]]", ""]
    if module.__doc__:
        lines += [module.__doc__.strip(), ""]
    spec = getattr(module, "SPEC", None)
    if spec is not None:
        lines.append("parameters (ros2 param set, -p, --params-file):")
        for prefix, cls in spec.configs.items():
            defaults = cls()
            for f in dataclasses.fields(cls):
                p = config_module.spec_of(f)
                limits = (f" one of {list(p.choices)}" if p.choices else
                          f" [{p.low:g} .. {p.high:g}]" if p.low is not None and p.high is not None else "")
                lines.append(f"  {prefix}{f.name} (default {getattr(defaults, f.name)!r}){limits}: {p.description}")
    return "\n".join(lines)


def _check_params_files(ros_args: list[str]) -> str | None:
    """The first problem with a ``--params-file`` among ``ros_args`` (missing, unreadable, not a
    ROS 2 parameter file), said plainly, or None. rcl's own message is a long C trace."""
    for flag, path in zip(ros_args, ros_args[1:]):
        if flag == "--params-file":
            try:
                config_module.load_yaml_parameters(path)
            except config_module.ConfigError as exc:
                return f"--params-file {exc}"
    return None


def run_node(node_class: type, args: list[str] | None = None, **node_kwargs) -> int:
    """Executable entry point: init, spin, shut down cleanly on Ctrl-C/SIGTERM.

    ``-h`` / ``--help`` prints the usage and parameters and returns 0 without starting ROS; a
    missing or broken ``--params-file``, or any other start-up failure, is one clear line on stderr
    and exit status 2 (1 for a failure while running), never a traceback.

    A single-threaded executor: images are processed on the node's own worker thread (keep-newest
    slot), so executor callbacks stay short. rclpy's MultiThreadedExecutor spinning beside that
    worker starved the process (bench/foundation.py: 304 of 650 replayed messages delivered,
    p50 3.2 s late, against 650 of 650 at p95 1.3 ms single-threaded).
    """
    from ..cli import split_ros_args, stopped_by_signal  # noqa: PLC0415

    argv = list(sys.argv if args is None else args)
    prog = (argv[0].rsplit("/", 1)[-1] if argv else "") or node_class.__name__
    own, ros = split_ros_args(argv[1:])
    if "-h" in own or "--help" in own:
        print(node_usage(node_class, prog))
        return 0
    if own:
        print(f"{prog}: ignoring arguments outside --ros-args: {' '.join(own)}", file=sys.stderr)
    problem = _check_params_files(ros)
    if problem:
        print(f"{prog}: {problem}", file=sys.stderr)
        raise SystemExit(2)
    try:
        rclpy.init(args=argv)
    except Exception as exc:  # rcl refused the arguments (bad -p value, unknown option ...)
        print(f"{prog}: cannot start: {_short(exc)}", file=sys.stderr)
        raise SystemExit(2) from None
    node = None
    code = 0
    try:
        node = node_class(**node_kwargs)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as exc:  # noqa: BLE001 - one line for the operator, the trace for a bug report
        if node is not None and stopped_by_signal():
            pass        # Ctrl-C / SIGTERM that raced the executor's wait set: a clean stop
        else:
            print(f"{prog}: {'stopped' if node is not None else 'cannot start'}: {type(exc).__name__}: {exc}",
                  file=sys.stderr)
            if os.environ.get("ADT_TRACEBACK"):
                traceback.print_exc(file=sys.stderr)
            code = 1 if node is not None else 2
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    if code:
        raise SystemExit(code)
    return 0


def _latency_text(summary: dict[str, float]) -> str:
    """The stamp-to-output latency for diagnostics, or why there is none (stamps on another clock)."""
    if "stamp_offset_s" not in summary:
        return f"{summary['latency_ms_p50']:.2f}"
    offset = summary["stamp_offset_s"]
    where = "behind" if offset > 0 else "ahead of"
    return (f"n/a: input stamps {abs(offset):.3g} s {where} this node's clock (a bag replayed without "
            f"use_sim_time, or a camera clock not synchronised)")
