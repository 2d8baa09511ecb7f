"""``mcap_record``: record live topics, undeserialised, into a rosbag2-compatible MCAP file.

    mcap_record -a -o run1                 # every topic, bag directory run1/ (metadata.yaml + mcap)
    mcap_record image detections -o x.mcap # two topics, one file

Topics appear while it runs are picked up (discovery every ``--discovery-interval`` s). The
subscription QoS adapts to the publishers, as ``ros2 bag record`` does: reliable only if every
publisher is reliable, transient-local only if every one is. Log time is the receive time on the
node's clock (``use_sim_time`` honoured), publish time the publisher's source timestamp. With
``use_sim_time``, discovery and flushing run on the steady clock, so topics are subscribed at once
rather than after the first ``/clock``; messages that arrive before it are held (up to
``--max-pending``) and written with the first ``/clock`` time. ``--max-bag-size`` and
``--max-bag-duration`` split a directory recording into ``<name>_0.mcap, <name>_1.mcap, ...`` as
``ros2 bag record`` does, with ``metadata.yaml`` listing them. Messages that never arrived (a lossy
link, a host cut off) are counted from the publisher's sequence numbers, on topics with one
publisher, logged and summed up at the end ("missed"). Ctrl-C or SIGTERM finish the file
properly; after a hard kill, the file holds everything up to the last chunk flushed (every
``--flush-interval`` s) but has no index: indexed readers (``ros2 bag``, rosbags, Foxglove) refuse
it until ``mcap_record --recover IN OUT`` rewrites it (``mcap_play`` and our tools read it as is,
with a warning).
"""
from __future__ import annotations

import argparse
import datetime
import re
import sys
import threading
import time

from ..cli import split_ros_args, stopped_by_signal
from .bag import BagError, BagWriter, get_message_class, qos_to_dict, recover

MAX_PENDING = 10_000  # messages held while a use_sim_time recorder waits for its first /clock


