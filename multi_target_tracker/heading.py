"""Heading-aligned views, shared by the UAV training chips, the detector's turned views and its blob views.

Pure (numpy + OpenCV). A model trained on objects turned along its window (the UAV set-up's) sees them through
the same two pieces everywhere: :func:`turned_canvas`, an image turned about a point onto a canvas centred there
(borders reflected), and :func:`chip_height`, the window that frames an object as the training chips did.
"""
from __future__ import annotations

import cv2
import numpy as np


def turned_canvas(image: np.ndarray, centre, angle: float, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``image`` turned by ``angle`` degrees about ``centre`` (x, y) onto a ``size`` (width, height) canvas whose
    centre is ``centre``, borders reflected: ``(canvas, the 2x3 affine map from the image to the canvas)``."""
    cx, cy = float(centre[0]), float(centre[1])
    turn = cv2.getRotationMatrix2D((cx, cy), float(angle), 1.0)
    turn[:, 2] += (size[0] / 2 - cx, size[1] / 2 - cy)
    return cv2.warpAffine(image, turn, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT), turn


def chip_height(length: float, width: float, window_aspect: float, context: float) -> float:
    """Height [px] of the window that frames an object ``length`` x ``width`` px along its heading as the
    training chips did: reshaped to the window's aspect (same area), enlarged ``context`` times."""
    return float(np.sqrt(length * width / window_aspect) * context)
