"""Box regression of the cascade's groups from their member windows (pure: numpy, numba): the UAV set-up's third step.

A group's box is the mean of its member windows. On the UAV scenes that box is often off the vehicle's
upright box (issue 12, tuning seeds 2000-2011 / 2100-2105 at the set-up of session 8: of 406 missed
vehicles, 164 had a group or a detection on them at IoU 0.3-0.5 only): the windows of a turned view map
back as the upright boxes of turned windows, some groups hold windows on half a vehicle (the box too small,
area 0.35-0.65 of the truth), some reach into the ground beside it (area 2-2.5). Where the members lie
tells which: a ridge regression (least squares with an L2 penalty on the standardised weights) predicts
each edge's offset from the member windows' statistics,

    offsets = ((f - mean) / std) @ W        (4 columns: left, right, top, bottom edge, in box widths / heights)

with ``f`` = :data:`FEATURES` of the group: its log window count, log summed margins, best margin, the
mean box's log aspect and log area, the 10th / 90th percentile and the extreme member edges, the
margin-weighted mean edges (each relative to the mean box's edge, in its width or height), the spread of
the members' centres and aspects, and whether the mean box touches each frame border. Trained by
``tools/train_uav_box_regressor.py`` on the training scenes' groups that overlap a counted vehicle by IoU
>= 0.3; the model file is JSON.

**Image stages** (version 2 files, issue 12 session 13): the member windows never look at the image, and a nadir
vehicle is a compact blob with a strong outline against the ground. Bounding-box regression in the manner of
R-CNN (Girshick et al. 2014, appendix C: ridge regression of the box's correction from features of the proposal's
image region, applied again to its own output) moves each box once more, in ``stages`` applied in turn, each a
ridge regression of :func:`edge_offsets` on :func:`image_features` of the box's region (grown ``grow`` times about
its centre, resampled to ``size`` x ``size`` pixels) followed by the group's :data:`FEATURES`: the colour
gradient profiles along x and y, the profiles of the colour distance from the region's rim (the ground's colour),
and where those profiles' mass and peaks lie, in the box's own coordinates. The detector applies them to the
groups its verifier accepts (published low-confidence ones included), after the verifier read its colour in the
member-statistics box, so the verifier's input is unchanged.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numba
import numpy as np

from multi_target_tracker.verifier import check_json_model, load_json_model

BOX_REGRESSOR_FORMAT = "aircraft_docking_tracker/group-box-regressor"
BOX_REGRESSOR_VERSION = 2        # 2: with image stages (version 1 files, without them, still load)
FEATURES = ("bias", "log_count", "log_margin_sum", "best_margin", "log_aspect", "log_area_8",
            "p10_left", "p90_right", "p10_top", "p90_bottom", "min_left", "max_right", "min_top", "max_bottom",
            "centre_x_spread", "centre_y_spread", "aspect_spread", "mean_abs_log_aspect",
            "weighted_left", "weighted_right", "weighted_top", "weighted_bottom",
            "at_left_border", "at_top_border", "at_right_border", "at_bottom_border")
BORDER_PX = 2.0
PROFILE_QUANTILES = (0.05, 0.1, 0.2, 0.5, 0.8, 0.9, 0.95)


def image_feature_names(size: int) -> tuple[str, ...]:
    """The names of :func:`image_features`' columns for a ``size`` x ``size`` region."""
    profiles = tuple(f"{kind}_{k}" for kind in ("grad_x", "grad_y", "contrast_x", "contrast_y") for k in range(size))
    quantiles = tuple(f"{kind}_q{int(q * 100)}" for kind in ("contrast_x", "contrast_y", "grad_x", "grad_y")
                      for q in PROFILE_QUANTILES)
    return profiles + quantiles + ("grad_x_peak_left", "grad_x_peak_right", "grad_y_peak_top", "grad_y_peak_bottom",
                                   "log_contrast", "log_gradient")


class BoxRegressorError(ValueError):
    """A box regressor model file or input that cannot be used."""


