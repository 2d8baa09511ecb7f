"""OpenCV cascade backend: any ``cv2.CascadeClassifier`` XML (Haar or LBP) (pure: OpenCV only).

Scores are OpenCV's own: ``detectMultiScale3(..., outputRejectLevels=True)`` returns per box the
weight of the last stage it reached (``levelWeights``), which we report as the detection score.
OpenCV 5's main module no longer has ``CascadeClassifier``; there :class:`OpenCVCascadeUnavailable`
says so instead of failing later.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np


class OpenCVCascadeError(ValueError):
    """A cascade XML that cannot be loaded, or bad input to it."""


class OpenCVCascadeUnavailable(OpenCVCascadeError):
    """The installed OpenCV has no ``cv2.CascadeClassifier`` (e.g. OpenCV 5 without contrib)."""


def _window_size(path: Path) -> tuple[int, int]:
    """Window (w, h) from the XML: new format ``<width>/<height>``, old format ``<size>w h</size>``."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise OpenCVCascadeError(f"{path}: not an XML file ({exc})") from exc
    cascade = next(iter(root), None)
    if cascade is None:
        raise OpenCVCascadeError(f"{path}: empty XML")
    w, h = cascade.find("width"), cascade.find("height")
    if w is not None and h is not None:
        return int(w.text), int(h.text)
    size = cascade.find("size")
    if size is not None:
        vals = size.text.split()
        return int(vals[0]), int(vals[1])
    raise OpenCVCascadeError(f"{path}: no window size in the cascade XML")


class OpenCVCascade:
    """A loaded ``cv2.CascadeClassifier`` with its window size."""

    def __init__(self, path: str | Path):
        if not hasattr(cv2, "CascadeClassifier"):
            raise OpenCVCascadeUnavailable(
                f"OpenCV {cv2.__version__} has no CascadeClassifier (removed from OpenCV 5's main module); "
                "use opencv-python(-headless) 4.x or the 'cascade' backend")
        self.path = Path(path)
        if not self.path.is_file():
            raise OpenCVCascadeError(f"cascade XML {path} not found")
        self.window = _window_size(self.path)
        self.classifier = cv2.CascadeClassifier(str(self.path))
        if self.classifier.empty():
            raise OpenCVCascadeError(f"cv2.CascadeClassifier could not load {path}")

    def detect(self, gray: np.ndarray, scale_factor: float = 1.1, min_neighbors: int = 3,
               min_size: float = 0.0, max_size: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``(boxes (n, 4) x y w h, scores)``; ``min_size``/``max_size`` are window heights in px (0: none)."""
        gray = np.asarray(gray)
        if gray.ndim != 2 or gray.dtype != np.uint8:
            raise OpenCVCascadeError(f"expected a uint8 grey image, got {gray.dtype} {gray.shape}")
        w0, h0 = self.window
        lo = (int(round(w0 * min_size / h0)), int(round(min_size))) if min_size > 0 else (0, 0)
        hi = (int(round(w0 * max_size / h0)), int(round(max_size))) if max_size > 0 else (0, 0)
        boxes, _, weights = self.classifier.detectMultiScale3(
            gray, scaleFactor=scale_factor, minNeighbors=int(min_neighbors), minSize=lo, maxSize=hi,
            outputRejectLevels=True)
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        return boxes, np.asarray(weights, np.float64).reshape(-1)
