"""``train_cascade``: train the seed 003 boosted cascade from labelled images (offline tool).

Positives: boxes from YOLO folders (``images/`` + ``labels/*.txt``, ``class cx cy w h``
normalised), Pascal VOC folders (``*.xml`` next to or under ``Annotations/``) or ground-truth bags
(``image`` + ``ground_truth`` / ``ground_truth/polygon`` topics). Each box is cut with the one-pixel
rim the features need and goes through the very same :class:`features.LevelScan` as detection.
Negatives: every window of the training images whose IoU with each box is below
``--negative-iou``, plus whole negative images; from stage 2 on only the windows the cascade so
far accepts (bootstrapping). Writes a JSON model (no pickle).

Example (the shipped drone-view vehicle model)::

    train_cascade --yolo ../shared/data/detect/drone-view-vehicles --exclude-prefix 1_ 4_ \\
        --window 64 32 --rotate90 --flips hv --output multi_target_tracker/models/drone_vehicles_fused.json
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np

from aircraft_docking_tracker.config import add_config_arguments, config_from_arguments
from aircraft_docking_tracker.geometry import box_iou
from multi_target_tracker.cascade import Cascade, CascadeTrainConfig, train_cascade
from multi_target_tracker.detector import map_back, scan_cascade, turned_view, window_scales
from multi_target_tracker.features import FUSED_DIM, LBP_SIZE, FeatureConfig, LevelScan

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")


class TrainingDataError(ValueError):
    """Labelled data that cannot be read or holds no usable box."""


@dataclass
class LabelledImage:
    """One training image: a loader (grey uint8) and its boxes (n, 4) x, y, w, h in pixels."""

    name: str
    load: Callable[[], np.ndarray]
    boxes: np.ndarray
    ignore: np.ndarray | None = None   # boxes neither used as positives nor cut as negatives
    path: Path | None = None           # the image file, for an image folder's items (None: from a bag)
    size: tuple[int, int] | None = None  # (width, height), when the reader has it (a YOLO folder's items)

    def load_colour(self) -> np.ndarray:
        """The image in colour (BGR uint8), as a camera gives it (the colour blobs' views read colour)."""
        image = cv2.imread(str(self.path), cv2.IMREAD_COLOR) if self.path is not None else None
        if image is None:
            raise TrainingDataError(f"{self.name}: no colour image file to read ({self.path})")
        return image

    def all_boxes(self) -> np.ndarray:
        return self.boxes if self.ignore is None or not len(self.ignore) else np.vstack([self.boxes, self.ignore])


def _prefix_ok(name: str, include: list[str] | None, exclude: list[str] | None) -> bool:
    if include and not any(name.startswith(p) for p in include):
        return False
    return not (exclude and any(name.startswith(p) for p in exclude))


def _imread_gray(path: Path) -> Callable[[], np.ndarray]:
    def load() -> np.ndarray:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise TrainingDataError(f"cannot read image {path}")
        return image
    return load


def read_yolo_folder(folder: str | Path, include: list[str] | None = None, exclude: list[str] | None = None,
                     classes: list[int] | None = None, ignore_classes: list[int] | None = None) -> list[LabelledImage]:
    """A YOLO folder (``images/`` and ``labels/`` side by side); file-name prefix filters for splits.

    Rows whose class is in ``ignore_classes`` (e.g. a vehicle mostly hidden under trees) are *ignored*:
    neither positives nor cut as negatives; other rows outside ``classes`` are dropped."""
    folder = Path(folder)
    if not folder.is_dir():
        raise TrainingDataError(f"YOLO folder {folder} not found")
    images_dir = folder / "images" if (folder / "images").is_dir() else folder
    labels_dir = folder / "labels" if (folder / "labels").is_dir() else folder
    out = []
    for image_path in sorted(p for p in images_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES):
        if not _prefix_ok(image_path.name, include, exclude):
            continue
        label = labels_dir / (image_path.stem + ".txt")
        rows, ignored = [], []
        if label.is_file():
            for line in label.read_text().splitlines():
                parts = line.split()
                if len(parts) < 5:
                    continue
                cls = int(float(parts[0]))
                if ignore_classes and cls in ignore_classes:
                    ignored.append([float(v) for v in parts[1:5]])
                elif classes is None or cls in classes:
                    rows.append([float(v) for v in parts[1:5]])
        size = _image_size(image_path)
        boxes, ignore = (_yolo_boxes(r, size) for r in (rows, ignored))
        out.append(LabelledImage(image_path.name, _imread_gray(image_path), boxes, ignore if len(ignore) else None,
                                 image_path, size))
    if not out:
        raise TrainingDataError(f"no images in {images_dir} (after prefix filters)")
    return out


def _yolo_boxes(rows: list, size: tuple[int, int]) -> np.ndarray:
    """Normalised YOLO ``cx cy w h`` rows -> (n, 4) x, y, w, h in pixels of an image of ``size`` (w, h)."""
    if not rows:
        return np.zeros((0, 4))
    r = np.asarray(rows)
    w, h = r[:, 2] * size[0], r[:, 3] * size[1]
    return np.column_stack([r[:, 0] * size[0] - w / 2, r[:, 1] * size[1] - h / 2, w, h])


def _image_size(path: Path) -> tuple[int, int]:
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise TrainingDataError(f"cannot read image {path}")
    return image.shape[1], image.shape[0]


def read_voc_folder(folder: str | Path, include: list[str] | None = None, exclude: list[str] | None = None,
                    names: list[str] | None = None) -> list[LabelledImage]:
    """Pascal VOC: ``*.xml`` annotations (``Annotations/`` or the folder) and images beside them."""
    folder = Path(folder)
    ann_dir = folder / "Annotations" if (folder / "Annotations").is_dir() else folder
    img_dirs = [folder / "JPEGImages", folder / "images", folder, ann_dir]
    out = []
    for xml_path in sorted(ann_dir.glob("*.xml")):
        root = ET.parse(xml_path).getroot()
        filename = root.findtext("filename") or xml_path.stem + ".jpg"
        if not _prefix_ok(filename, include, exclude):
            continue
        image_path = next((d / filename for d in img_dirs if (d / filename).is_file()), None)
        if image_path is None:
            continue
        rows = []
        for obj in root.iter("object"):
            if names and obj.findtext("name") not in names:
                continue
            bb = obj.find("bndbox")
            x0, y0, x1, y1 = (float(bb.findtext(k)) for k in ("xmin", "ymin", "xmax", "ymax"))
            rows.append([x0, y0, x1 - x0, y1 - y0])
        out.append(LabelledImage(filename, _imread_gray(image_path), np.asarray(rows).reshape(-1, 4), path=image_path))
    if not out:
        raise TrainingDataError(f"no VOC annotations with images in {folder}")
    return out


def read_bag(path: str | Path, every: int = 1, min_score: float = 0.0) -> list[LabelledImage]:
    """Frames of a ground-truth bag: ``image`` and ``ground_truth`` (table) or ``ground_truth/polygon``.

    Table rows with a ``state`` other than 1 (e.g. a hidden vehicle) or a ``score`` below ``min_score``
    (e.g. the visible fraction) are *ignored*: not positives, and no negative is cut over them.
    """
    from aircraft_docking_tracker.io.bag import BagReader, stamp_to_ns  # noqa: PLC0415
    from aircraft_docking_tracker.images import to_mono8  # noqa: PLC0415
    from aircraft_docking_tracker.object_table import cloud_to_table  # noqa: PLC0415

    images, truth, ignored = {}, {}, {}
    reader = BagReader(path)
    for topic, msg, _ in reader.ros_messages(["image", "ground_truth", "ground_truth/polygon"]):
        stamp = stamp_to_ns(msg.header.stamp)
        if topic == "image":
            images[stamp] = to_mono8(msg)
        elif topic == "ground_truth":
            t = cloud_to_table(msg)
            boxes = np.column_stack([t["x"], t["y"], t["w"], t["h"]]).astype(float).reshape(-1, 4)
            good = np.ones(len(t), bool)
            if "state" in t.dtype.names:
                good &= t["state"] == 1
            if "score" in t.dtype.names:
                good &= t["score"] >= min_score
            truth[stamp], ignored[stamp] = boxes[good], boxes[~good]
        else:
            pts = np.array([[p.x, p.y] for p in msg.polygon.points]).reshape(-1, 2)
            if len(pts):
                lo, hi = pts.min(axis=0), pts.max(axis=0)
                truth[stamp] = np.array([[lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]]])
    out = []
    for k, stamp in enumerate(sorted(set(images) & set(truth))):
        if k % every == 0:
            image = images[stamp]
            out.append(LabelledImage(f"{Path(path).name}@{stamp}", lambda image=image: image, truth[stamp],
                                     ignored.get(stamp)))
    if not out:
        raise TrainingDataError(f"{path}: no frame has both 'image' and ground truth")
    return out


