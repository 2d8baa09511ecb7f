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

Every window of a frame is scored at once by :class:`LevelScan`: per pyramid level one LBP code
image, per-cell code histograms and block sums, one binary contour image and its column/row
prefix sums; the per-window maxima of eqs. 3-4 are exact (maximum over the 256 bins of each
block; the largest of each window's step-long runs of the potential maps). All raw values are integers, so
the normalised comparison ``255 v_k / max >= t`` is tested exactly as ``255 v_k >= t max``.
The per-pixel and per-window loops (cell histograms, contour potentials, the cascade with its
early exit) are compiled by numba; :func:`window_features` is the plain reference they are
tested against.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numba
import numpy as np

from aircraft_docking_tracker.config import param
from multi_target_tracker.area_resize import resize_area

LBP_SIZE = 32          # texture window side (seed §2.1)
BLOCK = 16             # texture block side
CONTOUR_SIZE = 64      # contour window side
N_CODES = 256
LBP_DIM = 4 * N_CODES  # 1024
CONTOUR_DIM = 2 * CONTOUR_SIZE  # 128
FUSED_DIM = LBP_DIM + CONTOUR_DIM  # 1152
FEATURE_SETS = ("lbp", "contour", "fused")
BLOCK_OFFSETS = ((0, 0), (0, BLOCK), (BLOCK, 0), (BLOCK, BLOCK))  # (dy, dx) in row order
# a contour level's potentials are summed from its edge pixels alone (:func:`_edge_potentials`) when at most this
# share of its 8-pixel words holds one: the two paths break even at about 0.13 on the drone-view tiles' levels
# (session 50)
SPARSE_EDGE_WORDS = 0.12


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
    return _lbp_codes(np.ascontiguousarray(g))


@numba.njit(cache=True, nogil=True)
def _lbp_codes(g):
    """:func:`lbp_codes` compiled: one pass, per pixel the eight neighbour comparisons in the module
    docstring's bit order (6x faster than eight shifted array comparisons)."""
    h, w = g.shape
    codes = np.empty((h - 2, w - 2), np.uint8)
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            c = g[y, x]
            code = 0
            if g[y - 1, x - 1] >= c:
                code |= 1
            if g[y - 1, x] >= c:
                code |= 2
            if g[y - 1, x + 1] >= c:
                code |= 4
            if g[y, x + 1] >= c:
                code |= 8
            if g[y + 1, x + 1] >= c:
                code |= 16
            if g[y + 1, x] >= c:
                code |= 32
            if g[y + 1, x - 1] >= c:
                code |= 64
            if g[y, x - 1] >= c:
                code |= 128
            codes[y - 1, x - 1] = code
    return codes


def contour_image(gray: np.ndarray, edge_threshold: float) -> np.ndarray:
    """Binary contour image (uint8 0/1): ``|Laplacian| > edge_threshold`` (3x3 kernel, seed §2.1)."""
    lap = cv2.Laplacian(_gray(gray), cv2.CV_16S, ksize=1)
    if 0 <= edge_threshold < 255:   # |lap| saturated at 255 tests the same; OpenCV's uint8 threshold is x > floor(t)
        return cv2.threshold(cv2.convertScaleAbs(lap), edge_threshold, 1, cv2.THRESH_BINARY)[1]
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


@dataclass(frozen=True)
class PackedStages:
    """A cascade's stumps in flat arrays, what :meth:`LevelScan.evaluate` reads: stage s holds stumps
    ``ends[s-1] .. ends[s]-1`` and passes when their sum reaches ``stage_thresholds[s]``. Built from
    any stages with ``features, thresholds, left, right, threshold`` (``cascade.Stage``); kept here so
    that the cascade module imports the features and never the other way round. ``codes``: the LBP codes its
    texture stumps read (sorted), the only code planes a :class:`LevelScan` needs to keep for it."""

    features: np.ndarray
    thresholds: np.ndarray
    left: np.ndarray
    right: np.ndarray
    ends: np.ndarray
    stage_thresholds: np.ndarray
    codes: np.ndarray

    @classmethod
    def of(cls, stages: list) -> "PackedStages":
        def flat(name, dtype):
            return np.ascontiguousarray(np.concatenate([getattr(s, name) for s in stages]) if stages
                                        else np.zeros(0), dtype)
        features = flat("features", np.int64)
        return cls(features, flat("thresholds", np.int64), flat("left", np.float64),
                   flat("right", np.float64), np.cumsum([len(s.features) for s in stages], dtype=np.int64),
                   np.asarray([s.threshold for s in stages], np.float64).reshape(-1),
                   np.unique(features[features < LBP_DIM] % N_CODES))


def window_grid(level_size: tuple[int, int], stride: int) -> tuple[int, int]:
    """Rows and columns of the windows of a ``level_size`` (width, height) level on a ``stride`` grid: those whose
    34x34 texture patch (the 32x32 window and its LBP rim) lies inside it."""
    width, height = level_size
    return max(0, (height - LBP_SIZE - 2) // stride + 1), max(0, (width - LBP_SIZE - 2) // stride + 1)


def grid_origins(rows: np.ndarray, cols: np.ndarray, stride: int) -> np.ndarray:
    """``(n, 2)`` top-left (x, y) in texture-level pixels of the windows at grid ``rows``, ``cols`` of a ``stride``
    grid (:func:`window_grid`): code position ``(row, col) * stride``, pixel ``+1``."""
    return np.stack([cols * stride + 1, rows * stride + 1], axis=1).reshape(-1, 2)


@lru_cache(maxsize=16)
def _kept_planes(codes: bytes | None, dtype: str | None) -> tuple[np.ndarray, np.ndarray]:
    """``(codes, plane_of)`` of the LBP codes whose block planes a scan keeps (their array's bytes and dtype; None:
    all 256), checked once: a detector scans with one cascade's codes every level and frame. ``plane_of[code]`` is the
    code's plane in ``blocks`` (-1: not kept). Both read-only (shared by the scans)."""
    kept = np.arange(N_CODES) if codes is None else np.frombuffer(codes, dtype).astype(np.int64).reshape(-1)
    if len(kept) and (kept.min() < 0 or kept.max() >= N_CODES or np.any(np.diff(kept) <= 0)):
        raise FeatureError(f"codes must be distinct sorted LBP codes in 0..255, got {kept.tolist()}")
    plane_of = np.full(N_CODES, -1, np.int64)
    plane_of[kept] = np.arange(len(kept))
    kept.flags.writeable = plane_of.flags.writeable = False
    return kept, plane_of


class LevelScan:
    """Raw features and eq. 3-4 maxima of every window of one pyramid level, on a stride grid.

    ``gray_l`` is the frame resized so that one window is 32x32 (the texture level); the contour
    level is the same frame resized to exactly twice that size (both OpenCV's ``INTER_AREA``, computed
    to the same bits by :func:`area_resize.resize_area`). Windows have their top-left
    *code* position at ``(row * stride, col * stride)`` (pixel ``+1`` in ``gray_l``), ``stride``
    dividing 16 so that every block lies on the histogram cell grid. ``codes``: the LBP codes whose block
    planes are kept (a cascade's :attr:`PackedStages.codes`: a scan for detection); all 256 by default, which
    :meth:`vectors` needs. ``frame_transposed``: the frame's transpose when the caller has it (the resizes use it).
    """

    def __init__(self, frame_gray: np.ndarray, level_size: tuple[int, int], stride: int,
                 feature_set: str, edge_threshold: float, codes: np.ndarray | None = None,
                 frame_transposed: np.ndarray | None = None):
        frame_gray = _gray(frame_gray)
        self._setup(level_size, stride, feature_set, codes)
        if self.n_windows:
            wl, hl = level_size
            self._tables(
                resize_area(frame_gray, (wl, hl), frame_transposed) if feature_set in ("lbp", "fused") else None,
                resize_area(frame_gray, (2 * wl, 2 * hl), frame_transposed) if feature_set in ("contour", "fused")
                else None, edge_threshold)

    @classmethod
    def of_levels(cls, texture: np.ndarray | None, contour: np.ndarray | None, stride: int, feature_set: str,
                  edge_threshold: float, codes: np.ndarray | None = None) -> "LevelScan":
        """The scan of a texture level and its contour level resized already (twice its size; each None when the
        feature set does not use it): e.g. several canvases' levels side by side, whose windows inside one of them
        see only its pixels."""
        level = texture if texture is not None else contour[::2, ::2]
        height, width = level.shape
        if contour is not None and contour.shape != (2 * height, 2 * width):
            raise FeatureError(f"the contour level must be twice the texture level's {width}x{height}, "
                               f"got {contour.shape[1]}x{contour.shape[0]}")
        scan = cls.__new__(cls)
        scan._setup((width, height), stride, feature_set, codes)
        if scan.n_windows:
            scan._tables(_gray(texture) if feature_set in ("lbp", "fused") else None,
                         _gray(contour) if feature_set in ("contour", "fused") else None, edge_threshold)
        return scan

    def _setup(self, level_size: tuple[int, int], stride: int, feature_set: str, codes: np.ndarray | None) -> None:
        if BLOCK % stride:
            raise FeatureError(f"stride {stride} must divide the block size {BLOCK}")
        feature_range(feature_set)
        codes = None if codes is None else np.asarray(codes)
        self.codes, self.plane_of = _kept_planes(*((None, None) if codes is None else (codes.tobytes(), codes.dtype.str)))
        wl, hl = level_size
        self.stride, self.feature_set = stride, feature_set
        self.level_size = (wl, hl)
        self.rows, self.cols = window_grid((wl, hl), stride)
        self.m_lbp = self.m_contour = None

    def _tables(self, texture: np.ndarray | None, contour: np.ndarray | None, edge_threshold: float) -> None:
        if texture is not None:
            self._texture(texture)
        if contour is not None:
            self._contour(contour, edge_threshold)

    @property
    def n_windows(self) -> int:
        return self.rows * self.cols

    def window_origins(self, windows: np.ndarray | None = None) -> np.ndarray:
        """``(n, 2)`` top-left (x, y) in texture-level pixels of the ``windows`` (flat indices; all of them, row-major,
        by default)."""
        flat = np.arange(self.n_windows) if windows is None else np.asarray(windows, np.int64)
        return grid_origins(*np.divmod(flat, self.cols), self.stride)

    # --- texture: block histograms swept down the level -> kept code planes, per-window maximum (eq. 3)
    def _texture(self, gray_l: np.ndarray) -> None:
        # blocks[plane_of[code], by, bx]: count of the code in the 16x16 block at cell (by, bx), one plane per kept
        # code (the cascade's stumps each read one code across all windows)
        self.blocks, self.m_lbp = _code_planes(lbp_codes(gray_l), self.stride, self.rows, self.cols, self.codes)

    # --- contour: potential maps from prefix sums, per-window maximum over its runs (eq. 4)
    def _contour(self, gray_c: np.ndarray, edge_threshold: float) -> None:
        n, s2 = CONTOUR_SIZE, 2 * self.stride
        y0 = 2 + s2 * np.arange(self.rows)  # window top rows in contour-level pixels
        x0 = 2 + s2 * np.arange(self.cols)
        b = _inner_contour_image(gray_c, float(edge_threshold))
        few_edges = _edge_words(b) <= SPARSE_EDGE_WORDS * (b.size // 8)   # smooth or upsampled levels
        self.px, self.py = (_edge_potentials if few_edges else _swept_potentials)(b, s2, len(y0), len(x0), n)
        self.m_contour = _contour_maxima(self.px, self.py, s2, n, self.rows, self.cols)
        self._y0, self._x0 = y0, x0

    def evaluate(self, stages: PackedStages, last_stage_margin: float = 0.0,
                 windows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Run a cascade on every window of the level (or only on ``windows``, flat indices, passing ones returned in
        their order): ``(passing window indices, last-stage score)``.

        Exactly the test of :meth:`Cascade.evaluate_vectors` on :meth:`vectors` (``255 v_k >= t max``
        in integers), stage by stage over the windows still alive (Viola-Jones' early exit), compiled
        by numba: a rejected window's later features are never read.
        """
        if self.m_lbp is not None and np.any(self.plane_of[stages.codes] < 0):
            missing = stages.codes[self.plane_of[stages.codes] < 0]
            raise FeatureError(f"the cascade reads LBP codes {missing.tolist()} whose planes this scan did not keep")
        empty_i16 = np.zeros((N_CODES, 1, 1), np.int16)   # tables a feature set does not use
        empty_f32, empty_i64 = np.zeros((1, 1), np.float32), np.zeros(1, np.int64)
        return _evaluate_level(
            self.blocks if self.m_lbp is not None else empty_i16, self.plane_of,
            self.px if self.m_contour is not None else empty_f32,
            self.py if self.m_contour is not None else empty_f32,
            self.m_lbp if self.m_lbp is not None else empty_i64,
            self.m_contour if self.m_contour is not None else empty_i64,
            self.rows, self.cols, BLOCK // self.stride,
            self._x0 if self.m_contour is not None else empty_i64,
            self._y0 if self.m_contour is not None else empty_i64,
            np.arange(self.n_windows) if windows is None else self._windows(windows),
            stages.features, stages.thresholds, stages.left, stages.right, stages.ends, stages.stage_thresholds,
            float(last_stage_margin))

    def _windows(self, windows) -> np.ndarray:
        chosen = np.array(windows, np.int64).reshape(-1)        # a copy: the kernel compacts it in place
        if len(chosen) and (chosen.min() < 0 or chosen.max() >= self.n_windows):
            raise FeatureError(f"window indices must lie in 0..{self.n_windows - 1}")
        return chosen

    def vectors(self, windows: np.ndarray) -> np.ndarray:
        """Full normalised 1152-d vectors (uint8, floored) of some windows, for training (a scan keeping every code)."""
        if self.m_lbp is not None and len(self.codes) < N_CODES:
            raise FeatureError("vectors need every code's plane: build the scan with codes=None")
        out = np.zeros((len(windows), FUSED_DIM), np.uint8)
        if len(windows) == 0:
            return out
        r, c = np.divmod(np.asarray(windows), self.cols)
        s = self.stride
        if self.m_lbp is not None:
            raw = np.concatenate([self.blocks[:, r + dy // s, c + dx // s].T for dy, dx in BLOCK_OFFSETS], axis=1)
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


@numba.njit(cache=True, nogil=True)
def _inner_contour_image(g, edge_threshold):
    """:func:`contour_image` of ``g`` with its outermost pixels cleared (they have no full Laplacian
    neighbourhood), in one compiled pass instead of OpenCV's Laplacian, absolute value, threshold and
    four border writes: the same integer 4-neighbour Laplacian ``|l| > edge_threshold`` per pixel against
    ``floor(edge_threshold)`` (the same test for an integer ``l``). Every sum is cast back to int16 (``|l| <= 1020``):
    numba would widen int16 arithmetic to int64, and int16 lanes make the pass 4x faster (session 47, a 902x1392
    level: 0.37 against 1.51 ms); ``|l| > limit`` is tested as ``l > limit or l < -limit`` for the same reason."""
    h, w = g.shape
    b = np.zeros((h, w), np.uint8)
    limit = np.int16(min(max(np.floor(edge_threshold), -1.0), 1020.0))
    below = np.int16(-limit)
    four = np.int16(4)
    for y in range(1, h - 1):
        up, row, down = g[y - 1], g[y], g[y + 1]
        out = b[y]
        for x in range(1, w - 1):
            lap = np.int16(np.int16(np.int16(up[x]) + np.int16(down[x]))
                           + np.int16(np.int16(row[x - 1]) + np.int16(row[x + 1]))
                           - np.int16(four * np.int16(row[x])))
            out[x] = np.uint8((lap > limit) | (lap < below))
    return b


@numba.njit(cache=True, nogil=True)
def _column_potentials(b, step, rows, n, from_bottom):
    """Potentials down every column x of ``b`` for each window top row ``y0 = 2 + step * r`` (``(rows, W)``,
    float32): ``sum_i b(y0+i, x) (n - i)`` (``from_bottom``: ``P_x``, the distance to the window's bottom
    edge) or ``sum_i b(y0+i, x) (i + 1)`` (``P_y`` of the rows of ``b``'s transpose, from its left edge).

    ``b`` is the level's :func:`contour_image` with its outer pixels cleared. With prefix sums over
    ``y' < y`` of ``b`` and ``y' b`` down each column, over rows ``y0 .. y0+n-1`` the first is
    ``(n + y0) sum_Y b - sum_Y Y b`` and the second ``sum_Y Y b - (y0 - 1) sum_Y b``. The prefix sums are
    kept only where windows start and end (every ``step`` rows, as ``n`` is a multiple). Between two of those the
    rows are swept in chunks of at most 16, each row across all its columns without a test per pixel, into uint8
    sums of the chunk's count and of ``i`` times it (``i`` the row within the chunk: at most 120), 32 columns to an
    AVX2 instruction; the int64 prefix takes each chunk once as ``count`` and ``chunk_start * count + i-sum``
    (session 47: 0.6x the time of int32 sums on a 902x1392 contour level).
    """
    height, width = b.shape
    marks = rows + n // step                 # prefix rows 2, 2 + step, ...
    col_sum = np.zeros((marks, width), np.int32)     # counts <= height
    col_ysum = np.zeros((marks, width), np.int64)
    run, yrun = np.zeros(width, np.int32), np.zeros(width, np.int64)
    part, ipart = np.zeros(width, np.uint8), np.zeros(width, np.uint8)   # a chunk's count <= 16, i-sum <= 120
    y = 0
    for k in range(marks):                   # prefix rows 2 + step k (a window may end at the last row)
        end = min(2 + step * k, height)
        while y < end:
            chunk_start, chunk_end = y, min(end, y + 16)
            part[:] = 0
            ipart[:] = 0
            while y < chunk_end:
                line = b[y]
                i = np.uint8(y - chunk_start)
                for x in range(width):
                    v = line[x]
                    part[x] = np.uint8(part[x] + v)
                    ipart[x] = np.uint8(ipart[x] + np.uint8(i * v))
                y += 1
            for x in range(width):
                run[x] += part[x]
                yrun[x] += chunk_start * np.int64(part[x]) + ipart[x]
        col_sum[k] = run
        col_ysum[k] = yrun
    out = np.empty((rows, width), np.float32)
    for r in range(rows):
        top = 2 + step * r
        # out = a * count + b * ysum (the branch stays out of the loop)
        a, b_ = (n + top, -1) if from_bottom else (1 - top, 1)
        count_top, count_end = col_sum[r], col_sum[r + n // step]
        ysum_top, ysum_end = col_ysum[r], col_ysum[r + n // step]
        line = out[r]
        for x in range(width):
            line[x] = a * np.int64(count_end[x] - count_top[x]) + b_ * (ysum_end[x] - ysum_top[x])
    return out


def _swept_potentials(b: np.ndarray, step: int, rows: int, cols: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``P_x`` ``(rows, W)`` and ``P_y`` ``(H, cols)`` of every window (window top rows / left columns ``2 + step k``)
    by :func:`_column_potentials`: ``P_x`` down the columns of ``b``, ``P_y`` down the columns of ``b`` transposed
    (its rows), the same sweep, which runs across a whole row at once (2x faster on the rows than sweeping along
    each row); ``P_y`` kept ``(H, cols)``, neighbouring windows' values side by side."""
    px = _column_potentials(b, step, rows, n, True)
    return px, np.ascontiguousarray(_column_potentials(cv2.transpose(b), step, cols, n, False).T)


@numba.njit(cache=True, nogil=True)
def _edge_words(b):
    """How many of the 8-byte words of ``b`` (C-contiguous; its last ``size % 8`` bytes not counted) hold an edge
    pixel: the sparse path's cost goes with them."""
    flat = b.ravel()
    words = flat[:flat.size // 8 * 8].view(np.uint64)
    count = 0
    for i in range(len(words)):
        count += words[i] != 0
    return count


@numba.njit(cache=True, nogil=True)
def _edge_potentials(b, step, rows, cols, n):
    """:func:`_swept_potentials`' ``P_x`` ``(rows, W)`` and ``P_y`` ``(H, cols)`` of a ``b`` with few edge pixels, from
    the edge pixels alone: each adds itself (and its row or column) to the prefix mark it first counts in, ``2 + step
    k`` being the first mark beyond it, and the marks are then summed up; the potentials are the same differences of
    prefix sums (the same integers). ``b`` is C-contiguous; it is read eight
    pixels to a word, so that a blank word costs one test. On the UAV set-up's levels (0.2 % of the pixels edges:
    smooth and upsampled) twice as fast as the two sweeps and the transpose (session 50: 11 against 23 ms a frame); its
    cost grows with the edges, past theirs when about an eighth of the words hold one (:data:`SPARSE_EDGE_WORDS`)."""
    height, width = b.shape
    per = n // step
    marks_r, marks_c = rows + per, cols + per
    count_r = np.zeros((marks_r + 1, width), np.int32)   # [mark, column]: the pixels first counted at that mark
    sum_r = np.zeros((marks_r + 1, width), np.int64)     # ... and their rows' sum (the last slot: beyond all marks)
    count_c = np.zeros((marks_c + 1, height), np.int32)  # [mark, row]: the same along the rows
    sum_c = np.zeros((marks_c + 1, height), np.int64)
    first_c = np.empty(width, np.int64)
    for x in range(width):
        first_c[x] = min(0 if x < 2 else (x - 2) // step + 1, marks_c)
    flat = b.ravel()
    whole = flat.size // 8
    words = flat[:whole * 8].view(np.uint64)
    y, row_end = 0, width
    for i in range(whole + 1):
        if i < whole:
            if words[i] == 0:
                continue
            lo, hi = 8 * i, 8 * i + 8
        else:
            lo, hi = 8 * whole, flat.size
        for p in range(lo, hi):
            if flat[p]:
                while p >= row_end:
                    row_end += width
                    y += 1
                x = p - (row_end - width)
                kr, kc = min(0 if y < 2 else (y - 2) // step + 1, marks_r), first_c[x]
                count_r[kr, x] += 1
                sum_r[kr, x] += y
                count_c[kc, y] += 1
                sum_c[kc, y] += x
    for k in range(1, marks_r):
        for x in range(width):
            count_r[k, x] += count_r[k - 1, x]
            sum_r[k, x] += sum_r[k - 1, x]
    for k in range(1, marks_c):
        for y in range(height):
            count_c[k, y] += count_c[k - 1, y]
            sum_c[k, y] += sum_c[k - 1, y]
    px = np.empty((rows, width), np.float32)
    for r in range(rows):                    # sum_i b (n - i) over rows 2 + step r ..: (n + top) count - row sum
        a = n + 2 + step * r
        for x in range(width):
            px[r, x] = a * np.int64(count_r[r + per, x] - count_r[r, x]) - (sum_r[r + per, x] - sum_r[r, x])
    py = np.empty((height, cols), np.float32)
    for c in range(cols):                    # sum_j b (j + 1) over columns 2 + step c ..: column sum - (left - 1) count
        a = 1 - (2 + step * c)
        for y in range(height):
            py[y, c] = a * np.int64(count_c[c + per, y] - count_c[c, y]) + (sum_c[c + per, y] - sum_c[c, y])
    return px, py


@numba.njit(cache=True, nogil=True)
def _contour_maxima(px, py, step, n, rows, cols):
    """Eq. 4's maximum of every window: the largest of its ``P_x`` (``px[row, x0 .. x0 + n - 1]``) and its
    ``P_y`` (``py[y0 .. y0 + n - 1, col]``), ``x0 = 2 + step * col``, ``y0 = 2 + step * row``, as int64.

    Windows start every ``step`` pixels and span ``n / step`` such runs, so each run's maximum is taken
    once and a window's is the largest of its runs' (only the windows' own positions, not a sliding
    maximum at every pixel)."""
    per = n // step
    run_x = np.empty((rows, cols + per - 1), np.float32)
    for r in range(rows):
        for j in range(cols + per - 1):
            start = 2 + step * j
            top = px[r, start]
            for x in range(start + 1, start + step):
                top = px[r, x] if px[r, x] > top else top
            run_x[r, j] = top
    run_y = np.empty((rows + per - 1, cols), np.float32)
    for j in range(rows + per - 1):
        start = 2 + step * j
        run_y[j] = py[start]
        for y in range(start + 1, start + step):
            for c in range(cols):
                run_y[j, c] = py[y, c] if py[y, c] > run_y[j, c] else run_y[j, c]
    out = np.empty(rows * cols, np.int64)
    for r in range(rows):
        for c in range(cols):
            top = run_x[r, c]
            for q in range(per):
                top = max(top, run_x[r, c + q], run_y[r + q, c])
            out[r * cols + c] = np.int64(top)
    return out


@numba.njit(cache=True, nogil=True)
def _code_planes(codes, cell, rows, cols, kept):
    """The 16x16 blocks' code histograms, as planes of the ``kept`` codes only, and each window's largest bin (eq. 3's
    maximum, over all 256 codes): ``(planes, m_lbp)`` with ``planes[k, by, bx]`` (int16) the count of code ``kept[k]``
    in the block whose top-left ``cell x cell`` cell is (by, bx), and ``m_lbp[row * cols + col]`` (int64) the largest
    bin of the four blocks of the window at cell (row, col).

    One sweep down the level, a block row at a time, holding only one histogram per column of cells (``cell`` wide,
    16 tall): moving down a block row takes a cell's pixels out of each and puts the next cell's in (neighbouring
    columns' counts interleaved, so that no increment waits for the last one's store when a code repeats); along the
    row, a block is the previous one plus the column entering minus the column leaving, 256 adjacent int16 bins at a
    time, its maximum taken there and only its ``kept`` bins stored. Integer counts, so exactly the direct sums. A
    cascade reads few codes (the drone-view model 62, the UAV model 81). Against building every block's 256 bins in
    memory and transposing them into planes (session 46's kernel), on a 640x480 drone-view level at stride 4: 2.8 against
    8.0 ms; on the UAV set-up's finest level at stride 8, where that kernel's cells were 4x fewer: 1.02 against 1.02 ms
    (session 47)."""
    hc, wc = codes.shape[0] // cell, codes.shape[1] // cell
    per = BLOCK // cell
    hb, wb = hc - per + 1, wc - per + 1
    planes = np.empty((len(kept), hb, wb), np.int16)
    block_max = np.empty((hb, wb), np.int16)
    columns = np.zeros((wc, N_CODES), np.int16)       # the current block row's histogram of each column of cells
    one = np.int16(1)
    for y in range(BLOCK):
        line = codes[y]
        for j in range(cell):
            for cx in range(wc):
                columns[cx, line[cx * cell + j]] += one
    block = np.empty(N_CODES, np.int16)
    row_bins = np.empty((wb, N_CODES), np.int16)        # the block row's histograms, stored plane by plane after
    for by in range(hb):
        if by > 0:                                      # one cell row leaves the columns, the next one enters
            for y in range((by - 1) * cell, by * cell):
                line = codes[y]
                for j in range(cell):
                    for cx in range(wc):
                        columns[cx, line[cx * cell + j]] -= one
            for y in range((by - 1) * cell + BLOCK, by * cell + BLOCK):
                line = codes[y]
                for j in range(cell):
                    for cx in range(wc):
                        columns[cx, line[cx * cell + j]] += one
        for k in range(N_CODES):
            block[k] = columns[0, k]
        for q in range(1, per):
            column = columns[q]
            for k in range(N_CODES):
                block[k] = np.int16(block[k] + column[k])   # int16 sums (numba would widen them: 4x narrower lanes)
        for bx in range(wb):
            if bx > 0:
                entering, leaving = columns[bx + per - 1], columns[bx - 1]
                for k in range(N_CODES):
                    block[k] = np.int16(np.int16(block[k] + entering[k]) - leaving[k])
            top = block[0]
            for k in range(1, N_CODES):
                top = max(top, block[k])
            block_max[by, bx] = top
            row_bins[bx] = block
        for k in range(len(kept)):      # one plane at a time: its stores run along the row (2x faster than by block)
            code, out = kept[k], planes[k, by]
            for bx in range(wb):
                out[bx] = row_bins[bx, code]
    m_lbp = np.empty(rows * cols, np.int64)
    for r in range(rows):                      # the window's blocks: BLOCK_OFFSETS, ``per`` cells apart
        for c in range(cols):
            m_lbp[r * cols + c] = max(max(block_max[r, c], block_max[r, c + per]),
                                      max(block_max[r + per, c], block_max[r + per, c + per]))
    return planes, m_lbp


@numba.njit(cache=True, nogil=True)
def _evaluate_level(blocks, plane_of, px, py, m_lbp, m_contour, rows, cols, cells_per_block, x0, y0, alive,
                    features, thresholds, left, right, ends, stage_thresholds, last_stage_margin):
    """The cascade over the windows ``alive`` of a level (flat indices; see :meth:`LevelScan.evaluate`).

    Stump j reads raw feature ``features[j]`` of a window: texture bin (block, code) from
    ``blocks[plane_of[code]]``, contour potential ``P_x(k)`` from ``px`` or ``P_y(k)`` from ``py``; it tests
    ``255 * value >= thresholds[j] * max`` (eqs. 3-4 without a division) and adds ``right[j]`` when
    it passes, else ``left[j]``. Stage s spans stumps ``ends[s-1] .. ends[s]-1`` and keeps the windows
    whose sum reaches its threshold. Stump by stump over the surviving windows, so that each stump
    streams through one table plane. Each surviving window carries its flat offsets into the three
    tables and its two maxima (as floats), compacted after every stage: the stump loop then reads
    ``table[offset + feature shift]`` without a division per window and stump. The test is in int32: raw
    values and maxima are whole numbers (bins <= 256, potentials <= 2080) and a threshold outside
    [0, 256] decides as 0 or 256 do (a value never exceeds its maximum), so ``255 * value`` and
    ``t * max`` stay far below 2^31 and are exact, as they were in float64. A stump adds ``pair[test]``, its
    (left, right) indexed by the test's 0 or 1: the tests are as often true as false, and a branch on them
    was mispredicted about half the time (session 47: 1.75x faster over a UAV frame's 32 levels, same bits).
    """
    n = len(alive)                       # the windows to run it on (flat indices, compacted in place)
    bw, pxw, pyw = blocks.shape[2], px.shape[1], py.shape[1]
    base_l = np.empty(n, np.int64)       # blocks[code].flat offset of the window's top-left block
    base_x = np.empty(n, np.int64)       # px.flat offset of (row, x0[col])
    base_y = np.empty(n, np.int64)       # py.flat offset of (y0[row], col)
    ml = np.empty(n, np.int32)
    mc = np.empty(n, np.int32)
    for a in range(n):
        w = alive[a]
        r, c = w // cols, w % cols
        base_l[a] = r * bw + c
        base_x[a] = r * pxw + x0[c] if len(x0) == cols else 0
        base_y[a] = y0[r] * pyw + c if len(y0) == rows else 0
        ml[a] = m_lbp[w] if len(m_lbp) == rows * cols else 0
        mc[a] = m_contour[w] if len(m_contour) == rows * cols else 0
    flat_px, flat_py = px.ravel(), py.ravel()
    plane_size = blocks.shape[1] * bw
    flat_blocks = blocks.ravel()
    score = np.zeros(n)
    full = np.int32(255)
    pair = np.empty(2)                   # a stump's (left, right): picked by its test, with no branch
    start = 0
    for s in range(len(ends)):
        m = len(alive)
        if m == 0:
            break
        total = np.zeros(m)
        for j in range(start, ends[s]):
            f, t = features[j], np.int32(min(max(thresholds[j], 0), 256))
            pair[0], pair[1] = left[j], right[j]
            if f < LBP_DIM:
                shift = plane_of[f % N_CODES] * plane_size + (f // N_CODES // 2) * cells_per_block * bw \
                    + (f // N_CODES % 2) * cells_per_block
                for a in range(m):
                    mx = ml[a]
                    value = np.int32(flat_blocks[base_l[a] + shift])
                    total[a] += pair[np.int64(mx > 0) & np.int64(full * value >= t * mx)]
            elif f < LBP_DIM + CONTOUR_SIZE:
                k = f - LBP_DIM
                for a in range(m):
                    mx = mc[a]
                    value = np.int32(flat_px[base_x[a] + k])
                    total[a] += pair[np.int64(mx > 0) & np.int64(full * value >= t * mx)]
            else:
                k = (f - LBP_DIM - CONTOUR_SIZE) * pyw
                for a in range(m):
                    mx = mc[a]
                    value = np.int32(flat_py[base_y[a] + k])
                    total[a] += pair[np.int64(mx > 0) & np.int64(full * value >= t * mx)]
        bar = last_stage_margin if s == len(ends) - 1 else 0.0
        kept = 0
        for a in range(m):               # compact the survivors and their offsets in place, in order
            sc = total[a] - stage_thresholds[s]
            if sc >= bar:
                alive[kept], score[kept] = alive[a], sc
                base_l[kept], base_x[kept], base_y[kept] = base_l[a], base_x[a], base_y[a]
                ml[kept], mc[kept] = ml[a], mc[a]
                kept += 1
        alive = alive[:kept]
        start = ends[s]
    return alive, score[:len(alive)]
