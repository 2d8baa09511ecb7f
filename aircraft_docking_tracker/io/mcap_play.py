"""``mcap_play``: publish a bag's messages on live topics with their original timing.

    mcap_play run1/                         # a bag directory or a .mcap file
    mcap_play x.mcap --rate 2 --loop --topics image --remap image:=/cam0/image --clock

Messages go out undeserialised, in log-time order, spaced as recorded (divided by ``--rate``).
Each topic is published with the QoS recorded in the file (reliable only if every recorded
publisher was, transient-local likewise), or reliable depth 10 where none was recorded.
``--clock`` publishes ``/clock`` with the bag's time so nodes can run with ``use_sim_time``.
A split bag (a rosbag2 directory of several ``.mcap`` files) plays as one. A missing, non-MCAP or
non-ROS file is a clear error; a truncated file (a recording killed hard) plays up to its last
complete chunk and a damaged chunk is skipped, each with a warning: ``mcap_record --recover IN
OUT`` rewrites such a file whole for indexed readers (``ros2 bag``, rosbags).
"""
from __future__ import annotations

import argparse
import sys
import threading
import time
from dataclasses import dataclass, field

from ..cli import split_ros_args
from .bag import BagError, BagReader, get_message_class, ns_to_stamp


@dataclass
class PlayOptions:
    rate: float = 1.0
    loop: bool = False
    start_offset_s: float = 0.0
    duration_s: float | None = None
    topics: list[str] | None = None
    exclude: list[str] = field(default_factory=list)
    remap: dict[str, str] = field(default_factory=dict)
    clock_hz: float = 0.0  # 0: no /clock
    wait_for_subscribers_s: float = 0.0
    min_subscribers: int = 1  # with wait_for_subscribers_s: this many matched subscriptions on every topic
    delay_s: float = 0.0  # after the wait: lets every subscriber finish matching (DDS discovery)


@dataclass
class PlayReport:
    published: int = 0
    loops: int = 0
    timing_errors_ns: list[int] = field(default_factory=list)  # actual - intended publish time
    skipped_topics: dict[str, str] = field(default_factory=dict)


