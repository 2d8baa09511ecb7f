"""Patch network: a small CNN that verifies and places each candidate group from its colour patch (pure: numpy and
OpenCV's dnn module).

The colour verifier reads ten colour statistics of a group's box, and the box regressor's image stages a few
profiles of it: hand-made summaries of the patch around the group. On the UAV scenes what they miss is where the
vehicle lies in the patch (a box on half a vehicle, on two neighbours, reaching into the ground beside one; issue 12:
mislocalised boxes were the largest share of the misses and of the false positives) and what a partly hidden or
border-cut vehicle looks like. R-CNN (Girshick et al. 2014) classifies each proposal from its own image region and
regresses its box from it; Fast R-CNN (Girshick 2015) does both with one network and two heads. Here the proposals
are the cascade's groups (their member-statistics boxes), and the network sees each one's patch:

* the region: a square of ``grow`` times the box's longer side about its centre (:func:`square_regions`),
  resampled to ``size`` x ``size`` colour pixels, the frame reflected beyond its edge (:func:`patches`);
* the input: the patches as an ``(n, 3, size, size)`` float blob, BGR, ``pixel / 255 - 0.5``;
* the output, one row a patch: the log odds that a vehicle (at least 30 % visible) is what the box is on, then the
  vehicle box's left, top, right and bottom edges relative to the region's centre in region sides
  (:func:`encode_boxes` / :func:`decode_boxes`).

The detector adds the log odds to the colour verifier's (both are evidence about the same group; the sum is the
score ``verifier_threshold`` applies to) and publishes the network's box, cut to the frame.
``tools/train_uav_patch_net.py`` trains it (PyTorch, needed by the tool only) and stores it as ONNX, a protobuf
graph of weights and operators (no code, no pickle), beside a JSON header that names it and holds ``size``,
``grow`` and how it was trained.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

PATCH_NET_FORMAT = "aircraft_docking_tracker/patch-net"
PATCH_NET_VERSION = 1
OUTPUTS = ("log_odds", "left", "top", "right", "bottom")
MAX_ONNX_BYTES = 5 * 1024 * 1024


class PatchNetError(ValueError):
    """A patch network file or input that cannot be used."""


def square_regions(boxes: np.ndarray, grow: float) -> np.ndarray:
    """``(n, 3)`` centre x, centre y and side of each box's region: a square of ``grow`` times its longer side."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    side = grow * np.maximum(np.maximum(boxes[:, 2], boxes[:, 3]), 1.0)
    return np.column_stack([boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3] / 2, side])


