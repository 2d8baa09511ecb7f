"""Message processors: the one code path from input messages to output messages.

A node's whole behaviour, minus DDS, lives in a :class:`MessageProcessor`: it converts input
messages, calls the algorithm core and builds output messages. The live node
(``node_base.PerceptionNode.attach_processor``) and the offline runner (``offline.py``) both feed
it through :func:`process_guarded`, so a bag replayed offline gives the same outputs as the live
node, and bad input is handled the same way in both: a counted, reasoned rejection, never a crash.
This module imports message types only, never ``rclpy.node``.
"""
from __future__ import annotations

import collections
import logging
import re
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable

from ..io.bag import stamp_to_ns
from ..config import param
from ..images import MAX_PIXELS

LOG = logging.getLogger(__name__)


@dataclass
class ImageLimit:
    """The bound on the work one image may cost; a node's config inherits it (``node.max_image_pixels``)."""

    max_image_pixels: int = param(MAX_PIXELS, "refuse (count, log) images of more pixels than this; a compressed "
                                  "image's size is read from its header before decoding", low=1, high=400000000)


@dataclass
class DetectionsLimit:
    """The bound on the rows one detections message may bring (``node.max_detections``); see :func:`best_rows`."""

    max_detections: int = param(1000, "keep the best this many rows of a detections message (the rest are "
                                "dropped and counted)", low=1, high=1000000)


class Rejected(ValueError):
    """Raised by a processor to refuse one input message; the text is the reason."""


class MessageProcessor:
    """Base class: declare topics, implement :meth:`process`.

    ``inputs`` / ``outputs`` map relative topic names to type names (``sensor_msgs/msg/Image``).
    Topics in ``latest_only`` (images) are delivered keep-newest with sensor-data QoS: under
    overload the node skips stale frames and counts them; other inputs are processed in order.
    """

    inputs: dict[str, str] = {}
    outputs: dict[str, str] = {}
    latest_only: frozenset[str] = frozenset()
    #: Set by whoever runs the processor (live node, offline runner) to count a partial rejection,
    #: e.g. invalid rows dropped from a message that is otherwise processed.
    on_rejected: Callable[[str], None] | None = None
    #: Set likewise to log a notable event that is not a rejection (e.g. the tracks were reset).
    on_event: Callable[[str], None] | None = None

    #: Why :meth:`warm_up` failed ("" when it ran or there is nothing to warm up); the live node logs it.
    warm_up_error: str = ""
    #: What the user should read once at start-up, as (logging level, text); the live node logs it.
    start_up_notes: tuple[tuple[int, str], ...] = ()

    def warm_up(self) -> None:
        """Run :meth:`warm_up_work` before the node subscribes: compiled kernels load (or compile, on a fresh
        checkout: seconds) now, not on the camera's first frame, which a live node would otherwise spend while
        the frames behind it are skipped. A failure is kept in ``warm_up_error``, the processor still works."""
        self.warm_up_error = ""
        try:
            self.warm_up_work()
        except Exception as exc:  # noqa: BLE001 - kept for the node's log; each real frame reports its own error
            self.warm_up_error = f"{type(exc).__name__}: {exc}"

    def warm_up_work(self) -> None:
        """A throwaway input through the processor's cores (override); nothing by default."""

    def report_rejection(self, reason: str) -> None:
        if self.on_rejected is not None:
            self.on_rejected(reason)

    def report_event(self, text: str) -> None:
        if self.on_event is not None:
            self.on_event(text)

    def process(self, topic: str, msg: Any) -> list[tuple[str, Any]]:
        """Handle one input message; return ``(output topic, message)`` pairs to publish."""
        raise NotImplementedError

    def reset(self) -> None:
        """Forget all state (called when input time jumps backwards, e.g. a looped bag)."""

    def status(self) -> dict[str, str]:
        """Extra key/values for the diagnostics status (e.g. number of tracks)."""
        return {}

    def health(self) -> tuple[int, str] | None:
        """``(level, message)`` when the processor cannot do its job (level ``ERROR``, e.g. no model)
        or does it poorly (``WARN``); None when fine. Shown as the node's diagnostics level."""
        return None


#: Diagnostic levels (the values of diagnostic_msgs/DiagnosticStatus, without importing it here).
OK, WARN, ERROR = 0, 1, 2
#: Distinct rejection reasons counted one by one; any further kinds add to one "other" counter.
MAX_REASONS = 64
OTHER_REASONS = "other reasons (more than 64 kinds)"


MAX_LATENCY_S = 60.0    # a median stamp age above this is another clock, not a latency
MAX_CLOCK_SKEW_S = 1.0  # stamps this far ahead of the node's clock: another clock too