def truncated(boxes: np.ndarray, size: tuple[int, int], margin: float = 1.5) -> np.ndarray:
    """Boxes touching the frame border (cut by it): True per box.

    Closer than ``margin`` px to a border: labelling tools clip boxes to 1 px inside the image (the
    drone-view tiles: 611 boxes end 1.0-1.25 px from the tile border, as many as end on or beyond it, and
    56 % of both are squat halves of vehicles; only 30 boxes end 1.25-3 px from it)."""
    w, h = size
    b = np.asarray(boxes, float).reshape(-1, 4)
    return (b[:, 0] < margin) | (b[:, 1] < margin) | (b[:, 0] + b[:, 2] > w - margin) | (b[:, 1] + b[:, 3] > h - margin)


def positive_vector(gray: np.ndarray, box, feature_set: str, edge_threshold: float,
                    augment: Callable[[np.ndarray], np.ndarray] | None = None, angle: float = 0.0) -> np.ndarray | None:
    """The floored 1152-d vector of one box: the box plus its rim resized to one 34x34 level window
    (``augment(crop)`` first changes the cut pixels, e.g. :func:`photometric`; ``angle`` [deg] turns
    the image about the box centre first, with the real surroundings, as a vehicle turning in a nadir view)."""
    x, y, w, h = (float(v) for v in box)
    rx, ry = w / LBP_SIZE, h / LBP_SIZE        # one texture-level pixel in frame pixels
    x0, y0 = int(math.floor(x - rx)), int(math.floor(y - ry))
    x1, y1 = int(math.ceil(x + w + rx)), int(math.ceil(y + h + ry))
    if x0 < 0 or y0 < 0 or x1 > gray.shape[1] or y1 > gray.shape[0] or w < 4 or h < 4:
        return None
    if angle:
        turn = cv2.getRotationMatrix2D((x + w / 2, y + h / 2), float(angle), 1.0)
        turn[:, 2] -= (x0, y0)    # output pixel (0, 0) is frame pixel (x0, y0)
        crop = cv2.warpAffine(gray, turn, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    else:
        crop = gray[y0:y1, x0:x1]
    crop = crop if augment is None else augment(crop)
    scan = LevelScan(crop, (LBP_SIZE + 2, LBP_SIZE + 2), 2, feature_set, edge_threshold)
    return scan.vectors(np.zeros(1, int))[0]


def photometric(rng: np.random.Generator, strength: float) -> Callable[[np.ndarray], np.ndarray]:
    """A random grey-level change of a crop, as other videos show the same objects: contrast gain in
    ``[1 - s/2, 1 + s/2]``, brightness offset up to ``40 s`` grey levels, and with probability 1/2 a
    Gaussian blur of sigma up to ``1.2 s`` pixels (another camera's focus, compression, altitude)."""
    def augment(crop: np.ndarray) -> np.ndarray:
        out = crop.astype(np.float32)
        if rng.random() < 0.5:
            out = cv2.GaussianBlur(out, (0, 0), max(0.3, rng.uniform(0, 1.2 * strength)))
        gain = 1 + rng.uniform(-strength / 2, strength / 2)
        mean = float(out.mean())
        out = (out - mean) * gain + mean + rng.uniform(-40, 40) * strength
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)
    return augment