def percentile(values: np.ndarray, q: float):
    """``np.percentile(values, q)`` (its default linear method) of a float array, flattened: the same bits and dtype,
    NaN where NumPy gives NaN, without its general machinery (about 100 us a call against a few here: the box
    regressor takes four a group and two a box and stage). NumPy's steps: the virtual index ``(n - 1) q / 100``, its
    floor ``i`` and fraction ``g`` (from ``n - 1`` on ``i = -1``: the last value twice), the values partitioned at
    0, -1, ``i`` and ``i + 1`` (the same partition, so equal values, zeros of either sign, land where NumPy puts
    them), then ``a + (b - a) g``, or ``b - (b - a)(1 - g)`` when ``g >= 0.5`` (in the array's dtype); NaN if the
    largest is."""
    values = np.asarray(values).reshape(-1)
    n = len(values)
    if n == 0:
        raise BoxRegressorError("the percentile of no values")
    index = (n - 1) * (q / 100)
    below = math.floor(index) if index < n - 1 else -1
    above = below + 1 if below >= 0 else -1
    ordered = np.partition(values, np.unique([0, -1, below, above]))
    if np.isnan(ordered[-1]):
        return ordered[-1]
    a, b = ordered[below], ordered[above]
    fraction, kind = index - below, ordered.dtype.type
    return b - (b - a) * kind(1 - fraction) if fraction >= 0.5 else a + (b - a) * kind(fraction)


def column_medians(values: np.ndarray) -> np.ndarray:
    """``np.median(values, axis=0)`` of a 2-D float array with at least one row, the same bits: NumPy's partition
    (the middle one or two rows and the last), then its mean of the middle one or two, summed from 0 in the array's
    dtype (so a zero comes out +0) and divided by their count; NaN in a column whose largest value is NaN."""
    half = len(values) // 2
    middle = [half - 1, half] if len(values) % 2 == 0 else [half]
    ordered = np.partition(values, middle + [-1], axis=0)
    kind = ordered.dtype.type
    total = kind(0) + ordered[middle[0]]
    if len(middle) == 2:
        total = total + ordered[middle[1]]
    medians = total / kind(len(middle))
    medians[np.isnan(ordered[-1])] = np.nan
    return medians


def member_features(boxes: np.ndarray, margins: np.ndarray, label: np.ndarray, groups: np.ndarray,
                    group_boxes: np.ndarray, margin_floor: float, frame_size: tuple[int, int]) -> np.ndarray:
    """``(len(groups), len(FEATURES))``: the statistics of each group's member windows.

    ``boxes`` / ``margins`` / ``label``: every window (x, y, w, h), its last-stage margin and its group label
    (``detector.group_members``); ``groups``: the labels to describe, ``group_boxes`` their mean boxes;
    ``margin_floor``: the window margin the summed margins are counted above; ``frame_size``: (width, height).
    """
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    margins = np.asarray(margins, np.float64).reshape(-1)
    group_boxes = np.asarray(group_boxes, np.float64).reshape(-1, 4)
    out = np.zeros((len(groups), len(FEATURES)))
    if len(groups) == 0:
        return out
    order = np.argsort(label, kind="stable")
    starts = np.searchsorted(label[order], groups)
    ends = np.searchsorted(label[order], groups, side="right")
    if np.any(ends <= starts):
        raise BoxRegressorError(f"group {groups[np.argmax(ends <= starts)]} has no member windows")
    _member_statistics(boxes, margins, order, starts, ends, group_boxes, float(margin_floor), float(frame_size[0]),
                       float(frame_size[1]), BORDER_PX, out)
    return out


@numba.njit(cache=True, nogil=True)
def _linear_percentile(ordered, q):
    """``np.percentile(values, q)`` (linear) of ``ordered``, the values sorted: :func:`percentile`'s steps, the same
    bits."""
    n = len(ordered)
    index = (n - 1) * (q / 100)
    if index >= n - 1:
        return ordered[n - 1]
    below = math.floor(index)
    a, b = ordered[below], ordered[below + 1]
    fraction = index - below
    return b - (b - a) * (1 - fraction) if fraction >= 0.5 else a + (b - a) * fraction


@numba.njit(cache=True, nogil=True)
def _spread(values):
    """The population standard deviation (two passes, as NumPy's ``std``)."""
    mean = values.sum() / len(values)
    total = 0.0
    for v in values:
        total += (v - mean) * (v - mean)
    return math.sqrt(total / len(values))