@dataclass
class ProcessingStats:
    """Counters behind ``/diagnostics``: rates, latency, skipped and rejected inputs.

    Every rejection reason is counted under its kind (numbers folded, at most ``MAX_REASONS``
    kinds) with the time it was last seen, so diagnostics can show every reason and tell recent
    trouble (WARN) from old (back to OK).
    """

    window_s: float = 5.0
    received: int = 0
    processed: int = 0
    skipped: int = 0
    time_jumps: int = 0
    rejected: collections.Counter = field(default_factory=collections.Counter)
    last_rejected: dict = field(default_factory=dict)    # reason kind -> time.monotonic() last seen
    _events: collections.deque = field(default_factory=lambda: collections.deque(maxlen=2000))
    _received_at: collections.deque = field(default_factory=lambda: collections.deque(maxlen=2000))
    _skipped_at: collections.deque = field(default_factory=lambda: collections.deque(maxlen=2000))
    _last_stamp: dict[str, int] = field(default_factory=dict)

    def record(self, processing_s: float, age_s: float | None, topic: str = "") -> None:
        self.processed += 1
        self._events.append((time.monotonic(), processing_s, age_s, topic))

    def receive(self) -> None:
        self.received += 1
        self._received_at.append(time.monotonic())

    def skip(self) -> None:
        """A frame replaced by a newer one before it was processed (keep-newest under overload)."""
        self.skipped += 1
        self._skipped_at.append(time.monotonic())

    def reject(self, reason: str) -> str:
        """Count a rejection under its kind (numbers folded, see ``reason_key``); return the kind."""
        key = reason_key(reason)
        if key not in self.rejected and len(self.rejected) >= MAX_REASONS:
            key = OTHER_REASONS
        self.rejected[key] += 1
        self.last_rejected[key] = time.monotonic()
        return key

    def recent_rejections(self, within_s: float) -> dict[str, int]:
        """Reason kinds seen in the last ``within_s`` seconds, with their total counts."""
        now = time.monotonic()
        return {k: self.rejected[k] for k, t in self.last_rejected.items() if now - t <= within_s}

    def skip_fraction(self) -> float:
        """Of the frames that arrived in the last ``window_s`` seconds, the fraction skipped."""
        now = time.monotonic()
        skipped = sum(1 for t in self._skipped_at if now - t <= self.window_s)
        taken = sum(1 for t in self._received_at if now - t <= self.window_s)
        return skipped / (skipped + taken) if skipped + taken else 0.0

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    def summary(self) -> dict[str, float]:
        """Rate (Hz) over the last ``window_s`` seconds; processing time and stamp latency (ms)
        percentiles over the last 2000 processed messages. A median stamp age beyond
        ``MAX_LATENCY_S`` (or stamps more than ``MAX_CLOCK_SKEW_S`` ahead) is not a latency: a bag
        replayed without ``use_sim_time``, or a camera on another clock; the latency is then NaN and
        ``stamp_offset_s`` says how far behind the node's clock the stamps are.

        A node with several inputs (the docking tracker: images, and the detector's tables that it only
        keeps) is measured on the one its work is for, the input with the largest total processing time
        (``main_topic``): over all of them the median fell between the two kinds of message and flipped
        between 0.2 and 12 ms with one frame more or less. Every input's own median is
        ``processing_ms_p50 <topic>``."""
        now = time.monotonic()
        out = {"rate_hz": 0.0, "processing_ms_p50": 0.0, "processing_ms_p95": 0.0, "processing_ms_max": 0.0,
               "latency_ms_p50": 0.0}
        by_topic: dict[str, list] = collections.defaultdict(list)
        for event in self._events:
            by_topic[event[3]].append(event)
        if len(by_topic) > 1:
            for topic, events in sorted(by_topic.items()):
                out[f"processing_ms_p50 {topic}"] = _processing_ms(events)[len(events) // 2]
        main = max(by_topic, key=lambda t: sum(e[1] for e in by_topic[t]), default="")
        events = by_topic.get(main, [])
        recent = [e for e in events if now - e[0] <= self.window_s]
        if len(recent) >= 2:
            out["rate_hz"] = (len(recent) - 1) / max(recent[-1][0] - recent[0][0], 1e-3)
        if events:
            out["main_topic"] = main
            proc = _processing_ms(events)
            out["processing_ms_p50"] = proc[len(proc) // 2]
            out["processing_ms_p95"] = proc[min(len(proc) - 1, int(0.95 * len(proc)))]
            out["processing_ms_max"] = proc[-1]
            ages = sorted(e[2] for e in events if e[2] is not None)
            if ages:
                median = ages[len(ages) // 2]
                if -MAX_CLOCK_SKEW_S <= median <= MAX_LATENCY_S:
                    out["latency_ms_p50"] = max(0.0, median) * 1e3
                else:  # the stamps are not on the node's clock: no latency to report, say how far off they are
                    out["latency_ms_p50"] = float("nan")
                    out["stamp_offset_s"] = median
        return out


def message_stamp_ns(msg: Any) -> int | None:
    header = getattr(msg, "header", None)
    return stamp_to_ns(header.stamp) if header is not None else None


def process_guarded(processor: MessageProcessor, topic: str, msg: Any, stats: ProcessingStats,
                    now_ns: Callable[[], int] | None = None,
                    on_error: Callable[[str], None] | None = None,
                    on_time_jump: Callable[[str], None] | None = None) -> list[tuple[str, Any]]:
    """Run ``processor.process`` with the rules every node shares.

    * a stamp older than the last one on the same topic (a looped bag, a restarted player) is a
      time jump: counted, reported to ``on_time_jump``, the processor is reset (a failing reset is
      an internal error, never an exception out of here), and the message is processed afresh;
    * ``ValueError`` (``Rejected``, ``ImageConversionError``, ...) rejects the message with its
      reason; any other exception is an internal error, logged with its traceback and counted;
    * processing time and stamp-to-output latency (with ``now_ns``, the node's clock) are recorded.
    """
    stats.receive()

    def refuse(reason: str, bug: bool = False) -> list:
        stats.reject(reason)
        if bug:
            LOG.error("%s\n%s", reason, traceback.format_exc())
        if on_error:
            on_error(reason)
        return []

    try:
        stamp = message_stamp_ns(msg)
    except (AttributeError, TypeError, ValueError, OverflowError) as exc:
        return refuse(f"{topic}: bad header stamp ({exc})")
    if stamp is not None:
        last = stats._last_stamp.get(topic)
        if last is not None and stamp < last:
            stats.time_jumps += 1
            stats._last_stamp.clear()
            if on_time_jump:
                on_time_jump(f"{topic}: stamp went back by {(last - stamp) / 1e9:.3f} s (a looped or restarted "
                             f"source); state reset, processing starts afresh")
            try:
                processor.reset()
            except Exception as exc:  # a reset must not take the node down either
                return refuse(f"{topic}: internal error on reset {type(exc).__name__}: {exc}", bug=True)
        stats._last_stamp[topic] = stamp
    started = time.perf_counter()
    try:
        outputs = processor.process(topic, msg)
    except ValueError as exc:
        return refuse(f"{topic}: {exc}")
    except Exception as exc:  # a bug must not take the node or the recording down
        return refuse(f"{topic}: internal error {type(exc).__name__}: {exc}", bug=True)
    age = None
    if stamp is not None and now_ns is not None:
        age = (now_ns() - stamp) / 1e9  # signed: ProcessingStats.summary tells latency from a foreign clock
    stats.record(time.perf_counter() - started, age, topic)
    return outputs


def _processing_ms(events) -> list[float]:
    """The processing times [ms] of ``ProcessingStats`` events, sorted (for their percentiles)."""
    return sorted(e[1] * 1e3 for e in events)


_NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def reason_key(reason: str, limit: int = 120) -> str:
    """Reasons are counted by kind: numbers become ``#`` so that a camera sending frames truncated
    to varying lengths adds to one counter, not one key per length (memory stays bounded)."""
    key = _NUMBER.sub("#", reason)
    return key if len(key) <= limit else key[:limit] + "..."


def best_rows(table, limit: int, report: Callable[[str], None] | None = None, what: str = "rows"):
    """At most ``limit`` rows of an object table, the highest ``score`` first kept (in their
    original order); the cut is reported as a counted reason. Bounds the work per message."""
    if len(table) <= limit:
        return table
    import numpy as np  # noqa: PLC0415

    scores = np.nan_to_num(np.asarray(table["score"], np.float64), nan=-np.inf)
    keep = np.sort(np.argsort(-scores, kind="stable")[:limit])
    if report is not None:
        report(f"{what}: {len(table)} rows, more than the limit of {limit}; the best {limit} kept")
    return table[keep]


@dataclass(frozen=True)
class ProcessorSpec:
    """How to build a node's processor: what the live node and the offline runner both use.

    ``configs`` maps a parameter prefix ("" or e.g. "kalman.") to a config dataclass; ``build``
    takes the validated configs by prefix and returns the processor. The node declares each config
    as ROS parameters; the offline runner reads them from the same ``config/*.yaml`` section
    (``node_name``).
    """

    node_name: str
    configs: dict[str, type]
    build: Callable[[dict[str, Any]], MessageProcessor]

    def configs_from_parameters(self, parameters: dict[str, Any]) -> dict[str, Any]:
        """Validated configs from a flat parameter dict (``load_yaml_parameters`` output)."""
        from ..config import from_mapping  # noqa: PLC0415

        out = {}
        for prefix, cls in self.configs.items():
            names = {f for f in cls.__dataclass_fields__}
            values = {k[len(prefix):]: v for k, v in parameters.items()
                      if k.startswith(prefix) and k[len(prefix):] in names}
            out[prefix] = from_mapping(cls, values)
        return out
