"""Foundation benchmark: recorder throughput (MB/s) and replay timing error (p50/p95 ms).

Side by side in one run:
* recording 640x480 bgr8 images live over DDS with mcap_record's Recorder, against writing the
  same serialised messages straight to a file with our BagWriter and with rosbags' writer (the
  independent implementation): MB/s of payload and the share of published frames recorded;
* replaying a 30 Hz image + 100 Hz table bag with mcap_play's Player: |actual - intended| time of
  each message at a live subscriber, p50 / p95 / max in ms, at rate 1 and rate 2.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image, PointCloud2

from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp
from aircraft_docking_tracker.images import numpy_to_image
from aircraft_docking_tracker.io.mcap_play import Player, PlayOptions
from aircraft_docking_tracker.io.mcap_record import Recorder
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, table_to_cloud

RESULTS = Path(__file__).resolve().parent / "results"
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def frames(n: int, width=640, height=480):
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    for i in range(n):
        msg = numpy_to_image(np.roll(base, i, axis=1), "bgr8")
        msg.header.stamp, msg.header.frame_id = ns_to_stamp(i * 33_333_333), "camera"
        yield msg


def bench_offline_writers(tmp: Path, n: int) -> dict:
    data = [serialize_message(m) for m in frames(n)]
    payload = sum(map(len, data))
    out = {}
    started = time.perf_counter()
    with BagWriter(tmp / "ours.mcap") as writer:
        for i, d in enumerate(data):
            writer.write_serialized("/image", "sensor_msgs/msg/Image", d, i * 33_333_333)
    out["BagWriter (no DDS)"] = payload / 1e6 / (time.perf_counter() - started)
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.ROS2_JAZZY)
        started = time.perf_counter()
        writer = Writer(tmp / "rosbags", version=9, storage_plugin=StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            conn = writer.add_connection("/image", "sensor_msgs/msg/Image", typestore=store)
            for i, d in enumerate(data):
                writer.write(conn, i * 33_333_333, d)
        out["rosbags Writer, zstd (no DDS)"] = payload / 1e6 / (time.perf_counter() - started)
    except ImportError:
        pass
    return out


def bench_live_recording(tmp: Path, rate_hz: float, seconds: float) -> dict:
    """Publish 640x480 frames at ``rate_hz`` to a Recorder in the same process; MB/s and share kept."""
    rclpy.init()
    executor = SingleThreadedExecutor()
    talker, rec_node = rclpy.create_node("bench_talker"), rclpy.create_node("bench_recorder")
    executor.add_node(rec_node)
    writer = BagWriter(tmp / f"live_{rate_hz:g}.mcap")
    recorder = Recorder(rec_node, writer, topics=["/image"])
    pub = talker.create_publisher(Image, "/image", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    deadline = time.monotonic() + 10
    while not recorder.subscriptions and time.monotonic() < deadline:
        recorder.discover()
        time.sleep(0.05)
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    n = int(rate_hz * seconds)
    msgs = list(frames(n))
    started = time.perf_counter()
    for i, msg in enumerate(msgs):
        delay = started + i / rate_hz - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        pub.publish(msg)
    time.sleep(0.5)  # let the last messages arrive
    recorded, payload = writer.message_count, writer.bytes_written
    writer.close()
    executor.shutdown()
    talker.destroy_node()
    rec_node.destroy_node()
    rclpy.shutdown()
    return {"rate_hz": rate_hz, "published": n, "recorded": recorded,
            "mb_s": payload / 1e6 / seconds, "offered_mb_s": n * len(msgs[0].data) / 1e6 / seconds}


def make_replay_bag(path: Path, seconds: float) -> None:
    with BagWriter(path) as writer:
        n_img = int(seconds * 30)
        for i, msg in enumerate(frames(n_img, 320, 240)):
            t = 1_000_000_000 + i * 33_333_333
            msg.header.stamp = ns_to_stamp(t)
            writer.write("/image", msg, t)
        for j in range(int(seconds * 100)):
            t = 1_000_000_000 + j * 10_000_000
            header = Image().header
            header.stamp = ns_to_stamp(t)
            writer.write("/detections", table_to_cloud(np.zeros(3, DETECTION_DTYPE), header), t)


def bench_replay(path: Path, rate: float) -> dict:
    rclpy.init()
    executor = SingleThreadedExecutor()
    listener, player_node = rclpy.create_node("bench_listener"), rclpy.create_node("bench_player")
    executor.add_node(listener)
    arrivals = []
    for topic, cls in (("/image", Image), ("/detections", PointCloud2)):
        listener.create_subscription(cls, topic, lambda m: arrivals.append((time.monotonic(), m.header.stamp)),
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    reader = BagReader(path)
    player = Player(player_node, reader, PlayOptions(rate=rate, wait_for_subscribers_s=10.0))
    player.wait_for_subscribers(10.0)
    started = time.monotonic()
    player.options.wait_for_subscribers_s = 0.0
    player.run()
    time.sleep(0.3)
    executor.shutdown()
    listener.destroy_node()
    player_node.destroy_node()
    rclpy.shutdown()
    # intended arrival = start + (stamp - bag start) / rate; the stamps equal the log times here
    errors = np.array([abs((t - started) - ((s.sec * 1e9 + s.nanosec) - reader.start_ns) / 1e9 / rate) * 1e3
                       for t, s in arrivals])
    return {"rate": rate, "messages": len(arrivals), "expected": reader.message_count,
            "p50_ms": float(np.percentile(errors, 50)), "p95_ms": float(np.percentile(errors, 95)),
            "max_ms": float(errors.max()),
            "publish_call_p50_ms": float(np.percentile(np.abs(player.report.timing_errors_ns), 50) / 1e6)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    n = 150 if args.quick else 600
    seconds = 5.0 if args.quick else 20.0
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        writers = bench_offline_writers(tmp, n)
        live = [bench_live_recording(tmp, hz, 2.0 if args.quick else 5.0) for hz in (30.0, 60.0, 120.0)]
        make_replay_bag(tmp / "replay.mcap", seconds)
        replays = [bench_replay(tmp / "replay.mcap", rate) for rate in (1.0, 2.0)]
    results = {"frames": n, "frame_bytes": 640 * 480 * 3, "writers_mb_s": writers, "live": live, "replay": replays}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "foundation.json").write_text(json.dumps(results, indent=2))
    lines = ["## Foundation: recording and replay", "",
             f"Writing {n} serialised 640x480 bgr8 frames to a file, no DDS (payload MB/s, ratio to ours):", "",
             "| writer | MB/s | ratio |", "|---|---|---|"]
    base = writers["BagWriter (no DDS)"]
    for name, value in writers.items():
        lines.append(f"| {name} | {value:.0f} | {value / base:.2f} |")
    lines += ["", "Live recording with mcap_record's Recorder over DDS (publisher in the same process):", "",
              "| frames/s offered | MB/s offered | MB/s recorded | frames kept |", "|---|---|---|---|"]
    for r in live:
        lines.append(f"| {r['rate_hz']:g} | {r['offered_mb_s']:.0f} | {r['mb_s']:.0f} | {r['recorded']}/{r['published']} |")
    lines += ["",
              "Replay timing error at a live subscriber (|arrival - intended|), 30 Hz images + 100 Hz tables:", "",
              "| rate | messages | p50 ms | p95 ms | max ms |", "|---|---|---|---|---|"]
    for r in replays:
        lines.append(f"| {r['rate']:g}x | {r['messages']}/{r['expected']} | {r['p50_ms']:.2f} | {r['p95_ms']:.2f} | {r['max_ms']:.2f} |")
    (RESULTS / "foundation.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