def patches(bgr: np.ndarray, boxes: np.ndarray, size: int, grow: float) -> np.ndarray:
    """``(n, size, size, 3)`` uint8: each box's region (:func:`square_regions`) of a BGR image resampled (bilinear,
    the image reflected beyond its edge)."""
    if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
        raise PatchNetError(f"the patch network needs a BGR uint8 image, got {bgr.dtype} {bgr.shape}")
    regions = square_regions(boxes, grow)
    out = np.empty((len(regions), size, size, 3), np.uint8)
    for k, (cx, cy, side) in enumerate(regions):
        a = size / side
        warp = np.array([[a, 0.0, size / 2 - a * cx], [0.0, a, size / 2 - a * cy]])
        out[k] = cv2.warpAffine(bgr, warp, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return out


def encode_boxes(boxes: np.ndarray, regions: np.ndarray) -> np.ndarray:
    """``(n, 4)`` edges left, top, right, bottom of boxes (x, y, w, h) relative to the regions' centres, in sides."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    cx, cy, side = (regions[:, k] for k in range(3))
    return np.column_stack([(boxes[:, 0] - cx) / side, (boxes[:, 1] - cy) / side,
                            (boxes[:, 0] + boxes[:, 2] - cx) / side, (boxes[:, 1] + boxes[:, 3] - cy) / side])


def decode_boxes(edges: np.ndarray, regions: np.ndarray, frame_size: tuple[int, int]) -> np.ndarray:
    """:func:`encode_boxes` inverted, each box cut to the ``frame_size`` (w, h) frame: ``(n, 4)`` x, y, w, h."""
    edges = np.asarray(edges, np.float64).reshape(-1, 4)
    cx, cy, side = (regions[:, k:k + 1] for k in range(3))
    corners = edges * side + np.hstack([cx, cy, cx, cy])
    width, height = frame_size
    x0, x1 = np.clip(corners[:, 0], 0, width), np.clip(corners[:, 2], 0, width)
    y0, y1 = np.clip(corners[:, 1], 0, height), np.clip(corners[:, 3], 0, height)
    return np.column_stack([x0, y0, np.maximum(x1 - x0, 0.0), np.maximum(y1 - y0, 0.0)])


@dataclass
class PatchNet:
    """The network (``cv2.dnn``) with its patch geometry; :meth:`predict` is all the detector calls."""

    net: object
    size: int
    grow: float
    info: dict = field(default_factory=dict)

    def forward(self, crops: np.ndarray) -> np.ndarray:
        """``(n, 5)`` :data:`OUTPUTS` of ``(n, size, size, 3)`` uint8 patches."""
        if not len(crops):
            return np.zeros((0, len(OUTPUTS)))
        blob = cv2.dnn.blobFromImages(list(crops), 1.0 / 255.0, (self.size, self.size), (127.5, 127.5, 127.5),
                                      swapRB=False, crop=False)
        self.net.setInput(blob)
        out = np.asarray(self.net.forward(), np.float64).reshape(len(crops), -1)
        if out.shape[1] != len(OUTPUTS) or not np.isfinite(out).all():
            raise PatchNetError(f"the patch network gave {out.shape[1]} outputs a patch (expected {len(OUTPUTS)}) "
                                "or a non-finite one")
        return out

    def predict(self, bgr: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(log odds (n,), vehicle boxes (n, 4) x, y, w, h cut to the frame)`` for the groups' ``boxes``."""
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        out = self.forward(patches(bgr, boxes, self.size, self.grow))
        return out[:, 0], decode_boxes(out[:, 1:], square_regions(boxes, self.grow), bgr.shape[1::-1])

    @classmethod
    def load(cls, path: str | Path) -> "PatchNet":
        """The network of the JSON header ``path`` (its ``onnx`` file beside it); refuses another format, a missing
        or oversized graph, and one that does not give :data:`OUTPUTS` for a blank patch."""
        path = Path(path)
        try:
            header = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
            raise PatchNetError(f"cannot read patch network {path}: {exc}") from exc
        if not isinstance(header, dict) or header.get("format") != PATCH_NET_FORMAT:
            raise PatchNetError(f"{path}: not a {PATCH_NET_FORMAT} header")
        if header.get("version") != PATCH_NET_VERSION:
            raise PatchNetError(f"{path}: patch network version {header.get('version')} unsupported "
                                f"(expected {PATCH_NET_VERSION})")
        if list(header.get("outputs", ())) != list(OUTPUTS):
            raise PatchNetError(f"{path}: outputs {header.get('outputs')} are not {list(OUTPUTS)}")
        size, grow, onnx = header.get("size"), header.get("grow"), header.get("onnx")
        if not isinstance(size, int) or not 8 <= size <= 256:
            raise PatchNetError(f"{path}: size {size!r} is not a whole number of pixels in 8..256")
        if not isinstance(grow, (int, float)) or not 1.0 <= grow <= 4.0:
            raise PatchNetError(f"{path}: grow {grow!r} is not a number in 1..4")
        if not isinstance(onnx, str) or Path(onnx).name != onnx:
            raise PatchNetError(f"{path}: onnx {onnx!r} must be a file name beside the header")
        graph = path.parent / onnx
        try:
            data = graph.read_bytes()
        except OSError as exc:
            raise PatchNetError(f"{path}: cannot read its graph {graph}: {exc}") from exc
        if len(data) > MAX_ONNX_BYTES:
            raise PatchNetError(f"{graph}: {len(data)} bytes, more than {MAX_ONNX_BYTES}")
        try:
            net = cv2.dnn.readNetFromONNX(np.frombuffer(data, np.uint8))
        except cv2.error as exc:
            raise PatchNetError(f"{graph}: OpenCV cannot read it as ONNX ({str(exc).strip()})") from None
        model = cls(net, size, float(grow), dict(header.get("info", {})))
        try:
            model.forward(np.zeros((1, size, size, 3), np.uint8))
        except cv2.error as exc:
            raise PatchNetError(f"{graph}: does not run on a {size}x{size} patch ({str(exc).strip()})") from None
        return model



def header(onnx: str, size: int, grow: float, info: dict) -> dict:
    """The JSON header of a network of patch geometry ``size`` / ``grow`` stored as ``onnx`` beside it (what
    :meth:`PatchNet.load` reads)."""
    return {"format": PATCH_NET_FORMAT, "version": PATCH_NET_VERSION, "outputs": list(OUTPUTS), "onnx": onnx,
            "size": size, "grow": grow, "info": info}