class Recorder:
    """Raw subscriptions on ``node`` for the selected topics, written to ``writer``."""

    def __init__(self, node, writer: BagWriter, topics: list[str] | None = None,
                 exclude: str | None = None, include_hidden: bool = False, max_pending: int = MAX_PENDING):
        self.node = node
        self.writer = writer
        self.topics = {self._absolute(t) for t in topics} if topics else None
        self.exclude = re.compile(exclude) if exclude else None
        self.include_hidden = include_hidden
        self.subscriptions: dict[str, object] = {}
        self.unknown_types: set[str] = set()
        self.errors = 0
        self._lock = threading.Lock()
        # use_sim_time: the node's clock reads 0 until the first /clock; hold messages until then
        self.sim_time = bool(node.get_parameter("use_sim_time").value) if node.has_parameter("use_sim_time") else False
        self.max_pending = max_pending
        self.pending: list[tuple[str, str, bytes, int | None]] = []
        self.dropped = 0
        # sequence gaps: messages the publisher sent that never arrived (topics with one publisher)
        self.missed: dict[str, int] = {}
        self.gaps: dict[str, int] = {}
        self._last_sequence: dict[str, int] = {}
        self._single_publisher: set[str] = set()

    def _absolute(self, topic: str) -> str:
        from rclpy.validate_full_topic_name import validate_full_topic_name  # noqa: PLC0415

        name = self.node.resolve_topic_name(topic)
        validate_full_topic_name(name)
        return name

    def wanted(self, topic: str) -> bool:
        if self.topics is not None:
            return topic in self.topics
        if self.exclude is not None and self.exclude.search(topic):
            return False
        return self.include_hidden or not any(part.startswith("_") for part in topic.split("/"))

    def discover(self) -> None:
        """Subscribe to every wanted topic that has publishers and no subscription yet."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.subscriptions:  # with several publishers, sequence numbers interleave
                if self.node.count_publishers(topic) == 1:
                    self._single_publisher.add(topic)
                else:
                    self._single_publisher.discard(topic)
                    self._last_sequence.pop(topic, None)
            if topic in self.subscriptions or not self.wanted(topic) or not types:
                continue
            type_name = types[0]
            try:
                msg_class = get_message_class(type_name)
            except BagError:
                if type_name not in self.unknown_types:
                    self.unknown_types.add(type_name)
                    self.node.get_logger().warning(f"cannot record {topic}: type {type_name} is not installed")
                continue
            infos = self.node.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            qos = self._adapted_qos(infos)
            offered = [qos_to_dict(info.qos_profile) for info in infos]
            self.writer.add_topic(topic, type_name, offered)
            self.subscriptions[topic] = self.node.create_subscription(
                msg_class, topic, self._callback(topic, type_name), qos, raw=True)
            self.node.get_logger().info(f"recording {topic} [{type_name}]")

    @staticmethod
    def _adapted_qos(infos):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: PLC0415

        reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
        transient = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        return QoSProfile(depth=100,
                          reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)

    def _callback(self, topic: str, type_name: str):
        clock = self.node.get_clock()

        def on_message(data: bytes, info) -> None:
            receive_ns = clock.now().nanoseconds
            source_ns = info.get("source_timestamp") if isinstance(info, dict) else None
            if isinstance(info, dict) and topic in self._single_publisher:
                self._count_gap(topic, info.get("publication_sequence_number"))
            if receive_ns == 0 and self.sim_time:
                self._hold(topic, type_name, data, source_ns)
                return
            if self.pending:
                self.release_pending(receive_ns)
            self._write(topic, type_name, data, receive_ns, source_ns or receive_ns)
        return on_message

    def _write(self, topic: str, type_name: str, data: bytes, log_ns: int, publish_ns: int) -> None:
        try:
            self.writer.write_serialized(topic, type_name, data, log_ns, publish_ns)
        except Exception as exc:  # a full disk must not kill the node: count and say so
            with self._lock:
                self.errors += 1
            self.node.get_logger().error(f"write failed on {topic}: {exc}", throttle_duration_sec=5.0)

    def _hold(self, topic: str, type_name: str, data: bytes, source_ns: int | None) -> None:
        with self._lock:
            if len(self.pending) >= self.max_pending:
                self.pending.pop(0)
                self.dropped += 1
            self.pending.append((topic, type_name, bytes(data), source_ns))
        if len(self.pending) == 1:
            self.node.get_logger().info("use_sim_time: holding messages until the first /clock")

    def release_pending(self, log_ns: int | None = None) -> None:
        """Write the messages held before the first /clock, stamped with ``log_ns`` (default: the
        clock now, if it runs). Called by the first message after /clock, a timer, and at the end."""
        if log_ns is None:
            log_ns = self.node.get_clock().now().nanoseconds
            if log_ns == 0 and self.sim_time:
                return
        with self._lock:
            held, self.pending = self.pending, []
        for topic, type_name, data, source_ns in held:
            self._write(topic, type_name, data, log_ns, source_ns or log_ns)
        if self.dropped:
            self.node.get_logger().warning(f"use_sim_time: no /clock for a while, {self.dropped} early messages "
                                           f"beyond --max-pending were dropped")

    def start(self, discovery_interval: float = 0.5, flush_interval: float = 1.0) -> None:
        """Discover now and every ``discovery_interval`` s, flush every ``flush_interval`` s: on the
        steady clock, so that a ``use_sim_time`` recorder does not wait for /clock to subscribe."""
        from rclpy.clock import Clock, ClockType  # noqa: PLC0415

        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.timers = [self.node.create_timer(discovery_interval, self.discover, clock=steady),
                       self.node.create_timer(max(flush_interval, 0.1), self.writer.flush, clock=steady)]
        if self.sim_time:
            self.timers.append(self.node.create_timer(0.1, self.release_pending, clock=steady))
        self.discover()


    def _count_gap(self, topic: str, sequence: int | None) -> None:
        if not sequence:  # 0 or None: the middleware does not number messages
            return
        last = self._last_sequence.get(topic)
        self._last_sequence[topic] = sequence
        if last is None or sequence <= last:  # the first one, or a restarted publisher numbering anew
            return
        missed = sequence - last - 1
        if missed > 0:
            with self._lock:
                self.missed[topic] = self.missed.get(topic, 0) + missed
                self.gaps[topic] = self.gaps.get(topic, 0) + 1
            self.node.get_logger().warning(f"{topic}: {missed} messages missed (sequence {last} -> {sequence}); "
                                           f"{self.missed[topic]} in {self.gaps[topic]} gaps so far")


def default_output_name() -> str:
    return datetime.datetime.now().strftime("rosbag2_%Y_%m_%d-%H_%M_%S")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mcap_record", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("topics", nargs="*", help="topics to record (relative names resolve in the node's namespace)")
    parser.add_argument("-a", "--all", action="store_true", help="record every topic (default when none is named)")
    parser.add_argument("-o", "--output", default=None,
                        help="output: NAME.mcap for one file, anything else for a rosbag2 directory "
                             "(default rosbag2_<date>)")
    parser.add_argument("-e", "--exclude", default=None, help="regular expression of topics not to record (with -a)")
    parser.add_argument("--include-hidden-topics", action="store_true", help="also record topics with a part starting with _")
    parser.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd")
    parser.add_argument("--chunk-size", type=int, default=1 << 20, help="chunk size in bytes (default 1 MiB)")
    parser.add_argument("--flush-interval", type=float, default=1.0,
                        help="close a chunk at least this often (seconds): what a hard kill can lose")
    parser.add_argument("--discovery-interval", type=float, default=0.5, help="seconds between topic discoveries")
    parser.add_argument("--max-duration", type=float, default=0.0, help="stop after this many seconds (0: until Ctrl-C)")
    parser.add_argument("-b", "--max-bag-size", type=int, default=0, metavar="BYTES",
                        help="directory output: start a new .mcap file when the open one reaches this size (0: never)")
    parser.add_argument("-d", "--max-bag-duration", type=float, default=0.0, metavar="S",
                        help="directory output: start a new .mcap file every S seconds of recording (0: never)")
    parser.add_argument("--max-pending", type=int, default=MAX_PENDING,
                        help="use_sim_time: messages held until the first /clock (older ones are dropped, counted)")
    parser.add_argument("--recover", nargs=2, metavar=("IN", "OUT"),
                        help="repair a recording that was killed: rewrite IN's readable messages into OUT and exit")
    return parser


def main(args: list[str] | None = None) -> int:
    import rclpy  # noqa: PLC0415
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor  # noqa: PLC0415

    argv = sys.argv[1:] if args is None else list(args)
    own_args, ros_args = split_ros_args(argv)
    options = build_parser().parse_args(own_args)
    if options.recover:
        try:
            count = recover(*options.recover)
        except BagError as exc:
            print(f"mcap_record: {exc}", file=sys.stderr)
            return 2
        print(f"recovered {count} messages into {options.recover[1]}")
        return 0

    output = options.output or default_output_name()
    try:
        writer = BagWriter(output, compression=options.compression, chunk_size=options.chunk_size,
                           max_bytes=options.max_bag_size, max_duration_ns=int(options.max_bag_duration * 1e9))
    except BagError as exc:
        print(f"mcap_record: {exc}", file=sys.stderr)
        return 2
    rclpy.init(args=["mcap_record", *ros_args])
    node = rclpy.create_node("mcap_record")
    recorder = Recorder(node, writer, options.topics or None, options.exclude, options.include_hidden_topics,
                        max_pending=options.max_pending)
    # discovery at once and then periodically; a chunk closed every flush interval (what a hard kill loses)
    recorder.start(options.discovery_interval, options.flush_interval)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    started = time.monotonic()
    print(f"mcap_record: writing {output} ({'all topics' if not options.topics else ', '.join(options.topics)}); Ctrl-C to stop")
    try:
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
            if options.max_duration and time.monotonic() - started >= options.max_duration:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not stopped_by_signal():     # else Ctrl-C / SIGTERM that raced the executor's wait set: the asked stop
            raise
    finally:
        # held messages, if any: the clock's time now (0 if /clock never came, as the node saw it)
        recorder.release_pending(node.get_clock().now().nanoseconds)
        writer.close()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    files = f" in {len(writer.files)} files" if len(writer.files) > 1 else ""
    print(f"mcap_record: wrote {writer.message_count} messages, {writer.bytes_written / 1e6:.2f} MB of payload, "
          f"to {output}{files}")
    for topic, count in sorted(writer.topic_counts.items()):
        missed = recorder.missed.get(topic, 0)
        print(f"  {topic}: {count}" + (f" ({missed} missed in {recorder.gaps[topic]} gaps)" if missed else ""))
    return 1 if recorder.errors else 0


if __name__ == "__main__":
    sys.exit(main())
