"""OpenCV's ``INTER_AREA`` shrink of a grey image, to the same bits, several times faster (pure: numpy + numba).

The detector's pyramid (:class:`features.LevelScan`) resizes every frame to each level with
``cv2.resize(..., INTER_AREA)``. When both axes shrink by a factor that is not a whole number, OpenCV
takes its exact-area path (``ResizeArea_Invoker`` in ``imgproc/src/resize.cpp``): each destination pixel
is the area-weighted mean of the source pixels its cell covers. That path is scalar, recomputes a
source row's horizontal pass once for every destination row that reads it, and took 1.5-2 ms a level
on a 704x544 view whatever the level's size: a quarter of the UAV set-up's frame.

:func:`resize_area` computes the same sums in the same order, in float32 as OpenCV does:

* weights (OpenCV's ``computeResizeAreaTab``): destination cell ``d`` covers source ``[d s, (d+1) s)``
  (``s`` = source size / destination size); a source pixel partly inside weighs the covered share of
  the cell, ``1 / cell`` when whole, ``cell = min(s, size - d s)``;
* horizontal pass: ``h[y, d] = sum_k w_k * src[y, x_k]`` over the cell's pixels left to right;
* vertical pass: ``dst[d, x] = round(sum_k w_k * h[y_k, x])`` over its rows top to bottom, rounded half
  to even and saturated to 0..255 (``saturate_cast<uchar>``).

Every cell's weights are padded with zero weights to the widest cell's count: adding ``0 * v`` to a
non-negative float32 sum leaves its bits as they are, and the fixed count lets the loops run across
whole rows (the horizontal pass on the transposed image) instead of cell by cell. Any other case (a
whole-number factor, an axis that grows, the same size) is OpenCV's own call.
``test/test_area_resize.py`` compares the two on random images and sizes.
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def area_weights(source: int, destination: int, scale: float):
    """OpenCV's ``computeResizeAreaTab`` for one axis as ``(indices, weights)``, each ``(destination, k)``:
    row ``d`` lists the source pixels of cell ``d`` in order and their float32 weights, padded with weight 0
    (index of the cell's first pixel) to the widest cell's ``k``."""
    room = int(np.ceil(scale)) + 2             # a cell's pixels: a partial one each end, at most ceil(scale) whole
    indices = np.zeros((destination, room), np.int64)
    weights = np.zeros((destination, room), np.float32)
    widest = 1
    for d in range(destination):
        fs1 = d * scale
        fs2 = fs1 + scale
        cell = min(scale, source - fs1)
        s1, s2 = int(np.ceil(fs1)), int(np.floor(fs2))
        s2 = min(s2, source - 1)
        s1 = min(s1, s2)
        k = 0
        if s1 - fs1 > 1e-3:
            indices[d, k], weights[d, k] = s1 - 1, np.float32((s1 - fs1) / cell)
            k += 1
        for s in range(s1, s2):
            indices[d, k], weights[d, k] = s, np.float32(1.0 / cell)
            k += 1
        if fs2 - s2 > 1e-3:
            indices[d, k], weights[d, k] = s2, np.float32(min(min(fs2 - s2, 1.0), cell) / cell)
            k += 1
        indices[d, k:] = indices[d, 0]
        widest = max(widest, k)
    indices, weights = np.ascontiguousarray(indices[:, :widest]), np.ascontiguousarray(weights[:, :widest])
    return indices, weights


@numba.njit(cache=True, nogil=True)
def _horizontal(transposed, indices, weights):
    """The horizontal pass on the source's transpose: ``out[d, y] = sum_k weights[d, k] * src[y, indices[d, k]]``
    in ``k`` order, float32, every source row at once."""
    cells, count = indices.shape
    rows = transposed.shape[1]
    out = np.empty((cells, rows), np.float32)
    for d in range(cells):
        line = out[d]
        weight, column = weights[d, 0], transposed[indices[d, 0]]
        for y in range(rows):
            line[y] = np.float32(column[y]) * weight
        for k in range(1, count):
            weight, column = weights[d, k], transposed[indices[d, k]]
            for y in range(rows):
                line[y] += np.float32(column[y]) * weight
    return out


@numba.njit(cache=True, nogil=True)
def _vertical(horizontal, indices, weights):
    """The vertical pass: ``dst[d, x] = round(sum_k weights[d, k] * horizontal[indices[d, k], x])`` in ``k`` order,
    float32, rounded half to even and saturated to uint8."""
    cells, count = indices.shape
    width = horizontal.shape[1]
    out = np.empty((cells, width), np.uint8)
    total = np.empty(width, np.float32)
    for d in range(cells):
        weight, row = weights[d, 0], horizontal[indices[d, 0]]
        for x in range(width):
            total[x] = weight * row[x]
        for k in range(1, count):
            weight, row = weights[d, k], horizontal[indices[d, k]]
            for x in range(width):
                total[x] += weight * row[x]
        for x in range(width):
            value = np.rint(total[x])
            out[d, x] = 0 if value < 0 else (255 if value > 255 else np.uint8(value))
    return out


@lru_cache(maxsize=256)
def _axis_weights(source: int, destination: int, scale: float):
    """:func:`area_weights`, kept: a pyramid resizes every frame to the same level sizes, so each axis' table is
    computed once, not twice a level and frame (the passes only read it)."""
    return area_weights(source, destination, scale)


def resize_area(gray: np.ndarray, size: tuple[int, int], transposed: np.ndarray | None = None) -> np.ndarray:
    """``cv2.resize(gray, size, interpolation=cv2.INTER_AREA)`` of a uint8 grey image, the same bits; ``size`` is
    ``(width, height)``. ``transposed``: ``gray``'s transpose, C-contiguous, when the caller has it (a pyramid resizes
    one view to many levels, and the detector scans the transposed view too)."""
    height, width = gray.shape
    new_width, new_height = size
    scale_x, scale_y = 1.0 / (new_width / width), 1.0 / (new_height / height)   # as OpenCV: 1 / its inverse scale
    whole = abs(scale_x - round(scale_x)) < np.finfo(float).eps and abs(scale_y - round(scale_y)) < np.finfo(float).eps
    if gray.dtype != np.uint8 or scale_x < 1 or scale_y < 1 or whole:
        return cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
    if transposed is None or transposed.shape != (width, height) or not transposed.flags.c_contiguous:
        transposed = cv2.transpose(gray)
    horizontal = _horizontal(transposed, *_axis_weights(width, new_width, scale_x))
    return _vertical(cv2.transpose(horizontal), *_axis_weights(height, new_height, scale_y))
