"""Fused LBP-texture + contour-potential features of seed 003 §2.1-2.2 (pure: numpy + OpenCV).

One candidate window gives the 1152-d vector ``v = [v'_L, v'_C]``:

* texture ``v_L`` (1024-d): the window resized to 32x32, the basic 8-neighbour LBP code
  (256 patterns, Ojala et al. 2002 = seed ref. [13]) of each pixel, one 256-bin histogram per
  16x16 block, blocks in row order (top-left, top-right, bottom-left, bottom-right);
* contour ``v_C`` (128-d): the window resized to 64x64, ``|Laplacian| > edge_threshold`` as the
  binary contour image ``b``, then its *potential-energy* sequences along x and along y;
* each part scaled to [0, 255] by ``255 / its own maximum`` (eqs. 3-4) and concatenated.

Potential energy (the seed cites Chen & Xu 2011, "gray-scale potential" of a binary image, which
sums each foreground pixel's distance to a base line; the seed gives no formula, so this is ours):
every edge pixel is a unit mass, its potential is its distance to the axis, the x axis being the
window's bottom edge and the y axis its left edge (image rows i = 0..63 from the top, columns
j = 0..63 from the left)::

    P_x(j) = sum_i b(i, j) * (64 - i)        (column j: 64 values, a bottom-row pixel weighs 1)
    P_y(i) = sum_j b(i, j) * (j + 1)         (row i: 64 values, a left-column pixel weighs 1)

LBP code: neighbours of pixel c clockwise from the top-left, neighbour k sets bit k when its
grey value is >= c's (bit 0 = top-left, 1 = top, 2 = top-right, 3 = right, 4 = bottom-right,
5 = bottom, 6 = bottom-left, 7 = left).

Every window of a frame is scored without a Python loop over windows by :class:`LevelScan`: per
pyramid level one LBP code image, per-cell code histograms (one ``bincount``) and block sums,
one binary contour image and its column/row cumulative sums; the per-window maxima of eqs. 3-4
are exact (maximum over the 256 bins of each block; sliding maxima of the potential maps by
``cv2.dilate``). All raw values are integers, so the normalised comparison ``255 v_k / max >= t``
is tested exactly as ``255 v_k >= t max``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aircraft_docking_tracker.config import param

LBP_SIZE = 32          # texture window side (seed §2.1)
BLOCK = 16             # texture block side
CONTOUR_SIZE = 64      # contour window side
N_CODES = 256
LBP_DIM = 4 * N_CODES  # 1024
CONTOUR_DIM = 2 * CONTOUR_SIZE  # 128
FUSED_DIM = LBP_DIM + CONTOUR_DIM  # 1152
FEATURE_SETS = ("lbp", "contour", "fused")
BLOCK_OFFSETS = ((0, 0), (0, BLOCK), (BLOCK, 0), (BLOCK, BLOCK))  # (dy, dx) in row order

# neighbour offsets (dy, dx) for bits 0..7, clockwise from the top-left
_NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1))


class FeatureError(ValueError):
    """Input that the features cannot be computed on (wrong shape, size or type)."""


@dataclass
class FeatureConfig:
    """Constants of the feature extraction (seed 003 §2.1-2.2)."""

    feature_set: str = param("fused", "features used: LBP texture only, contour only, or both (seed)",
                             choices=FEATURE_SETS)
    edge_threshold: float = param(40.0, "binarisation threshold of |Laplacian| (grey levels) for the "
                                  "contour image; the seed gives none", low=0.0, high=1020.0)


def feature_range(feature_set: str) -> np.ndarray:
    """Indices into the 1152-d fused vector that a feature set may use."""
    if feature_set == "lbp":
        return np.arange(LBP_DIM)
    if feature_set == "contour":
        return np.arange(LBP_DIM, FUSED_DIM)
    if feature_set == "fused":
        return np.arange(FUSED_DIM)
    raise FeatureError(f"unknown feature set {feature_set!r}; expected one of {FEATURE_SETS}")


def _gray(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim != 2:
        raise FeatureError(f"expected a grey or BGR image, got shape {image.shape}")
    if image.dtype != np.uint8:
        raise FeatureError(f"expected uint8 pixels, got {image.dtype}")
    return image


def lbp_codes(gray: np.ndarray) -> np.ndarray:
    """LBP8 code of every interior pixel: ``out[y, x]`` is the code of ``gray[y + 1, x + 1]``."""
    g = _gray(gray)
    h, w = g.shape
    if h < 3 or w < 3:
        raise FeatureError(f"image {w}x{h} too small for LBP")
    centre = g[1:-1, 1:-1]
    codes = np.zeros((h - 2, w - 2), np.uint8)
    for bit, (dy, dx) in enumerate(_NEIGHBOURS):
        codes |= (g[1 + dy:h - 1 + dy, 1 + dx:w - 1 + dx] >= centre).view(np.uint8) << bit
    return codes


def contour_image(gray: np.ndarray, edge_threshold: float) -> np.ndarray:
    """Binary contour image (uint8 0/1): ``|Laplacian| > edge_threshold`` (3x3 kernel, seed §2.1)."""
    lap = cv2.Laplacian(_gray(gray), cv2.CV_16S, ksize=1)
    return (np.abs(lap) > edge_threshold).view(np.uint8)


def potential_sequences(binary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P_x, P_y)`` of a square binary image (see the module docstring for the formulas)."""
    b = np.asarray(binary)
    if b.ndim != 2 or b.shape[0] != b.shape[1]:
        raise FeatureError(f"expected a square binary image, got shape {b.shape}")
    n = b.shape[0]
    b = (b != 0).astype(np.int64)
    px = (b * (n - np.arange(n))[:, None]).sum(axis=0)
    py = (b * (np.arange(n) + 1)[None, :]).sum(axis=1)
    return px, py