@numba.njit(cache=True, nogil=True)
def _member_statistics(boxes, margins, order, starts, ends, group_boxes, margin_floor, width, height, border, out):
    """:func:`member_features` of each group ``k`` (members ``order[starts[k]:ends[k]]``) into ``out[k]``, in
    :data:`FEATURES` order. One compiled pass: the same statistics as NumPy calls, about 230 us a group and 9 ms a UAV
    frame (session 48); the percentiles and extremes have the same bits, the sums and dot products their own order."""
    for k in range(len(starts)):
        members = order[starts[k]:ends[k]]
        n = len(members)
        mb, mm = boxes[members], margins[members]
        above = np.maximum(mm - margin_floor, 0.0)
        mass = above.sum()
        weight = above / mass if mass > 0 else np.full(n, 1.0 / n)
        gx, gy = group_boxes[k, 0], group_boxes[k, 1]
        gw, gh = max(group_boxes[k, 2], 1e-6), max(group_boxes[k, 3], 1e-6)
        x0, y0 = mb[:, 0].copy(), mb[:, 1].copy()
        x1, y1 = mb[:, 0] + mb[:, 2], mb[:, 1] + mb[:, 3]
        aspect = np.log(np.maximum(mb[:, 2], 1e-6) / np.maximum(mb[:, 3], 1e-6))
        f = out[k]
        f[0], f[1], f[2], f[3] = 1.0, math.log(n), math.log1p(mass), mm.max()
        f[4], f[5] = math.log(gw / gh), math.log(gw * gh) / 8
        f[10], f[11] = (x0.min() - gx) / gw, (x1.max() - gx - gw) / gw
        f[12], f[13] = (y0.min() - gy) / gh, (y1.max() - gy - gh) / gh
        f[14], f[15] = _spread((x0 + x1) / 2) / gw, _spread((y0 + y1) / 2) / gh
        f[16], f[17] = _spread(aspect), np.abs(aspect).sum() / n
        f[18], f[19] = ((weight * x0).sum() - gx) / gw, ((weight * x1).sum() - gx - gw) / gw
        f[20], f[21] = ((weight * y0).sum() - gy) / gh, ((weight * y1).sum() - gy - gh) / gh
        f[22], f[23] = 1.0 if gx < border else 0.0, 1.0 if gy < border else 0.0
        f[24] = 1.0 if gx + gw > width - border else 0.0
        f[25] = 1.0 if gy + gh > height - border else 0.0
        x0.sort(), x1.sort(), y0.sort(), y1.sort()
        f[6], f[7] = (_linear_percentile(x0, 10) - gx) / gw, (_linear_percentile(x1, 90) - gx - gw) / gw
        f[8], f[9] = (_linear_percentile(y0, 10) - gy) / gh, (_linear_percentile(y1, 90) - gy - gh) / gh


def region_patch(bgr: np.ndarray, box, grow: float, size: int) -> np.ndarray:
    """``(size, size, 3)`` float32: the region of ``box`` (x, y, w, h) grown ``grow`` times about its centre,
    resampled bilinearly after a Gaussian blur against aliasing (sigma 0.4 of the sampling step); the image
    reflected beyond its border."""
    x, y, w, h = (float(v) for v in box)
    rw, rh = grow * max(w, 1.0), grow * max(h, 1.0)
    x0, y0 = x + w / 2 - rw / 2, y + h / 2 - rh / 2
    sx, sy = rw / size, rh / size
    ix0, iy0 = int(math.floor(x0)) - 3, int(math.floor(y0)) - 3
    ix1, iy1 = int(math.ceil(x0 + rw)) + 3, int(math.ceil(y0 + rh)) + 3
    height, width = bgr.shape[:2]
    top, left = min(max(iy0, 0), height - 1), min(max(ix0, 0), width - 1)
    bottom, right = max(min(iy1, height), top + 1), max(min(ix1, width), left + 1)
    crop = bgr[top:bottom, left:right]
    pads = (top - iy0, iy1 - bottom, left - ix0, ix1 - right)
    if any(pads):
        crop = cv2.copyMakeBorder(crop, *(max(p, 0) for p in pads), cv2.BORDER_REFLECT)
    ix0, iy0 = left - max(pads[2], 0), top - max(pads[0], 0)
    crop = crop.astype(np.float32)
    if sx > 1.2 or sy > 1.2:
        crop = cv2.GaussianBlur(crop, (0, 0), sigmaX=max(0.4 * sx, 0.3), sigmaY=max(0.4 * sy, 0.3))
    ox, oy = x0 - ix0, y0 - iy0
    m = np.array([[sx, 0.0, ox + 0.5 * sx - 0.5], [0.0, sy, oy + 0.5 * sy - 0.5]])
    return cv2.warpAffine(crop, m, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REFLECT)