FLIPS = {"none": [], "h": [1], "v": [0], "hv": [1, 0, -1]}


def positive_vectors(data: list[LabelledImage], window: tuple[int, int], feature_set: str, edge_threshold: float,
                     rotate90: bool, flips: str, keep_truncated: bool = False, max_positives: int = 0,
                     rng: np.random.Generator | None = None, jitter: int = 0,
                     jitter_shift: float = 0.0625, jitter_scale: float = 1.1,
                     positive_aspect: str = "box", photometric_strength: float = 0.0,
                     turn_jitter: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Vectors of every usable box (turned to the window's orientation when ``rotate90``) and its flips,
    and the window-orientation heights of the boxes used.

    ``jitter`` extra copies per view are shifted by up to ``jitter_shift`` of the box size and scaled
    by up to ``jitter_scale``: the scan meets objects only on its stride grid and scale steps.
    ``positive_aspect`` "window" reshapes every box to the window's shape (same centre and area)
    before cutting it: the scan only ever shows the cascade windows of that shape, so boxes of
    other shapes (e.g. vehicles at any heading) would teach it views it never meets.
    ``photometric_strength`` > 0 also changes the grey levels of every jittered copy (:func:`photometric`).
    ``turn_jitter`` > 0 also turns every jittered copy by up to that many degrees about its centre (headings
    between the 90-degree views: vehicles turning or parked at an angle, a camera not aligned with the street;
    up to 45 fills every heading) and cuts the turned box's upright bounding box, as the labels box such vehicles.
    """
    rng = rng or np.random.default_rng(0)
    augment = photometric(rng, photometric_strength) if photometric_strength > 0 else None
    wide = window[0] >= window[1]
    out, heights = [], []
    for item in data:
        gray = item.load()
        size = (gray.shape[1], gray.shape[0])
        for box, cut in zip(item.boxes, truncated(item.boxes, size)):
            if cut and not keep_truncated:
                continue
            views = [(gray, box)]
            if rotate90 and (box[2] >= box[3]) != wide:
                views = [(np.ascontiguousarray(gray.T), box[[1, 0, 3, 2]])]
            g, b = views[0]
            if positive_aspect == "window":
                b = window_shaped(b, window)
                views = [(g, b)]
            heights.append(b[3])
            views += [(cv2.flip(g, code), _flip_box(b, code, g.shape)) for code in FLIPS[flips]]
            for g, b in views:
                jittered = [b]
                for _ in range(jitter):
                    scale = jitter_scale ** rng.uniform(-1, 1)
                    w, h = b[2] * scale, b[3] * scale
                    dx, dy = rng.uniform(-jitter_shift, jitter_shift, 2) * (b[2], b[3])
                    jittered.append(np.array([b[0] + (b[2] - w) / 2 + dx, b[1] + (b[3] - h) / 2 + dy, w, h]))
                for j, bj in enumerate(jittered):
                    angle = rng.uniform(-turn_jitter, turn_jitter) if j and turn_jitter > 0 else 0.0
                    if angle:    # the turned vehicle's upright bounding box, as a labeller boxes it
                        bj = turned_box(bj, angle)
                        bj = window_shaped(bj, window) if positive_aspect == "window" else bj
                    v = positive_vector(g, bj, feature_set, edge_threshold, augment if j else None, angle)
                    if v is not None:
                        out.append(v)
    x = np.asarray(out, np.uint8).reshape(-1, FUSED_DIM)
    if max_positives and len(x) > max_positives:
        x = x[np.sort(rng.choice(len(x), max_positives, replace=False))]
    return x, np.asarray(heights, float)


def turned_box(box, angle: float) -> np.ndarray:
    """The upright bounding box of ``box`` (x, y, w, h) turned by ``angle`` degrees about its centre."""
    x, y, w, h = (float(v) for v in box)
    c, s = abs(math.cos(math.radians(angle))), abs(math.sin(math.radians(angle)))
    width, height = w * c + h * s, w * s + h * c
    return np.array([x + (w - width) / 2, y + (h - height) / 2, width, height])


def window_shaped(box, window: tuple[int, int]) -> np.ndarray:
    """``box`` (x, y, w, h) reshaped to the aspect of ``window`` (w, h), same centre and area."""
    x, y, w, h = (float(v) for v in box)
    aspect = window[0] / window[1]
    height = math.sqrt(max(w * h, 0.0) / aspect)
    width = aspect * height
    return np.array([x + (w - width) / 2, y + (h - height) / 2, width, height])


def _flip_box(box, code: int, shape) -> np.ndarray:
    x, y, w, h = box
    height, width = shape
    if code in (1, -1):
        x = width - x - w
    if code in (0, -1):
        y = height - y - h
    return np.array([x, y, w, h])


class NegativeMiner:
    """Windows of the training images away from every box that the cascade so far accepts.

    Early stages accept many windows: images are visited in random order and each level gives at
    most a few, so negatives come from many images. Once the accepted windows of the *whole* set
    (estimated from the images visited) would fit in ``pool_size`` vectors, one full pass keeps all of
    them as a pool; later stages only filter the pool by the cascade (no more image scans), and
    training stops when the pool runs dry: every hard negative of the data has been used.
    """

    def __init__(self, data: list[LabelledImage], negative_images: list[Path], scan: dict, rotate90: bool,
                 negative_iou: float = 0.3, rng: np.random.Generator | None = None, pool_size: int = 200_000,
                 progress: Callable[[str], None] | None = None, angles: tuple = (0.0,)):
        self.data, self.negative_images = data, negative_images
        self.angles = sorted({float(a) for a in angles})
        self.scan, self.rotate90, self.negative_iou = scan, rotate90, negative_iou
        self.rng = rng or np.random.default_rng(0)
        self.pool_size, self.pool = pool_size, None
        self.say = progress or (lambda msg: None)

    @property
    def n_sources(self) -> int:
        return len(self.data) + len(self.negative_images)

    def _sources(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        order = list(range(self.n_sources))
        self.rng.shuffle(order)
        for k in order:
            if k < len(self.data):
                yield self.data[k].load(), self.data[k].all_boxes()
            else:
                image = cv2.imread(str(self.negative_images[k - len(self.data)]), cv2.IMREAD_GRAYSCALE)
                if image is not None:
                    yield image, np.zeros((0, 4))

    def _scan(self, cascade: Cascade, gray: np.ndarray, boxes: np.ndarray, per_image: int | None):
        """Accepted windows of one image away from its boxes: ``(vectors, how many were accepted)``;
        ``per_image`` caps the vectors kept (spread over the pyramid levels), None keeps all.

        The image is scanned as the detector scans it: turned by each of ``angles`` (``DetectorConfig.angles``)
        and, with ``rotate90``, transposed too; a window of a turned view is compared with the boxes as the
        upright box of its turned corners (``map_back``), and windows whose centre falls outside the image (on
        the turned canvas' reflected border, which the detector drops) are never negatives."""
        views = []
        for angle in self.angles:
            turned, back = turned_view(gray, angle)
            views.append((turned, back, False))
            if self.rotate90:
                views.append((np.ascontiguousarray(turned.T), back, True))
        size = gray.shape[::-1]
        found, accepted = [], 0
        for g, back, transposed in views:
            n_levels = len(window_scales(cascade.window, g.shape[::-1], self.scan["scale_factor"],
                                         self.scan["min_size"], self.scan["max_size"]))
            cap = None if per_image is None else max(1, int(math.ceil(per_image / max(1, n_levels))))

            def select(wins, back=back, transposed=transposed, cap=cap):
                nonlocal accepted
                framed, ok = map_back(wins[:, [1, 0, 3, 2]] if transposed else wins, np.arange(len(wins)), back, size)
                if len(boxes) and len(ok):
                    ok = ok[box_iou(framed[:, None, :], boxes[None, :, :]).max(axis=1) < self.negative_iou]
                accepted += len(ok)
                return ok if cap is None or len(ok) <= cap else self.rng.choice(ok, cap, replace=False)

            found.append(scan_cascade(g, cascade, with_vectors=True, select=select, **self.scan)[2])
        return np.vstack(found), accepted

    def __call__(self, cascade: Cascade, n: int) -> np.ndarray:
        if self.pool is not None:
            self.pool = self.pool[cascade.evaluate_vectors(self.pool)[0]]
            return self._draw(self.pool, n)
        per_image = max(4, int(math.ceil(4 * n / max(1, self.n_sources))))
        found, total, accepted, visited = [], 0, 0, 0
        for gray, boxes in self._sources():
            vectors, count = self._scan(cascade, gray, boxes, per_image)
            found.append(vectors)
            total, accepted, visited = total + len(vectors), accepted + count, visited + 1
            if total >= n:
                break
        estimate = accepted / max(1, visited) * self.n_sources
        if estimate <= self.pool_size and self.pool_size > 0:
            self.say(f"about {estimate:.0f} windows pass the cascade over all images: keeping them all as the "
                     "negative pool")
            self.pool = np.vstack([self._scan(cascade, gray, boxes, None)[0] for gray, boxes in self._sources()]
                                  or [np.zeros((0, FUSED_DIM), np.uint8)])
            self.say(f"negative pool: {len(self.pool)} windows")
            return self._draw(self.pool, n)
        x = np.vstack(found) if found else np.zeros((0, FUSED_DIM), np.uint8)
        return x[:n]

    def _draw(self, pool: np.ndarray, n: int) -> np.ndarray:
        return pool if len(pool) <= n else pool[np.sort(self.rng.choice(len(pool), n, replace=False))]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="train_cascade", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--yolo", nargs="*", default=[], help="YOLO folders (images/ + labels/)")
    p.add_argument("--voc", nargs="*", default=[], help="Pascal VOC folders")
    p.add_argument("--bag", nargs="*", default=[], help="ground-truth bags (image + ground_truth topics)")
    p.add_argument("--bag-every", type=int, default=1, help="use every k-th frame of a bag")
    p.add_argument("--bag-min-score", type=float, default=0.0,
                   help="ground-truth rows scoring below this (e.g. visible fraction) are ignored")
    p.add_argument("--negative-images", nargs="*", default=[], help="folders of images with no object")
    p.add_argument("--include-prefix", nargs="*", default=None, help="only image files with these name prefixes")
    p.add_argument("--exclude-prefix", nargs="*", default=None, help="skip image files with these name prefixes")
    p.add_argument("--class-ids", nargs="*", type=int, default=None, help="YOLO classes used as positives")
    p.add_argument("--ignore-class-ids", nargs="*", type=int, default=None,
                   help="YOLO classes ignored: neither positives nor cut as negatives (e.g. mostly hidden vehicles)")
    p.add_argument("--window", nargs=2, type=int, default=[64, 32], metavar=("W", "H"),
                   help="window size in frame pixels at scale 1 (the smallest object searched)")
    p.add_argument("--rotate90", action="store_true", help="objects appear turned by 90 degrees too: "
                   "train on boxes turned to the window's orientation, detect on the frame and its transpose")
    p.add_argument("--flips", choices=sorted(FLIPS), default="h", help="mirror augmentations of positives")
    p.add_argument("--positive-aspect", choices=("box", "window"), default="box",
                   help="cut positives as labelled (box) or reshaped to the window's shape, same centre and area "
                   "(window: for objects whose boxes vary in shape, e.g. vehicles at any heading)")
    p.add_argument("--keep-truncated", action="store_true", help="also use boxes cut by the frame border")
    p.add_argument("--jitter", type=int, default=2, help="randomly shifted/scaled copies per positive view")
    p.add_argument("--jitter-shift", type=float, default=0.0,
                   help="largest shift of a jittered copy, as a fraction of the window (0: half the mining stride)")
    p.add_argument("--photometric", type=float, default=0.0,
                   help="grey-level augmentation of the jittered copies (contrast, brightness, blur; 0: none, 1: strong)")
    p.add_argument("--turn-jitter", type=float, default=0.0,
                   help="turn the jittered copies by up to this many degrees about the box centre and cut their upright "
                   "bounding box (vehicles at any heading in nadir views; 45: every heading; 0: none)")
    p.add_argument("--max-positives", type=int, default=0, help="subsample positives to this many (0: all)")
    p.add_argument("--negative-pool", type=int, default=200_000,
                   help="once all windows the cascade accepts fit in this many vectors (1152 bytes each), keep "
                   "them and stop scanning images (0: scan every stage)")
    p.add_argument("--angles", nargs="*", type=float, default=[0.0],
                   help="mine negatives in the image turned by each of these angles [deg] too, as the detector "
                   "scans it (DetectorConfig.angles; with --rotate90 each view also transposed)")
    p.add_argument("--negative-iou", type=float, default=0.3, help="a negative window overlaps every box less")
    p.add_argument("--scale-factor", type=float, default=1.2, help="pyramid step while mining negatives")
    p.add_argument("--stride", type=int, default=4, choices=(2, 4, 8), help="scan stride while mining negatives")
    p.add_argument("--min-size", type=float, default=0.0, help="smallest window height mined [px] (0: auto)")
    p.add_argument("--max-size", type=float, default=0.0, help="largest window height mined [px] (0: auto)")
    p.add_argument("--edge-threshold", type=float, default=FeatureConfig().edge_threshold,
                   help="|Laplacian| binarisation threshold of the contour features")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--output", "-o", required=True, help="model file to write (.json)")
    add_config_arguments(p, CascadeTrainConfig)
    return p


def load_training_data(args) -> list[LabelledImage]:
    data: list[LabelledImage] = []
    for folder in args.yolo:
        data += read_yolo_folder(folder, args.include_prefix, args.exclude_prefix, args.class_ids,
                                 args.ignore_class_ids)
    for folder in args.voc:
        data += read_voc_folder(folder, args.include_prefix, args.exclude_prefix)
    for bag in args.bag:
        data += read_bag(bag, args.bag_every, args.bag_min_score)
    if not data:
        raise TrainingDataError("no training data: give --yolo, --voc or --bag")
    return data


def run(args) -> Cascade:
    from aircraft_docking_tracker.io.bag import check_outputs  # noqa: PLC0415

    # the model is saved after every stage: `-o` must not be one of the bags or folders trained from
    check_outputs([args.output], [*args.yolo, *args.voc, *args.bag, *args.negative_images], "train_cascade")
    cfg = config_from_arguments(CascadeTrainConfig, args)
    rng = np.random.default_rng(args.seed)
    data = load_training_data(args)
    window = (int(args.window[0]), int(args.window[1]))
    t0 = time.perf_counter()
    say = lambda msg: print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", flush=True)  # noqa: E731
    xp, heights = positive_vectors(data, window, cfg.feature_set, args.edge_threshold, args.rotate90,
                                   args.flips, args.keep_truncated, args.max_positives, rng, args.jitter,
                                   args.jitter_shift or args.stride / 2 / LBP_SIZE, args.scale_factor ** 0.5,
                                   args.positive_aspect,
                                   args.photometric, args.turn_jitter)
    say(f"{len(data)} images, {len(xp)} positive vectors")
    min_size = args.min_size or (float(np.percentile(heights, 2)) * 0.85 if len(heights) else 0.0)
    if 0 < min_size < window[1]:   # the scan never looks at windows smaller than the model's
        small = float(np.mean(heights < window[1])) if len(heights) else 0.0
        say(f"warning: {100 * small:.0f} % of the boxes are lower than the {window[1]} px window: they are "
            f"searched at {window[1]} px only (train with a smaller --window to find them at their size)")
        min_size = float(window[1])
    max_size = args.max_size or (float(np.percentile(heights, 98)) * 1.15 if len(heights) else 0.0)
    negatives = [p for folder in args.negative_images for p in sorted(Path(folder).iterdir())
                 if p.suffix.lower() in IMAGE_SUFFIXES]
    miner = NegativeMiner(data, negatives, dict(scale_factor=args.scale_factor, stride=args.stride,
                                                min_size=min_size, max_size=max_size),
                          args.rotate90, args.negative_iou, rng, args.negative_pool, say, tuple(args.angles))
    say(f"mining negatives at window heights {min_size:.0f}..{max_size:.0f} px")
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    info = {"data": [str(p) for p in args.yolo + args.voc + args.bag],
            "include_prefix": args.include_prefix, "exclude_prefix": args.exclude_prefix,
            "flips": args.flips, "jitter": args.jitter, "jitter_shift": args.jitter_shift or args.stride / 2 / LBP_SIZE, "positive_aspect": args.positive_aspect,
            "photometric": args.photometric, "turn_jitter": args.turn_jitter, "mining_angles": list(args.angles),
            "mining_stride": args.stride, "max_positives": args.max_positives, "seed": args.seed,
            "search_min_size": min_size, "search_max_size": max_size}

    def save(cascade: Cascade) -> None:  # after every stage: an interrupted run still leaves a model
        cascade.info.update(info, train_seconds=round(time.perf_counter() - t0, 1))
        cascade.save(args.output)

    cascade = train_cascade(xp, miner, cfg, window, args.edge_threshold, args.rotate90, progress=say,
                            on_stage=save)
    save(cascade)
    say(f"wrote {args.output}: {len(cascade.stages)} stages, {cascade.n_stumps} stumps")
    return cascade


def main(args=None) -> int:
    parsed = build_parser().parse_args(args)
    try:
        run(parsed)
    except (TrainingDataError, ValueError, OSError) as exc:
        print(f"train_cascade: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
