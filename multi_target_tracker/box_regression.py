"""Box regression of the cascade's groups from their member windows (pure: numpy): the UAV set-up's third step.

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
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multi_target_tracker.verifier import check_json_model, load_json_model

BOX_REGRESSOR_FORMAT = "aircraft_docking_tracker/group-box-regressor"
BOX_REGRESSOR_VERSION = 1
FEATURES = ("bias", "log_count", "log_margin_sum", "best_margin", "log_aspect", "log_area_8",
            "p10_left", "p90_right", "p10_top", "p90_bottom", "min_left", "max_right", "min_top", "max_bottom",
            "centre_x_spread", "centre_y_spread", "aspect_spread", "mean_abs_log_aspect",
            "weighted_left", "weighted_right", "weighted_top", "weighted_bottom",
            "at_left_border", "at_top_border", "at_right_border", "at_bottom_border")
BORDER_PX = 2.0


class BoxRegressorError(ValueError):
    """A box regressor model file or input that cannot be used."""


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
    width, height = frame_size
    for k, (a, b) in enumerate(zip(starts, ends)):
        if b <= a:
            raise BoxRegressorError(f"group {groups[k]} has no member windows")
        mb, mm = boxes[order[a:b]], margins[order[a:b]]
        above = np.maximum(mm - margin_floor, 0.0)
        weight = above / above.sum() if above.sum() > 0 else np.full(len(mm), 1.0 / len(mm))
        gx, gy, gw, gh = group_boxes[k]
        gw, gh = max(gw, 1e-6), max(gh, 1e-6)
        x0, y0, x1, y1 = mb[:, 0], mb[:, 1], mb[:, 0] + mb[:, 2], mb[:, 1] + mb[:, 3]
        aspect = np.log(np.maximum(mb[:, 2], 1e-6) / np.maximum(mb[:, 3], 1e-6))
        out[k] = [1.0, math.log(len(mb)), math.log1p(above.sum()), mm.max(), math.log(gw / gh), math.log(gw * gh) / 8,
                  (np.percentile(x0, 10) - gx) / gw, (np.percentile(x1, 90) - gx - gw) / gw,
                  (np.percentile(y0, 10) - gy) / gh, (np.percentile(y1, 90) - gy - gh) / gh,
                  (x0.min() - gx) / gw, (x1.max() - gx - gw) / gw, (y0.min() - gy) / gh, (y1.max() - gy - gh) / gh,
                  ((x0 + x1) / 2).std() / gw, ((y0 + y1) / 2).std() / gh, aspect.std(), np.abs(aspect).mean(),
                  (weight @ x0 - gx) / gw, (weight @ x1 - gx - gw) / gw, (weight @ y0 - gy) / gh,
                  (weight @ y1 - gy - gh) / gh,
                  float(gx < BORDER_PX), float(gy < BORDER_PX), float(gx + gw > width - BORDER_PX),
                  float(gy + gh > height - BORDER_PX)]
    return out


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
    """A ridge regression of :func:`edge_offsets` on :data:`FEATURES`: standardisation and weights (n x 4)."""

    mean: np.ndarray
    std: np.ndarray
    weights: np.ndarray
    info: dict = field(default_factory=dict)

    def offsets(self, features: np.ndarray) -> np.ndarray:
        features = np.asarray(features, np.float64).reshape(-1, len(FEATURES))
        return ((features - self.mean) / self.std) @ self.weights

    def refine(self, group_boxes: np.ndarray, features: np.ndarray) -> np.ndarray:
        """The groups' boxes with each edge moved by the predicted offset."""
        return apply_offsets(group_boxes, self.offsets(features))

    def to_dict(self) -> dict:
        return {"format": BOX_REGRESSOR_FORMAT, "version": BOX_REGRESSOR_VERSION, "features": list(FEATURES),
                "mean": self.mean.tolist(), "std": self.std.tolist(), "weights": self.weights.tolist(), "info": self.info}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def from_dict(cls, d: dict) -> "BoxRegressor":
        """A regressor from its JSON form; refuses another format, other features, non-finite numbers."""
        check_json_model(d, BOX_REGRESSOR_FORMAT, BOX_REGRESSOR_VERSION, FEATURES, BoxRegressorError, "box regressor")
        try:
            mean, std = (np.asarray(d[k], np.float64).reshape(-1) for k in ("mean", "std"))
            weights = np.asarray(d["weights"], np.float64)
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise BoxRegressorError(f"malformed box regressor ({type(exc).__name__}: {exc})") from None
        if len(mean) != len(FEATURES) or len(std) != len(FEATURES) or weights.shape != (len(FEATURES), 4):
            raise BoxRegressorError(f"mean and std need {len(FEATURES)} values, weights {len(FEATURES)} x 4")
        if not (np.isfinite(mean).all() and np.isfinite(std).all() and np.isfinite(weights).all()) or (std <= 0).any():
            raise BoxRegressorError("the box regressor holds a non-finite number or a std <= 0")
        return cls(mean, std, weights, dict(d.get("info", {})))

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