def _mass_positions(profile: np.ndarray) -> np.ndarray:
    """Where the cumulative mass of ``profile`` reaches each of :data:`PROFILE_QUANTILES` (0-1 along it)."""
    c = np.cumsum(profile)
    c = c / max(c[-1], 1e-9)
    return np.searchsorted(c, PROFILE_QUANTILES).astype(np.float64) / len(profile)


def image_features(bgr: np.ndarray, boxes: np.ndarray, grow: float, size: int) -> np.ndarray:
    """``(len(boxes), len(image_feature_names(size)))``: what the image shows of each box's region
    (:func:`region_patch`): the largest-channel |Sobel| x / y gradients averaged over the box's own rows / columns
    (profiles along x / y), the same profiles of the colour distance from the region's rim (median colour of its
    outer pixels: the ground), each set scaled by its mean; where each profile's mass reaches
    :data:`PROFILE_QUANTILES` (the contrast profiles less their 20th percentile) and the gradient peaks in each half,
    in the box's own coordinates (0 its left / top edge, 1 its right / bottom edge); the logs of the two scales."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    inner = int(round(size * (1 - 1 / grow) / 2))
    band = slice(inner, size - inner)
    rim = np.ones((size, size), bool)
    m = max(2, inner // 2)
    rim[m:size - m, m:size - m] = False
    half = size // 2
    out = np.zeros((len(boxes), 4 * size + 4 * len(PROFILE_QUANTILES) + 6))
    for k, box in enumerate(boxes):
        patch = region_patch(bgr, box, grow, size)
        gx = np.abs(cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3)).max(axis=2)
        gy = np.abs(cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3)).max(axis=2)
        contrast = np.sqrt(((patch - column_medians(patch[rim])) ** 2).sum(axis=2))
        px_g, py_g = gx[band].mean(axis=0), gy[:, band].mean(axis=1)
        px_d, py_d = contrast[band].mean(axis=0), contrast[:, band].mean(axis=1)
        sc, sg = max(px_d.mean() + py_d.mean(), 1.0), max(px_g.mean() + py_g.mean(), 1.0)
        positions = np.concatenate([
            _mass_positions(np.maximum(px_d - percentile(px_d, 20), 0)),
            _mass_positions(np.maximum(py_d - percentile(py_d, 20), 0)), _mass_positions(px_g),
            _mass_positions(py_g), [np.argmax(px_g[:half]) / size, (half + np.argmax(px_g[half:])) / size,
                                    np.argmax(py_g[:half]) / size, (half + np.argmax(py_g[half:])) / size]])
        out[k] = np.concatenate([px_g / sg, py_g / sg, px_d / sc, py_d / sc, positions * grow - (grow - 1) / 2,
                                 [math.log(sc), math.log(sg)]])
    return out


def image_stage_features(bgr: np.ndarray, boxes: np.ndarray, member: np.ndarray, grow: float, size: int) -> np.ndarray:
    """An image stage's rows: a bias, :func:`image_features` of ``boxes`` and the groups' ``member`` statistics
    (their :data:`FEATURES` rows without the bias)."""
    member = np.asarray(member, np.float64).reshape(-1, len(FEATURES))
    return np.column_stack([np.ones(len(member)), image_features(bgr, boxes, grow, size), member[:, 1:]])


@dataclass
class ImageStage:
    """One image stage: the region's ``grow`` and ``size``, standardisation and ridge weights over
    :func:`image_features` followed by :data:`FEATURES` (bias first, as in :class:`BoxRegressor`)."""

    grow: float
    size: int
    mean: np.ndarray
    std: np.ndarray
    weights: np.ndarray

    def names(self) -> tuple[str, ...]:
        return ("bias",) + image_feature_names(self.size) + FEATURES[1:]

    def features(self, bgr: np.ndarray, boxes: np.ndarray, member: np.ndarray) -> np.ndarray:
        return image_stage_features(bgr, boxes, member, self.grow, self.size)

    def refine(self, bgr: np.ndarray, boxes: np.ndarray, member: np.ndarray) -> np.ndarray:
        return apply_offsets(boxes, ((self.features(bgr, boxes, member) - self.mean) / self.std) @ self.weights)

    def to_dict(self) -> dict:
        return {"grow": self.grow, "size": self.size, "features": list(self.names()), "mean": self.mean.tolist(),
                "std": self.std.tolist(), "weights": self.weights.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "ImageStage":
        try:
            grow, size = float(d["grow"]), int(d["size"])
            if not (1.0 <= grow <= 4.0 and 8 <= size <= 128):
                raise ValueError(f"grow {grow} outside [1, 4] or size {size} outside [8, 128]")
            stage = cls(grow, size, *(np.asarray(d[k], np.float64) for k in ("mean", "std", "weights")))
            names = stage.names()
            if list(d["features"]) != list(names):
                raise ValueError("features are not image_feature_names(size) followed by FEATURES")
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise BoxRegressorError(f"malformed image stage ({type(exc).__name__}: {exc})") from None
        n = len(names)
        if stage.mean.shape != (n,) or stage.std.shape != (n,) or stage.weights.shape != (n, 4):
            raise BoxRegressorError(f"an image stage needs mean and std of {n} values, weights {n} x 4")
        if not (np.isfinite(stage.mean).all() and np.isfinite(stage.std).all() and np.isfinite(stage.weights).all()) \
                or (stage.std <= 0).any():
            raise BoxRegressorError("an image stage holds a non-finite number or a std <= 0")
        return stage


def edge_offsets(boxes: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``(n, 4)`` offsets of ``truth``'s left, right, top, bottom edges from ``boxes``' (in the boxes' widths /
    heights): the regression's targets."""
    b, t = np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(truth, np.float64).reshape(-1, 4)
    w, h = np.maximum(b[:, 2], 1e-6), np.maximum(b[:, 3], 1e-6)
    return np.column_stack([(t[:, 0] - b[:, 0]) / w, (t[:, 0] + t[:, 2] - b[:, 0] - b[:, 2]) / w,
                            (t[:, 1] - b[:, 1]) / h, (t[:, 1] + t[:, 3] - b[:, 1] - b[:, 3]) / h])