def scale_to_255(v: np.ndarray) -> np.ndarray:
    """Eqs. 3-4: ``255 / max(v) * v`` (all zeros when the maximum is 0)."""
    v = np.asarray(v, dtype=np.float64)
    m = v.max() if v.size else 0.0
    return v * (255.0 / m) if m > 0 else np.zeros_like(v)


def lbp_histograms(codes32: np.ndarray) -> np.ndarray:
    """Raw 1024-d texture vector ``v_L`` of a 32x32 code patch (four 256-bin block histograms)."""
    if codes32.shape != (LBP_SIZE, LBP_SIZE):
        raise FeatureError(f"expected 32x32 LBP codes, got {codes32.shape}")
    return np.concatenate([np.bincount(codes32[dy:dy + BLOCK, dx:dx + BLOCK].ravel(), minlength=N_CODES)
                           for dy, dx in BLOCK_OFFSETS])


def window_features(lbp_patch: np.ndarray, contour_patch: np.ndarray, edge_threshold: float) -> np.ndarray:
    """The 1152-d fused vector ``v`` of one window, given its pixels with one pixel of context.

    ``lbp_patch`` is the window resized to 32x32 plus a 1-pixel rim (34x34); ``contour_patch`` the
    window resized to 64x64 plus a rim (66x66): the rim gives the LBP and Laplacian neighbours.
    This is the reference path; :class:`LevelScan` gives the same numbers for every window at once.
    """
    lbp_patch, contour_patch = _gray(lbp_patch), _gray(contour_patch)
    if lbp_patch.shape != (LBP_SIZE + 2,) * 2 or contour_patch.shape != (CONTOUR_SIZE + 2,) * 2:
        raise FeatureError(f"expected 34x34 and 66x66 patches, got {lbp_patch.shape}, {contour_patch.shape}")
    v_l = lbp_histograms(lbp_codes(lbp_patch))
    binary = contour_image(contour_patch, edge_threshold)[1:-1, 1:-1]
    v_c = np.concatenate(potential_sequences(binary))
    return np.concatenate([scale_to_255(v_l), scale_to_255(v_c)])


