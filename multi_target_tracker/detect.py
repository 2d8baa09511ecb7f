"""``detect``: the detector core over an image folder, a video or a bag (offline tool).

    detect ../shared/data/detect/drone-view-vehicles/images -o boxes.txt
    detect video1.avi --backend opencv --model ../shared/data/cascades/cars.xml -o cars.txt --bag out.mcap
    detect scene.mcap -o boxes.txt --bag out.mcap

Writes one text line per detection, ``<frame> <x> <y> <w> <h> <score> <class_id>`` (frame = the image
file name, the video frame index or the bag stamp in ns; x, y top-left in pixels), and with
``--bag`` an output bag holding ``image`` (bag input: the input's other topics too) and
``detections`` (PointCloud2 DETECTION_DTYPE) with the image's header. Parameters come from
``config/detector.yaml`` (or ``--params-file``) overridden by the options below; it is the same
:class:`multi_target_tracker.detector.Detector` as the node's.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from aircraft_docking_tracker.io.bag import check_outputs
from aircraft_docking_tracker.cli import AtomicFile
from aircraft_docking_tracker.config import ConfigError, add_config_arguments, config_from_arguments, tool_parameters
from multi_target_tracker.detector import Detector, DetectorConfig
from multi_target_tracker.detector_node import NODE_NAME
from multi_target_tracker.train_cascade import IMAGE_SUFFIXES

VIDEO_SUFFIXES = (".avi", ".mp4", ".mkv", ".mov", ".m4v", ".webm")


def frames(source: str | Path) -> Iterator[tuple[str, np.ndarray, int]]:
    """``(frame name, BGR image, stamp ns)`` from a folder of images, a video file or a bag."""
    source = Path(source)
    if source.is_dir() and not (source / "metadata.yaml").is_file():
        for k, path in enumerate(sorted(p for p in source.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)):
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                print(f"detect: cannot read {path}; skipped", file=sys.stderr)
                continue
            yield path.name, image, int(k * 1e8)
    elif source.suffix.lower() in VIDEO_SUFFIXES:
        cap = cv2.VideoCapture(str(source))
        if not cap.isOpened():
            raise ValueError(f"cannot open video {source}")
        fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
        k = 0
        while True:
            ok, image = cap.read()
            if not ok:
                break
            yield str(k), image, int(k * 1e9 / fps)
            k += 1
    elif source.is_file() and source.suffix.lower() in IMAGE_SUFFIXES:
        image = cv2.imread(str(source), cv2.IMREAD_COLOR)
        if image is None:
            raise ValueError(f"cannot read image {source}")
        yield source.name, image, 0
    else:
        from aircraft_docking_tracker.io.bag import BagReader, stamp_to_ns  # noqa: PLC0415
        from aircraft_docking_tracker.images import to_bgr8  # noqa: PLC0415

        reader = BagReader(source)
        if reader.problem:
            print(f"detect: warning: {reader.problem}", file=sys.stderr)
        known = reader.error
        topic = next((t for t in reader.topics if t.lstrip("/") == "image"), "image")
        for item in reader.messages([topic]):
            try:  # a frame that does not decode is skipped, as an unreadable file in a folder
                msg = item.deserialize()
                image = to_bgr8(msg)
            except ValueError as exc:
                print(f"detect: frame at {item.log_time_ns} ns: {exc}; skipped", file=sys.stderr)
                continue
            stamp = stamp_to_ns(msg.header.stamp)
            yield str(stamp), image, stamp
        if reader.error != known:
            print(f"detect: warning: {reader.problem}", file=sys.stderr)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="detect", description=__doc__.split("\n\n")[0])
    p.add_argument("input", help="image folder, image, video file, or bag (.mcap / rosbag2 folder)")
    p.add_argument("-o", "--output", default="-", help="text file of detections ('-': stdout)")
    p.add_argument("--bag", default=None, help="also write an output bag with image and detections")
    p.add_argument("--params-file", default=None, help="ROS 2 parameter file (default config/detector.yaml)")
    p.add_argument("--frame-id", default="camera", help="frame_id of images read from folders or videos")
    p.add_argument("--no-progress", action="store_true")
    add_config_arguments(p, DetectorConfig)
    return p


def run(args) -> dict:
    base = tool_parameters(args.params_file, "detector.yaml", NODE_NAME)
    config = config_from_arguments(DetectorConfig, args, base={k: v for k, v in base.items() if "." not in k})
    detector = Detector(config)
    source = Path(args.input)
    is_bag = not (source.is_dir() and not (source / "metadata.yaml").is_file()) and \
        source.suffix.lower() not in VIDEO_SUFFIXES + IMAGE_SUFFIXES
    inputs = [source]
    if source.is_dir():
        inputs += [p for p in source.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES + (".mcap", ".yaml")]
    check_outputs([args.output, args.bag], inputs, "detect")
    # both outputs appear only when the run completes: an error leaves no partial file behind
    out = sys.stdout if args.output == "-" else AtomicFile(args.output)
    writer = None
    if args.bag:
        from aircraft_docking_tracker.io.bag import BagWriter  # noqa: PLC0415
        writer = BagWriter(args.bag, overwrite=True, atomic=True)
    from tqdm import tqdm  # noqa: PLC0415

    n_frames = n_dets = 0
    seconds = 0.0
    completed = False
    try:
        for name, image, stamp in tqdm(frames(args.input), unit="frame", disable=args.no_progress or out is sys.stdout):
            started = time.perf_counter()
            table = detector.detect(image)
            seconds += time.perf_counter() - started
            n_frames += 1
            n_dets += len(table)
            for row in table:
                out.write(f"{name} {row['x']:.1f} {row['y']:.1f} {row['w']:.1f} {row['h']:.1f} "
                          f"{row['score']:.4f} {int(row['class_id'])}\n")
            if writer is not None:
                _write_frame(writer, image, table, stamp, args.frame_id, write_image=not is_bag)
        if writer is not None and is_bag:
            _copy_bag(args.input, writer)
        completed = True
    finally:
        if out is not sys.stdout:
            out.close() if completed else out.abort()
        if writer is not None:
            writer.close() if completed else writer.abort()
    return {"frames": n_frames, "detections": n_dets, "fps": n_frames / seconds if seconds else 0.0}


def _write_frame(writer, image: np.ndarray, table: np.ndarray, stamp: int, frame_id: str, write_image: bool) -> None:
    from std_msgs.msg import Header  # noqa: PLC0415

    from aircraft_docking_tracker.io.bag import ns_to_stamp  # noqa: PLC0415
    from aircraft_docking_tracker.images import numpy_to_image  # noqa: PLC0415
    from aircraft_docking_tracker.object_table import table_to_cloud  # noqa: PLC0415

    header = Header(stamp=ns_to_stamp(stamp), frame_id=frame_id)
    if write_image:
        writer.write("image", numpy_to_image(image, "bgr8", header), stamp)
    writer.write("detections", table_to_cloud(table, header), stamp)


def _copy_bag(source: str, writer) -> None:
    """Every message of the input bag except its old detections (ours replace them)."""
    from aircraft_docking_tracker.io.bag import BagReader  # noqa: PLC0415

    reader = BagReader(source)
    for info in reader.topics.values():  # recorded schemas: types not installed here are copied too
        if info.name.lstrip("/") != "detections" and info.name not in writer.topic_counts:
            writer.add_topic_like(info)
    for item in reader.messages():
        if item.topic.lstrip("/") != "detections":
            writer.write_serialized(item.topic, item.type_name, item.data, item.log_time_ns, item.publish_time_ns)


def main(args=None) -> int:
    parsed = build_parser().parse_args(args)
    try:
        summary = run(parsed)
    except (ConfigError, ValueError, OSError) as exc:
        print(f"detect: {exc}", file=sys.stderr)
        return 2
    print(f"detect: {summary['frames']} frames, {summary['detections']} detections, "
          f"{summary['fps']:.1f} frames/s (detector only)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