def apply_offsets(boxes: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """``boxes`` with their edges moved by ``offsets`` (:func:`edge_offsets`' inverse); at least 1 px wide and high."""
    b, d = np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(offsets, np.float64).reshape(-1, 4)
    x0, x1 = b[:, 0] + d[:, 0] * b[:, 2], b[:, 0] + b[:, 2] + d[:, 1] * b[:, 2]
    y0, y1 = b[:, 1] + d[:, 2] * b[:, 3], b[:, 1] + b[:, 3] + d[:, 3] * b[:, 3]
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    w, h = np.maximum(x1 - x0, 1.0), np.maximum(y1 - y0, 1.0)
    return np.column_stack([cx - w / 2, cy - h / 2, w, h])


@dataclass
class BoxRegressor:
    """A ridge regression of :func:`edge_offsets` on :data:`FEATURES`: standardisation and weights (n x 4); and
    optionally the :class:`ImageStage` s applied after it (:meth:`refine_image`)."""

    mean: np.ndarray
    std: np.ndarray
    weights: np.ndarray
    info: dict = field(default_factory=dict)
    image_stages: list = field(default_factory=list)

    def offsets(self, features: np.ndarray) -> np.ndarray:
        features = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
        return ((features - self.mean) / self.std) @ self.weights

    def refine(self, group_boxes: np.ndarray, features: np.ndarray) -> np.ndarray:
        """The groups' boxes with each edge moved by the predicted offset."""
        return apply_offsets(group_boxes, self.offsets(features))

    def refine_image(self, bgr: np.ndarray, boxes: np.ndarray, features: np.ndarray) -> np.ndarray:
        """``boxes`` (those :meth:`refine` gave) moved by each image stage in turn, reading ``bgr``; ``features``
        the groups' :data:`FEATURES` rows. Without image stages ``boxes`` as they are."""
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        for stage in self.image_stages if len(boxes) else ():
            boxes = stage.refine(bgr, boxes, features)
        return boxes

    def to_dict(self) -> dict:
        d = {"format": BOX_REGRESSOR_FORMAT, "version": BOX_REGRESSOR_VERSION if self.image_stages else 1,
             "features": list(FEATURES), "mean": self.mean.tolist(), "std": self.std.tolist(),
             "weights": self.weights.tolist(), "info": self.info}
        if self.image_stages:
            d["image_stages"] = [stage.to_dict() for stage in self.image_stages]
        return d

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def from_dict(cls, d: dict) -> "BoxRegressor":
        """A regressor from its JSON form; refuses another format, other features, non-finite numbers."""
        version = d.get("version") if isinstance(d, dict) and d.get("version") in (1, BOX_REGRESSOR_VERSION) else \
            BOX_REGRESSOR_VERSION
        check_json_model(d, BOX_REGRESSOR_FORMAT, version, FEATURES, BoxRegressorError, "box regressor")
        stages = d.get("image_stages", [])
        if (version == 1) != (not stages) or not isinstance(stages, list):
            raise BoxRegressorError("a version 2 box regressor needs image stages, a version 1 one has none")
        try:
            mean, std = (np.asarray(d[k], np.float64).reshape(-1) for k in ("mean", "std"))
            weights = np.asarray(d["weights"], np.float64)
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise BoxRegressorError(f"malformed box regressor ({type(exc).__name__}: {exc})") from None
        if len(mean) != len(FEATURES) or len(std) != len(FEATURES) or weights.shape != (len(FEATURES), 4):
            raise BoxRegressorError(f"mean and std need {len(FEATURES)} values, weights {len(FEATURES)} x 4")
        if not (np.isfinite(mean).all() and np.isfinite(std).all() and np.isfinite(weights).all()) or (std <= 0).any():
            raise BoxRegressorError("the box regressor holds a non-finite number or a std <= 0")
        return cls(mean, std, weights, dict(d.get("info", {})), [ImageStage.from_dict(stage) for stage in stages])

    @classmethod
    def load(cls, path: str | Path) -> "BoxRegressor":
        return load_json_model(path, cls.from_dict, BoxRegressorError, "box regressor")


def fit_box_regressor(features: np.ndarray, offsets: np.ndarray, l2: float = 100.0) -> BoxRegressor:
    """Ridge regression of ``offsets`` (n x 4, :func:`edge_offsets`) on ``features`` (n x len(FEATURES)); the
    bias column is neither standardised nor penalised."""
    x = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
    y = np.asarray(offsets, np.float64).reshape(-1, 4)
    if len(x) != len(y) or len(x) < len(FEATURES):
        raise BoxRegressorError(f"fitting needs as many targets as rows and at least {len(FEATURES)} rows")
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-6
    mean[0], std[0] = 0.0, 1.0
    z = (x - mean) / std
    penalty = np.full(len(FEATURES), float(l2))
    penalty[0] = 0.0
    weights = np.linalg.solve(z.T @ z + np.diag(penalty), z.T @ y)
    return BoxRegressor(mean, std, weights, {"samples": int(len(x)), "l2": float(l2)})


def fit_image_stage(features: np.ndarray, offsets: np.ndarray, grow: float, size: int, l2: float = 30.0) -> ImageStage:
    """Ridge regression of ``offsets`` (n x 4) on an image stage's ``features`` (:meth:`ImageStage.features`'
    rows); the bias column is neither standardised nor penalised."""
    n = 1 + len(image_feature_names(size)) + len(FEATURES) - 1
    x = np.asarray(features, np.float64).reshape(-1, n)
    y = np.asarray(offsets, np.float64).reshape(-1, 4)
    if len(x) != len(y) or len(x) < n:
        raise BoxRegressorError(f"fitting an image stage needs as many targets as rows and at least {n} rows")
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-6
    mean[0], std[0] = 0.0, 1.0
    z = (x - mean) / std
    penalty = np.full(n, float(l2))
    penalty[0] = 0.0
    return ImageStage(float(grow), int(size), mean, std, np.linalg.solve(z.T @ z + np.diag(penalty), z.T @ y))
