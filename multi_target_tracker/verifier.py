"""Colour verifier of the cascade's groups (pure: numpy, scipy, OpenCV, numba): the UAV set-up's second stage.

The cascade looks at grey texture only (seed 003's LBP and contour features). On the UAV scenes its
window count does not tell a vehicle from the tree canopy, smoke or a road patch that passes it as
often (bench/uav_detector.py: the count, the summed last-stage margins and the best margin give
about the same precision-recall curve). A vehicle's paint does: a second stage scores each group
from its colour and its cascade evidence with a logistic regression,

    logit = w . (f - mean) / std + b

with ``f`` = the colour statistics of the inner half of the group's box (mean and standard deviation
of B, G, R; the saturation-weighted hue as cos / sin; mean saturation; standard deviation of the value)
and the group's log window count, log(1 + summed margins above ``window_margin``) and best margin.
It is trained by ``tools/train_uav_verifier.py`` on the training scenes' groups (labelled by the
ground truth), its threshold chosen on the tuning scenes. The model file is JSON (never pickle).

:class:`TreeVerifier` (version 2) scores the same features with boosted depth-2 regression trees
(Newton steps on the logistic loss, :func:`fit_tree_verifier`): the vehicles' paints are several
colours (white, black, red, blue, brown) among green canopy and grey roads, which one linear boundary
in colour space cannot carve out. Its colour is read in the box regressor's refined box
(``colour_box`` "refined"; the logistic regression's in the groups' mean box).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numba
import numpy as np
from scipy.optimize import minimize

VERIFIER_FORMAT = "aircraft_docking_tracker/group-verifier"
VERIFIER_VERSION = 1
COLOUR_FEATURES = ("mean_b", "mean_g", "mean_r", "std_b", "std_g", "std_r", "hue_cos", "hue_sin",
                   "mean_saturation", "std_value")
GROUP_FEATURES = ("log_count", "log_margin_sum", "best_margin")
FEATURES = COLOUR_FEATURES + GROUP_FEATURES


class VerifierError(ValueError):
    """A verifier model file or input that cannot be used."""


def colour_features(bgr: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """``(n, 10)`` colour statistics (:data:`COLOUR_FEATURES`, scaled to about 0..1) of the inner half of
    each box (x, y, w, h; clipped to the image) of a BGR uint8 image."""
    if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
        raise VerifierError(f"the colour verifier needs a BGR uint8 image, got {bgr.dtype} {bgr.shape}")
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    height, width = bgr.shape[:2]
    out = np.zeros((len(boxes), len(COLOUR_FEATURES)))
    for k, (x, y, w, h) in enumerate(boxes):
        # Python's min / max: np.clip on one number costs 10 us, 4 a box (a NaN still fails int() either way)
        x0, x1 = int(min(max(x + w / 4, 0), width - 1)), int(min(max(x + 3 * w / 4, 0), width - 1))
        y0, y1 = int(min(max(y + h / 4, 0), height - 1)), int(min(max(y + 3 * h / 4, 0), height - 1))
        inner = bgr[y0:max(y1, y0 + 1), x0:max(x1, x0 + 1)]
        _colour_statistics(inner, cv2.cvtColor(inner, cv2.COLOR_BGR2HSV), _HUE_COS, _HUE_SIN, out[k])
    return out


_HUE_COS, _HUE_SIN = np.cos(np.arange(256) * (np.pi / 90.0)), np.sin(np.arange(256) * (np.pi / 90.0))
"""cos / sin of each 8-bit hue (OpenCV's 0..179 for 0..358 degrees)"""


@numba.njit(cache=True, nogil=True)
def _colour_statistics(bgr, hsv, hue_cos, hue_sin, out):
    """:func:`colour_features` of one box's pixels ``bgr`` (their HSV ``hsv``) into ``out``: the means and standard
    deviations (of the population) of B, G, R, the means of cos(hue) S, sin(hue) S and S, the standard deviation of V,
    each / 255, in float64 (two passes, as NumPy's mean and std; sums in pixel order, NumPy's pairwise order aside).
    One compiled call a box: the same statistics as NumPy calls took about 230 us a box, 9 ms a UAV frame (session 48)."""
    height, width = bgr.shape[0], bgr.shape[1]
    n = height * width
    total = np.zeros(7)                        # B, G, R, cos S, sin S, S, V
    for y in range(height):
        for x in range(width):
            for c in range(3):
                total[c] += np.float64(bgr[y, x, c])
            h, s = hsv[y, x, 0], np.float64(hsv[y, x, 1])
            total[3] += hue_cos[h] * s
            total[4] += hue_sin[h] * s
            total[5] += s
            total[6] += np.float64(hsv[y, x, 2])
    mean = total / n
    spread = np.zeros(4)                       # B, G, R, V squared deviations
    for y in range(height):
        for x in range(width):
            for c in range(3):
                d = np.float64(bgr[y, x, c]) - mean[c]
                spread[c] += d * d
            d = np.float64(hsv[y, x, 2]) - mean[6]
            spread[3] += d * d
    for c in range(3):
        out[c] = mean[c] / 255
        out[3 + c] = np.sqrt(spread[c] / n) / 255
    out[6], out[7], out[8] = mean[3] / 255, mean[4] / 255, mean[5] / 255
    out[9] = np.sqrt(spread[3] / n) / 255


def group_features(counts: np.ndarray, margin_sums: np.ndarray, best_margins: np.ndarray) -> np.ndarray:
    """``(n, 3)`` cascade evidence of each group (:data:`GROUP_FEATURES`)."""
    return np.column_stack([np.log(np.maximum(np.asarray(counts, np.float64), 1.0)),
                            np.log1p(np.maximum(np.asarray(margin_sums, np.float64), 0.0)),
                            np.asarray(best_margins, np.float64)]).reshape(-1, len(GROUP_FEATURES))


def features(bgr: np.ndarray, boxes: np.ndarray, counts: np.ndarray, margin_sums: np.ndarray,
             best_margins: np.ndarray) -> np.ndarray:
    """``(n, len(FEATURES))``: each group's colour statistics in ``bgr`` beside its cascade evidence."""
    return np.hstack([colour_features(bgr, boxes), group_features(counts, margin_sums, best_margins)])


@dataclass
class Verifier:
    """A logistic regression over :data:`FEATURES`: standardisation, weights, bias."""

    mean: np.ndarray
    std: np.ndarray
    weights: np.ndarray
    bias: float
    info: dict = field(default_factory=dict)
    colour_box = "mean"      # the box whose colour it reads: the group's mean box

    def logit(self, features: np.ndarray) -> np.ndarray:
        """Log odds that each row of ``features`` (n x len(FEATURES)) is a vehicle."""
        features = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
        return ((features - self.mean) / self.std) @ self.weights + self.bias

    def to_dict(self) -> dict:
        return {"format": VERIFIER_FORMAT, "version": VERIFIER_VERSION, "features": list(FEATURES),
                "mean": self.mean.tolist(), "std": self.std.tolist(), "weights": self.weights.tolist(),
                "bias": float(self.bias), "info": self.info}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def from_dict(cls, d: dict) -> "Verifier":
        """A verifier from its JSON form; refuses another format, other features, non-finite numbers."""
        check_json_model(d, VERIFIER_FORMAT, VERIFIER_VERSION, FEATURES, VerifierError, "verifier")
        try:
            arrays = [np.asarray(d[k], np.float64).reshape(-1) for k in ("mean", "std", "weights")]
            bias = float(d["bias"])
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise VerifierError(f"malformed verifier ({type(exc).__name__}: {exc})") from None
        if any(len(a) != len(FEATURES) for a in arrays):
            raise VerifierError(f"mean, std and weights need {len(FEATURES)} values each")
        if not all(np.isfinite(a).all() for a in arrays) or not math.isfinite(bias) or (arrays[1] <= 0).any():
            raise VerifierError("the verifier holds a non-finite number or a std <= 0")
        return cls(*arrays, bias, dict(d.get("info", {})))

    @classmethod
    def load(cls, path: str | Path) -> "Verifier":
        return load_json_model(path, cls.from_dict, VerifierError, "verifier")


TREE_VERIFIER_VERSION = 2
COLOUR_BOXES = ("mean", "refined")


@dataclass
class TreeVerifier:
    """Boosted depth-2 regression trees over :data:`FEATURES` (version 2 of the verifier's JSON).

    Tree ``k`` splits at its root on ``feature[k, 0] <= threshold[k, 0]``, then on node 1 (left) or 2 (right);
    its 4 leaves hold the log-odds steps, summed with ``bias``. A node that does not split has threshold
    +inf (every row goes left)."""

    feature: np.ndarray      # (trees, 3) int
    threshold: np.ndarray    # (trees, 3)
    leaf: np.ndarray         # (trees, 4)
    bias: float
    colour_box: str = "refined"
    info: dict = field(default_factory=dict)

    def logit(self, features: np.ndarray) -> np.ndarray:
        """Log odds that each row of ``features`` (n x len(FEATURES)) is a vehicle."""
        x = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
        if not len(self.leaf):
            return np.full(len(x), self.bias)
        root = x[:, self.feature[:, 0]] > self.threshold[:, 0]                  # (n, trees): went right
        node = np.where(root, 2, 1)
        trees = np.arange(len(self.leaf))
        child = x[np.arange(len(x))[:, None], self.feature[trees, node]] > self.threshold[trees, node]
        return self.leaf[trees, 2 * root + child].sum(axis=1) + self.bias

    def to_dict(self) -> dict:
        return {"format": VERIFIER_FORMAT, "version": TREE_VERIFIER_VERSION, "features": list(FEATURES),
                "colour_box": self.colour_box, "feature": self.feature.tolist(),
                "threshold": [[t if math.isfinite(t) else None for t in row] for row in self.threshold.tolist()],
                "leaf": self.leaf.tolist(), "bias": float(self.bias), "info": self.info}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def from_dict(cls, d: dict) -> "TreeVerifier":
        check_json_model(d, VERIFIER_FORMAT, TREE_VERIFIER_VERSION, FEATURES, VerifierError, "tree verifier")
        if d.get("colour_box") not in COLOUR_BOXES:
            raise VerifierError(f"colour_box {d.get('colour_box')!r} is not one of {COLOUR_BOXES}")
        try:
            feature = np.asarray(d["feature"], np.int64).reshape(-1, 3)
            threshold = np.asarray([[np.inf if t is None else t for t in row] for row in d["threshold"]],
                                   np.float64).reshape(-1, 3)
            leaf = np.asarray(d["leaf"], np.float64).reshape(-1, 4)
            bias = float(d["bias"])
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise VerifierError(f"malformed tree verifier ({type(exc).__name__}: {exc})") from None
        if not len(feature) == len(threshold) == len(leaf):
            raise VerifierError("feature, threshold and leaf need one row per tree")
        if ((feature < 0) | (feature >= len(FEATURES))).any():
            raise VerifierError(f"a tree splits on a feature outside 0..{len(FEATURES) - 1}")
        if np.isnan(threshold).any() or not np.isfinite(leaf).all() or not math.isfinite(bias):
            raise VerifierError("the tree verifier holds a non-finite number")
        return cls(feature, threshold, leaf, bias, d["colour_box"], dict(d.get("info", {})))


def verifier_from_dict(d: dict) -> "Verifier | TreeVerifier":
    """Either verifier from its JSON form (by its version)."""
    if isinstance(d, dict) and d.get("version") == TREE_VERIFIER_VERSION:
        return TreeVerifier.from_dict(d)
    return Verifier.from_dict(d)


def load_verifier_model(path: str | Path) -> "Verifier | TreeVerifier":
    """The verifier (either kind) in the JSON file ``path``."""
    return load_json_model(path, verifier_from_dict, VerifierError, "verifier")


def check_json_model(d, format_name: str, version: int, features, error: type[ValueError], what: str) -> None:
    """Refuse (as ``error``) a JSON model ``d`` that is not a dict of ``format_name``, its ``version``, over
    exactly ``features``: the header every model file of the detector carries."""
    if not isinstance(d, dict) or d.get("format") != format_name:
        raise error(f"not a {format_name} model")
    if d.get("version") != version:
        raise error(f"{what} version {d.get('version')} unsupported (expected {version})")
    if list(d.get("features", ())) != list(features):
        raise error(f"{what} features {d.get('features')} are not {list(features)}")


def load_json_model(path: str | Path, from_dict, error: type[ValueError], what: str):
    """``from_dict`` of the JSON file ``path``; any failure is an ``error`` naming the file and ``what`` it is."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise error(f"cannot read {what} {path}: {exc}") from exc
    try:
        return from_dict(data)
    except error as exc:
        raise error(f"{path}: {exc}") from None


def fit_verifier(features: np.ndarray, labels: np.ndarray, l2: float = 1e-3) -> Verifier:
    """Logistic regression (L-BFGS, L2 penalty ``l2`` on the standardised weights, the two classes weighted
    equally) of ``labels`` (1 vehicle, 0 not) on ``features`` (n x len(FEATURES))."""
    x = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
    y = np.asarray(labels, bool).reshape(-1)
    if len(x) != len(y) or y.all() or not y.any():
        raise VerifierError("fitting needs as many labels as rows and both classes")
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-6
    z = np.column_stack([(x - mean) / std, np.ones(len(x))])
    sign = np.where(y, 1.0, -1.0)
    weight = np.where(y, 0.5 / y.mean(), 0.5 / (1 - y.mean())) / len(y)

    def loss(w):
        margin = sign * (z @ w)
        grad = -(weight * sign * np.exp(-np.logaddexp(0.0, margin))) @ z + l2 * np.append(w[:-1], 0.0)
        return float(weight @ np.logaddexp(0.0, -margin) + 0.5 * l2 * w[:-1] @ w[:-1]), grad

    w = minimize(loss, np.zeros(z.shape[1]), jac=True, method="L-BFGS-B", options={"maxiter": 1000}).x
    return Verifier(mean, std, w[:-1], float(w[-1]), {"samples": int(len(y)), "positives": int(y.sum()), "l2": l2})


def fit_tree_verifier(features: np.ndarray, labels: np.ndarray, rounds: int = 150, learning_rate: float = 0.1,
                      bins: int = 32, l2: float = 1.0, min_leaf: int = 10, colour_box: str = "refined") -> TreeVerifier:
    """Boosted depth-2 trees (Newton steps on the logistic loss, the two classes weighted equally) of ``labels``
    on ``features``: each node's split the best gain over ``bins`` quantile thresholds of every feature,
    leaves -G / (H + ``l2``) shrunk by ``learning_rate``, nodes of fewer than ``min_leaf`` rows not split."""
    x = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
    y = np.asarray(labels, bool).reshape(-1)
    if len(x) != len(y) or y.all() or not y.any():
        raise VerifierError("fitting needs as many labels as rows and both classes")
    weight = np.where(y, 0.5 / y.mean(), 0.5 / (1 - y.mean()))
    cuts = [np.unique(np.quantile(x[:, j], np.linspace(0, 1, bins + 1)[1:-1])) for j in range(x.shape[1])]
    binned = np.column_stack([np.searchsorted(c, x[:, j], side="left") for j, c in enumerate(cuts)])

    def split(rows, g, h):
        """(feature, threshold) of the best split of ``rows`` or None."""
        big_g, big_h, best = g[rows].sum(), h[rows].sum(), (0.0, None)
        for j, c in enumerate(cuts):
            if not len(c):
                continue
            b = binned[rows, j]
            gl = np.cumsum(np.bincount(b, g[rows], len(c) + 1))[:-1]
            hl = np.cumsum(np.bincount(b, h[rows], len(c) + 1))[:-1]
            nl = np.cumsum(np.bincount(b, None, len(c) + 1))[:-1]
            gain = gl ** 2 / (hl + l2) + (big_g - gl) ** 2 / (big_h - hl + l2) - big_g ** 2 / (big_h + l2)
            gain[(nl < min_leaf) | (len(rows) - nl < min_leaf)] = -np.inf
            k = int(np.argmax(gain))
            if gain[k] > best[0]:
                best = (float(gain[k]), (j, float(c[k])))
        return best[1]

    score = np.zeros(len(y))
    feature, threshold, leaf = [], [], []
    rows = np.arange(len(y))
    for _ in range(rounds):
        p = 1.0 / (1.0 + np.exp(-score))
        g, h = weight * (p - y), weight * p * (1 - p)
        f, t, v = [0, 0, 0], [np.inf] * 3, []
        root = split(rows, g, h)
        if root is not None:
            f[0], t[0] = root
        right = x[:, f[0]] > t[0]
        for node, side in ((1, rows[~right]), (2, rows[right])):
            child = split(side, g, h) if len(side) >= 2 * min_leaf else None
            if child is not None:
                f[node], t[node] = child
        for side in (~right, right):
            second = x[:, f[2 if side is right else 1]] > t[2 if side is right else 1]
            for m in (side & ~second, side & second):
                v.append(-learning_rate * g[m].sum() / (h[m].sum() + l2))
        feature.append(f)
        threshold.append(t)
        leaf.append(v)
        tree = TreeVerifier(np.array([f]), np.array([t]), np.array([v]), 0.0, colour_box)
        score += tree.logit(x)
    return TreeVerifier(np.array(feature, np.int64), np.array(threshold), np.array(leaf), 0.0, colour_box,
                        {"samples": int(len(y)), "positives": int(y.sum()), "rounds": rounds,
                         "learning_rate": learning_rate, "bins": bins, "l2": l2, "min_leaf": min_leaf})