class LevelScan:
    """Raw features and eq. 3-4 maxima of every window of one pyramid level, on a stride grid.

    ``gray_l`` is the frame resized so that one window is 32x32 (the texture level); the contour
    level is the same frame resized to exactly twice that size. Windows have their top-left
    *code* position at ``(row * stride, col * stride)`` (pixel ``+1`` in ``gray_l``), ``stride``
    dividing 16 so that every block lies on the histogram cell grid.
    """

    def __init__(self, frame_gray: np.ndarray, level_size: tuple[int, int], stride: int,
                 feature_set: str, edge_threshold: float):
        if BLOCK % stride:
            raise FeatureError(f"stride {stride} must divide the block size {BLOCK}")
        feature_range(feature_set)
        frame_gray = _gray(frame_gray)
        wl, hl = level_size
        self.stride, self.feature_set = stride, feature_set
        self.level_size = (wl, hl)
        # windows whose 34x34 texture patch lies inside the level
        self.rows = max(0, (hl - LBP_SIZE - 2) // stride + 1)
        self.cols = max(0, (wl - LBP_SIZE - 2) // stride + 1)
        self.m_lbp = self.m_contour = None
        if self.rows == 0 or self.cols == 0:
            return
        if feature_set in ("lbp", "fused"):
            self._texture(cv2.resize(frame_gray, (wl, hl), interpolation=cv2.INTER_AREA))
        if feature_set in ("contour", "fused"):
            self._contour(cv2.resize(frame_gray, (2 * wl, 2 * hl), interpolation=cv2.INTER_AREA),
                          edge_threshold)

    @property
    def n_windows(self) -> int:
        return self.rows * self.cols

    def window_origins(self) -> np.ndarray:
        """``(n, 2)`` top-left (x, y) of every window in texture-level pixels, row-major."""
        r, c = np.divmod(np.arange(self.n_windows), self.cols)
        return np.stack([c * self.stride + 1, r * self.stride + 1], axis=1)

    # --- texture: cell histograms -> block histograms -> per-window maximum (eq. 3)
    def _texture(self, gray_l: np.ndarray) -> None:
        s = self.stride
        codes = lbp_codes(gray_l)
        hc, wc = codes.shape[0] // s, codes.shape[1] // s
        codes = codes[:hc * s, :wc * s]
        cell = (np.arange(hc * s) // s)[:, None] * wc + (np.arange(wc * s) // s)[None, :]
        hist = np.bincount((cell * N_CODES + codes).ravel(), minlength=hc * wc * N_CODES)
        blocks = hist.reshape(hc, wc, N_CODES).astype(np.int16)
        span = 1  # sum 16/stride cells per side by doubling (stride divides 16: a power of two)
        while span < BLOCK // s:
            blocks = blocks[:-span] + blocks[span:]
            blocks = blocks[:, :-span] + blocks[:, span:]
            span *= 2
        self.blocks = blocks  # blocks[by, bx, code]: histogram of the 16x16 block at cell (by, bx)
        block_max = self.blocks.max(axis=2)
        r, c = self.rows, self.cols
        self.m_lbp = np.max([block_max[dy // s:dy // s + r, dx // s:dx // s + c] for dy, dx in BLOCK_OFFSETS],
                            axis=0).reshape(-1).astype(np.int64)

    # --- contour: potential maps from integral images, per-window maximum by sliding max (eq. 4)
    def _contour(self, gray_c: np.ndarray, edge_threshold: float) -> None:
        n, s2 = CONTOUR_SIZE, 2 * self.stride
        b = contour_image(gray_c, edge_threshold)
        b[0, :] = b[-1, :] = 0
        b[:, 0] = b[:, -1] = 0
        y0 = 2 + s2 * np.arange(self.rows)  # window top rows in contour-level pixels
        x0 = 2 + s2 * np.arange(self.cols)
        bf = b.astype(np.float32)
        # integral images (sums over y' < y, x' < x) of b, Y b and X b; all sums are exact integers
        sum_b = cv2.integral(b, sdepth=cv2.CV_32S).astype(np.float64)
        sum_yb = cv2.integral(bf * np.arange(b.shape[0], dtype=np.float32)[:, None], sdepth=cv2.CV_64F)
        sum_xb = cv2.integral(bf * np.arange(b.shape[1], dtype=np.float32)[None, :], sdepth=cv2.CV_64F)

        def down(integral):  # sum over rows y0 .. y0+n-1 of every column X: (rows, W)
            below = np.diff(integral[y0 + n], axis=1)
            return below - np.diff(integral[y0], axis=1)

        def right(integral):  # sum over columns x0 .. x0+n-1 of every row Y: (H, cols)
            return np.diff(integral[:, x0 + n], axis=0) - np.diff(integral[:, x0], axis=0)

        # P_x(j) = sum_i b(y0+i, X)(n - i) = (n + y0) sum_Y b - sum_Y Y b, rows y0, every column X
        self.px = ((n + y0)[:, None] * down(sum_b) - down(sum_yb)).astype(np.float32)
        # P_y(i) = sum_j b(Y, x0+j)(j + 1) = sum_X X b - (x0 - 1) sum_X b, every row Y, columns x0
        self.py = (right(sum_xb) - (x0 - 1)[None, :] * right(sum_b)).astype(np.float32)
        run_x = cv2.dilate(self.px, np.ones((1, n), np.uint8), anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)
        run_y = cv2.dilate(self.py, np.ones((n, 1), np.uint8), anchor=(0, 0), borderType=cv2.BORDER_REPLICATE)
        self.m_contour = np.maximum(run_x[:, x0], run_y[y0, :]).reshape(-1).astype(np.int64)
        self._y0, self._x0 = y0, x0

    def raw(self, features: np.ndarray, windows: np.ndarray) -> np.ndarray:
        """Raw (un-normalised, integer) values ``(n windows, k features)`` of fused-vector features.

        One flat ``np.take`` per table: a window's base offset plus a feature's offset.
        """
        features = np.asarray(features, np.int64)
        r, c = np.divmod(np.asarray(windows, np.int64), self.cols)
        out = np.zeros((len(r), len(features)), np.int64)
        lbp = features < LBP_DIM
        if lbp.any():   # blocks[r + by, c + bx, code], blocks of shape (hb, wb, 256)
            hb, wb, _ = self.blocks.shape
            block, code = np.divmod(features[lbp], N_CODES)
            by, bx = (np.asarray(BLOCK_OFFSETS)[block] // self.stride).T
            offset = (by * wb + bx) * N_CODES + code
            out[:, lbp] = np.take(self.blocks, ((r * wb + c) * N_CODES)[:, None] + offset[None, :])
        k = features - LBP_DIM
        along_x, along_y = (k >= 0) & (k < CONTOUR_SIZE), k >= CONTOUR_SIZE
        if along_x.any():   # px[r, x0[c] + k]
            out[:, along_x] = np.take(self.px, (r * self.px.shape[1] + self._x0[c])[:, None] + k[along_x][None, :])
        if along_y.any():   # py[y0[r] + k - 64, c]
            cols = self.py.shape[1]
            out[:, along_y] = np.take(self.py, (self._y0[r] * cols + c)[:, None]
                                      + ((k[along_y] - CONTOUR_SIZE) * cols)[None, :])
        return out

    def maxima(self, features: np.ndarray, windows: np.ndarray) -> np.ndarray:
        """The eq. 3 or eq. 4 maximum of the part each feature belongs to, ``(n windows, k features)``."""
        lbp = np.asarray(features) < LBP_DIM
        out = np.zeros((len(windows), len(lbp)), np.int64)
        if lbp.any():
            out[:, lbp] = self.m_lbp[windows][:, None]
        if (~lbp).any():
            out[:, ~lbp] = self.m_contour[windows][:, None]
        return out

    def passes(self, features: np.ndarray, thresholds: np.ndarray, windows: np.ndarray) -> np.ndarray:
        """Exact ``255 * v_k / max >= t_k``, ``(n windows, k features)`` (False where max is 0)."""
        m = self.maxima(features, windows)
        return (255 * self.raw(features, windows) >= np.asarray(thresholds, np.int64)[None, :] * m) & (m > 0)

    def vectors(self, windows: np.ndarray) -> np.ndarray:
        """Full normalised 1152-d vectors (uint8, floored) of some windows, for training."""
        out = np.zeros((len(windows), FUSED_DIM), np.uint8)
        if len(windows) == 0:
            return out
        r, c = np.divmod(np.asarray(windows), self.cols)
        s = self.stride
        if self.m_lbp is not None:
            raw = np.concatenate([self.blocks[r + dy // s, c + dx // s, :] for dy, dx in BLOCK_OFFSETS], axis=1)
            out[:, :LBP_DIM] = _floor_scaled(raw, self.m_lbp[windows])
        if self.m_contour is not None:
            cols = self._x0[c][:, None] + np.arange(CONTOUR_SIZE)[None, :]
            rows = self._y0[r][:, None] + np.arange(CONTOUR_SIZE)[None, :]
            raw = np.concatenate([self.px[r[:, None], cols], self.py[rows, c[:, None]]], axis=1)
            out[:, LBP_DIM:] = _floor_scaled(raw, self.m_contour[windows])
        return out


def _floor_scaled(raw: np.ndarray, maxima: np.ndarray) -> np.ndarray:
    """``floor(255 * raw / max)`` row by row, exact in integers (0 where max is 0)."""
    raw = np.asarray(raw, np.int64)
    m = np.asarray(maxima, np.int64)[:, None]
    return np.where(m > 0, (255 * raw) // np.maximum(m, 1), 0).astype(np.uint8)


def quantised(vector: np.ndarray) -> np.ndarray:
    """``floor`` of a normalised float vector as uint8 (the training representation)."""
    return np.floor(np.asarray(vector) + 1e-9).clip(0, 255).astype(np.uint8)