class Player:
    """Publishes a bag through ``node``; :meth:`run` blocks until done or :meth:`stop`."""

    def __init__(self, node, reader: BagReader, options: PlayOptions | None = None):
        from rclpy.qos import QoSProfile  # noqa: PLC0415

        self.node = node
        self.reader = reader
        self.options = options or PlayOptions()
        if self.options.rate <= 0:
            raise ValueError("--rate must be positive")
        self.report = PlayReport()
        self._stop = threading.Event()
        self.publishers = {}
        for name, info in reader.topics.items():
            if self.options.topics is not None and name not in self.options.topics:
                continue
            if name in self.options.exclude:
                continue
            try:
                msg_class = get_message_class(info.type_name)
            except BagError as exc:
                self.report.skipped_topics[name] = str(exc)
                node.get_logger().warning(f"not playing {name}: {exc}")
                continue
            qos = info.qos or QoSProfile(depth=10)
            self.publishers[name] = node.create_publisher(msg_class, self.options.remap.get(name, name), qos)
        self.clock_publisher = None
        if self.options.clock_hz > 0:
            from rclpy.qos import QoSProfile as Q  # noqa: PLC0415
            from rosgraph_msgs.msg import Clock  # noqa: PLC0415

            self.clock_publisher = node.create_publisher(Clock, "/clock", Q(depth=1))

    def stop(self) -> None:
        self._stop.set()

    def _publish_clock(self, bag_ns: int) -> None:
        from rosgraph_msgs.msg import Clock  # noqa: PLC0415

        self.clock_publisher.publish(Clock(clock=ns_to_stamp(bag_ns)))

    def wait_for_subscribers(self, timeout_s: float, minimum: int = 1) -> bool:
        """Wait until every topic has ``minimum`` matched subscriptions; False (and a warning) on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not self._stop.is_set():
            if all(p.get_subscription_count() >= minimum for p in self.publishers.values()):
                return True
            time.sleep(0.02)
        short = {p.topic_name: p.get_subscription_count() for p in self.publishers.values()
                 if p.get_subscription_count() < minimum}
        if short and not self._stop.is_set():
            self.node.get_logger().warning(
                f"playing after {timeout_s:g} s without {minimum} subscriber(s) on {short}: early messages may be lost")
        return False

    def _sleep_until(self, target: float, bag_ns_at) -> None:
        """Sleep to ``target`` (monotonic s), publishing /clock at its rate meanwhile."""
        clock_period = 1.0 / self.options.clock_hz if self.clock_publisher else 0.05
        while not self._stop.is_set():
            remaining = target - time.monotonic()
            if remaining <= 0:
                return
            time.sleep(min(remaining, clock_period))
            if self.clock_publisher:
                self._publish_clock(bag_ns_at(time.monotonic()))

    def run(self) -> PlayReport:
        if self.options.wait_for_subscribers_s > 0:
            self.wait_for_subscribers(self.options.wait_for_subscribers_s, self.options.min_subscribers)
        if self.options.delay_s > 0:
            self._stop.wait(self.options.delay_s)
        self.node.get_logger().info(f"playing {len(self.publishers)} topic(s)")   # scripts wait for this line
        begin = self.reader.start_ns + int(self.options.start_offset_s * 1e9)
        end = begin + int(self.options.duration_s * 1e9) if self.options.duration_s else None
        topics = list(self.publishers)
        while not self._stop.is_set():
            wall_start = time.monotonic()
            rate = self.options.rate

            def bag_ns_at(now: float) -> int:
                return begin + int((now - wall_start) * rate * 1e9)

            # from the bag's very start unless asked otherwise: a damaged summary's start time is no filter
            first = begin if self.options.start_offset_s > 0 else None
            for item in self.reader.messages(topics=topics, start_ns=first, end_ns=end):
                if self._stop.is_set():
                    break
                target = wall_start + (item.log_time_ns - begin) / 1e9 / rate
                self._sleep_until(target, bag_ns_at)
                if self._stop.is_set():
                    break
                if self.clock_publisher:
                    self._publish_clock(item.log_time_ns)
                self.publishers[item.topic].publish(item.data)
                self.report.timing_errors_ns.append(int((time.monotonic() - target) * 1e9))
                self.report.published += 1
            self.report.loops += 1
            if not self.options.loop:
                break
        return self.report


LINGER_S = 1.0  # after the last message, before the node goes away


def _parse_remaps(pairs: list[str]) -> dict[str, str]:
    out = {}
    for pair in pairs:
        if ":=" not in pair:
            raise argparse.ArgumentTypeError(f"remap {pair!r} is not OLD:=NEW")
        old, new = pair.split(":=", 1)
        out[old] = new
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mcap_play", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", help="a .mcap file or a rosbag2 directory")
    parser.add_argument("-r", "--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    parser.add_argument("-l", "--loop", action="store_true", help="start again at the end, until Ctrl-C")
    parser.add_argument("--start", type=float, default=0.0, help="seconds into the bag to start at")
    parser.add_argument("--duration", type=float, default=None, help="seconds of the bag to play")
    parser.add_argument("--topics", nargs="+", default=None, help="play only these topics (names as in the bag)")
    parser.add_argument("--exclude", nargs="+", default=[], help="do not play these topics")
    parser.add_argument("--remap", nargs="+", default=[], metavar="OLD:=NEW", help="publish topic OLD as NEW")
    parser.add_argument("--clock", type=float, nargs="?", const=100.0, default=0.0, metavar="HZ",
                        help="publish /clock (default 100 Hz when given) for nodes with use_sim_time")
    parser.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                        help="wait up to S seconds for a subscriber on every topic before starting")
    parser.add_argument("--min-subscribers", type=int, default=1, metavar="N",
                        help="with --wait-for-subscribers: wait for N matched subscribers on every topic "
                             "(e.g. every node and the recorder), as ros2 topic pub --wait-matching-subscriptions")
    parser.add_argument("--delay", type=float, default=0.0, metavar="S",
                        help="then wait S seconds more: a subscriber that has just appeared may not have matched "
                             "the player yet, and a volatile topic's first messages would miss it")
    return parser


def main(args: list[str] | None = None) -> int:
    import rclpy  # noqa: PLC0415

    argv = sys.argv[1:] if args is None else list(args)
    own_args, ros_args = split_ros_args(argv)
    parser = build_parser()
    ns = parser.parse_args(own_args)
    try:
        remap = _parse_remaps(ns.remap)
        reader = BagReader(ns.bag)
    except (BagError, argparse.ArgumentTypeError) as exc:
        print(f"mcap_play: {exc}", file=sys.stderr)
        return 2
    if reader.problem:
        print(f"mcap_play: warning: {reader.problem}", file=sys.stderr)
    known = reader.error
    options = PlayOptions(rate=ns.rate, loop=ns.loop, start_offset_s=ns.start, duration_s=ns.duration,
                          topics=ns.topics, exclude=ns.exclude, remap=remap, clock_hz=ns.clock,
                          wait_for_subscribers_s=ns.wait_for_subscribers, min_subscribers=ns.min_subscribers,
                          delay_s=ns.delay)
    rclpy.init(args=["mcap_play", *ros_args])
    node = rclpy.create_node("mcap_play")
    try:
        player = Player(node, reader, options)
    except ValueError as exc:
        print(f"mcap_play: {exc}", file=sys.stderr)
        return 2
    print(reader.describe())
    thread = threading.Thread(target=player.run, daemon=True)
    thread.start()
    try:
        while thread.is_alive() and rclpy.ok():
            thread.join(timeout=0.1)
        # played to the end: give the last messages time to leave (large ones go out in fragments
        # from a sending thread; destroying the node at once lost the last image over UDP)
        if not thread.is_alive() and rclpy.ok():
            time.sleep(LINGER_S)
    except KeyboardInterrupt:
        pass
    finally:
        player.stop()
        thread.join(timeout=2.0)
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    errors = sorted(abs(e) for e in player.report.timing_errors_ns)
    p50 = errors[len(errors) // 2] / 1e6 if errors else 0.0
    print(f"mcap_play: published {player.report.published} messages in {player.report.loops} pass(es); "
          f"timing error p50 {p50:.2f} ms")
    if reader.error != known:  # damaged chunks are found while reading
        print(f"mcap_play: warning: {reader.problem}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
