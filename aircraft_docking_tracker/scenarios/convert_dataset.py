"""``convert_dataset``: real sequences -> MCAP bags with ground truth, to replay through the nodes.

    convert_dataset ../shared/data/sot/Car4 --out car4.mcap [--fps 30] [--max-frames 100]
    convert_dataset ../shared/data/mot/TUD-Campus --out tud.mcap        (fps from seqinfo.ini or --fps)
    convert_dataset ../shared/data/detect/drone-view-vehicles --out tiles.mcap --max-frames 50
    convert_dataset ../shared/data --out-dir out/bags                   (every sequence found)

* ``sot`` (OTB / TinyTLP frame folders): ``image`` (bgr8) and ``ground_truth/polygon`` (the box as
  a 4-point polygon TL, TR, BR, BL; empty where the target is lost), stamps at ``--fps``;
* ``mot`` (MOTChallenge ``det.txt`` / ``gt.txt``): ``detections`` (DETECTION_DTYPE) and
  ``ground_truth`` (TRACK_DTYPE: id, box, velocity from the previous frame, ``score`` = the gt
  visibility or 1, ``state`` 1) for every frame 1..N at the sequence's frame rate, no images;
* ``detect`` (tiles with YOLO labels): ``image`` and ``ground_truth`` (DETECTION_DTYPE) per tile.

Time stamps start at ``render.EPOCH_NS``; frame k (0-based) is at k / fps.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from aircraft_docking_tracker.io.bag import BagWriter
from aircraft_docking_tracker.geometry import box_to_quad
from aircraft_docking_tracker.object_table import DETECTION_DTYPE
from aircraft_docking_tracker.scenarios import datasets
from aircraft_docking_tracker.scenarios import messages as m
from aircraft_docking_tracker.scenarios.datasets import DatasetError
from aircraft_docking_tracker.scenarios.render import frame_stamp_ns
from aircraft_docking_tracker.io import motchallenge

DEFAULT_FPS = {"sot": 30.0, "mot": 25.0, "detect": 10.0}


def read_image(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise DatasetError(f"{path}: not a readable image (truncated or not an image file)")
    return image


def convert_sot(folder: Path, out: Path, fps: float, max_frames: int = 0, progress: bool = True,
                overwrite: bool = False) -> dict:
    frames = datasets.list_frames(folder)
    boxes, fmt = datasets.read_sot_boxes(folder / "groundtruth_rect.txt")
    n = min(len(frames), len(boxes))
    if max_frames:
        n = min(n, max_frames)
    quads = box_to_quad(boxes[:n])
    with BagWriter(out, overwrite=overwrite) as bag:
        for k in tqdm(range(n), desc=folder.name, disable=not progress, unit="frame"):
            stamp = frame_stamp_ns(k, fps)
            hdr = m.header(stamp)
            bag.write(m.IMAGE, m.image_msg(read_image(frames[k]), hdr), stamp)
            bag.write(m.GT_POLYGON, m.quad_to_polygon(quads[k], hdr), stamp)
        counts = bag.topic_counts
    return {"kind": "sot", "format": fmt, "frames": n, "images": len(frames), "boxes": len(boxes), "topics": counts}


def convert_mot(folder: Path, out: Path, fps: float | None, max_frames: int = 0, progress: bool = True,
                overwrite: bool = False) -> dict:
    det_path = folder / "det.txt" if (folder / "det.txt").is_file() else folder / "det" / "det.txt"
    gt_path = folder / "gt.txt" if (folder / "gt.txt").is_file() else folder / "gt" / "gt.txt"
    dets = motchallenge.read_detections(det_path) if det_path.is_file() else None
    gts = motchallenge.read_ground_truth(gt_path) if gt_path.is_file() else None
    if dets is None and gts is None:
        raise DatasetError(f"{folder}: neither det.txt nor gt.txt")
    info = motchallenge.read_seqinfo(folder)
    fps = fps or info.get("frameRate") or DEFAULT_FPS["mot"]
    last = max(int(t["frame"].max()) for t in (dets, gts) if t is not None and len(t))
    last = max(last, int(info.get("seqLength", 0)))
    if max_frames:
        last = min(last, max_frames)
    empty = np.zeros(0, motchallenge.MOT_ROW_DTYPE)
    det_frames = motchallenge.frames(dets if dets is not None else empty, 1, last)
    gt_frames = motchallenge.frames(gts if gts is not None else empty, 1, last)
    previous: dict = {}
    with BagWriter(out, overwrite=overwrite) as bag:
        for (frame, d), (_, g) in tqdm(zip(det_frames, gt_frames), total=last, desc=folder.name,
                                       disable=not progress, unit="frame"):
            stamp = frame_stamp_ns(frame - 1, fps)
            hdr = m.header(stamp)
            if dets is not None:
                table = np.zeros(len(d), DETECTION_DTYPE)
                for name in ("x", "y", "w", "h", "score"):
                    table[name] = d[name]
                table["class_id"] = np.maximum(d["cls"], 0)
                bag.write(m.DETECTIONS, m.cloud_msg(table, hdr), stamp)
            if gts is not None:
                bag.write(m.GROUND_TRUTH, m.cloud_msg(datasets.mot_rows_to_tracks(g, previous, fps), hdr), stamp)
        counts = bag.topic_counts
    return {"kind": "mot", "frames": last, "fps": fps, "topics": counts}


def convert_detect(folder: Path, out: Path, fps: float, max_frames: int = 0, progress: bool = True,
                   overwrite: bool = False) -> dict:
    images = datasets.list_frames(folder)
    if max_frames:
        images = images[:max_frames]
    boxes = 0
    with BagWriter(out, overwrite=overwrite) as bag:
        for k, path in enumerate(tqdm(images, desc=folder.name, disable=not progress, unit="tile")):
            image = read_image(path)
            labels = datasets.read_yolo_labels(folder / "labels" / (path.stem + ".txt"), image.shape[1], image.shape[0])
            boxes += len(labels)
            stamp = frame_stamp_ns(k, fps)
            hdr = m.header(stamp)
            bag.write(m.IMAGE, m.image_msg(image, hdr), stamp)
            bag.write(m.GROUND_TRUTH, m.cloud_msg(labels, hdr), stamp)
        counts = bag.topic_counts
    return {"kind": "detect", "frames": len(images), "boxes": boxes, "topics": counts}


CONVERTERS = {"sot": convert_sot, "mot": convert_mot, "detect": convert_detect}


def convert(folder: str | Path, out: str | Path, kind: str = "auto", fps: float | None = None,
            max_frames: int = 0, progress: bool = True, overwrite: bool = False) -> dict:
    """Convert one dataset folder into a bag at ``out``; returns a summary."""
    folder, out = Path(folder), Path(out)
    kind = datasets.dataset_kind(folder) if kind == "auto" else kind
    if kind not in CONVERTERS:
        raise DatasetError(f"unknown dataset kind {kind!r}")
    if kind == "mot":
        return convert_mot(folder, out, fps, max_frames, progress, overwrite)
    return CONVERTERS[kind](folder, out, fps or DEFAULT_FPS[kind], max_frames, progress, overwrite)


def find_sequences(root: Path) -> list[tuple[str, Path]]:
    """Every ``(kind, folder)`` under a data root laid out as ``sot/*``, ``mot/*``, ``detect/*``."""
    found = []
    for kind in ("sot", "mot", "detect"):
        if (root / kind).is_dir():
            found += [(kind, p) for p in sorted((root / kind).iterdir()) if p.is_dir()]
    return found


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="convert_dataset", description=__doc__.split("\n")[0])
    parser.add_argument("source", help="a dataset folder, or a data root holding sot/ mot/ detect/")
    parser.add_argument("--out", help="output .mcap (one folder)")
    parser.add_argument("--out-dir", help="output folder (data root: one <kind>_<name>.mcap per sequence)")
    parser.add_argument("--kind", default="auto", choices=["auto", *CONVERTERS])
    parser.add_argument("--fps", type=float, default=None,
                        help="frame rate for the stamps (default: seqinfo.ini, else sot 30, mot 25, detect 10)")
    parser.add_argument("--max-frames", type=int, default=0, help="convert only the first N frames (0: all)")
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    source = Path(args.source)
    try:
        if args.out_dir:
            jobs = find_sequences(source) or [(datasets.dataset_kind(source), source)]
            jobs = [(kind, folder, Path(args.out_dir) / f"{kind}_{folder.name}.mcap") for kind, folder in jobs]
        elif args.out:
            jobs = [(args.kind, source, Path(args.out))]
        else:
            parser.error("give --out FILE.mcap or --out-dir DIR")
        for kind, folder, out in jobs:
            summary = convert(folder, out, kind, args.fps, args.max_frames, not args.quiet, args.overwrite)
            topics = ", ".join(f"{k}: {v}" for k, v in sorted(summary["topics"].items()))
            print(f"{folder} -> {out} ({summary['kind']}, {summary['frames']} frames; {topics})")
    except (DatasetError, ValueError) as exc:
        print(f"convert_dataset: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
