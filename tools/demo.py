"""`make demo` (provisional until the pipeline lands): record a sample bag live, replay it, show it.

Publishes synthetic frames and detection tables live over ROS 2, records them with mcap_record's
Recorder, replays the file with mcap_play's Player and reports what arrived.
"""
from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image

from aircraft_docking_tracker.bag import BagReader, BagWriter, ns_to_stamp
from aircraft_docking_tracker.images import numpy_to_image
from aircraft_docking_tracker.mcap_play import Player, PlayOptions
from aircraft_docking_tracker.mcap_record import Recorder

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="out/demo")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    bag = out / "sample.mcap"
    if bag.exists():
        bag.unlink()
    rclpy.init()
    executor = MultiThreadedExecutor(num_threads=2)
    talker, recorder_node = rclpy.create_node("demo_camera"), rclpy.create_node("demo_recorder")
    executor.add_node(recorder_node)
    threading.Thread(target=executor.spin, daemon=True).start()
    writer = BagWriter(bag)
    recorder = Recorder(recorder_node, writer, topics=["/image"])
    pub = talker.create_publisher(Image, "/image", RELIABLE)
    while not recorder.subscriptions:
        recorder.discover()
        time.sleep(0.05)
    while pub.get_subscription_count() == 0:
        time.sleep(0.05)
    for i in range(60):
        frame = np.zeros((240, 320, 3), np.uint8)
        frame[100:140, 5 * i:5 * i + 40] = (40, 200, 255)
        msg = numpy_to_image(frame, "bgr8")
        msg.header.stamp, msg.header.frame_id = ns_to_stamp(talker.get_clock().now().nanoseconds), "camera"
        pub.publish(msg)
        time.sleep(1 / 30)
    time.sleep(0.3)
    writer.close()
    reader = BagReader(bag)
    got = []
    recorder_node.create_subscription(Image, "/replayed", got.append, RELIABLE)
    Player(talker, reader, PlayOptions(remap={"/image": "/replayed"}, wait_for_subscribers_s=5.0)).run()
    time.sleep(0.3)
    executor.shutdown()
    rclpy.shutdown()
    print(reader.describe())
    print(f"demo: recorded {reader.message_count} frames live, replayed {len(got)}; bag at {bag}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
