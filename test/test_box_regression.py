"""The box regressor of the verified groups (multi_target_tracker/box_regression.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError, validate
from multi_target_tracker.box_regression import (
    FEATURES, BoxRegressor, BoxRegressorError, apply_offsets, edge_offsets, fit_box_regressor, member_features)
from multi_target_tracker.detector import Detector, DetectorConfig, group_members, members_stats
from multi_target_tracker.verifier import FEATURES as VERIFIER_FEATURES, Verifier


def test_edge_offsets_and_apply_offsets_are_inverse():
    rng = np.random.default_rng(0)
    boxes = np.column_stack([rng.uniform(0, 500, (20, 2)), rng.uniform(20, 90, (20, 2))])
    truth = boxes + rng.normal(0, 8, boxes.shape)
    truth[:, 2:] = np.abs(truth[:, 2:]) + 5
    assert np.allclose(apply_offsets(boxes, edge_offsets(boxes, truth)), truth)
    assert np.allclose(apply_offsets(boxes, np.zeros((20, 4))), boxes)
    collapsed = apply_offsets(boxes[:1], np.array([[0.6, -0.6, 0.0, 0.0]]))    # edges crossed: 1 px, not negative
    assert collapsed[0, 2] == 1.0 and collapsed[0, 3] == boxes[0, 3]


def test_member_features_describe_where_the_members_lie():
    # group 0: windows spread to the right of their mean box; group 1: identical windows at the frame border
    spread = np.array([[100, 100, 40, 20], [110, 100, 40, 20], [120, 100, 40, 20], [130, 100, 40, 20]], float)
    border = np.array([[0, 50, 30, 30]] * 3, float)
    boxes, margins = np.vstack([spread, border]), np.array([2.0, 1.5, 1.2, 1.1, 3.0, 2.0, 1.0])
    members = group_members(boxes, margins, 0.1)
    kept, group_boxes, counts, _, _ = members_stats(*members, 1.0, 3)
    f = member_features(*members[:3], kept, group_boxes, 1.0, (640, 480))
    assert f.shape == (2, len(FEATURES)) and np.isfinite(f).all()
    i, j = (0, 1) if counts[0] == 4 else (1, 0)
    name = {n: k for k, n in enumerate(FEATURES)}
    assert f[i, name["log_count"]] == pytest.approx(np.log(4))
    assert f[i, name["min_left"]] == pytest.approx(-15 / 40) and f[i, name["max_right"]] == pytest.approx(15 / 40)
    assert f[i, name["weighted_left"]] < 0                        # the best margins are on the left windows
    assert f[j, name["centre_x_spread"]] == 0 and f[j, name["min_left"]] == 0
    assert f[j, name["at_left_border"]] == 1 and f[i, name["at_left_border"]] == 0


def test_fit_box_regressor_recovers_a_linear_rule_and_round_trips_through_json(tmp_path):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(500, len(FEATURES)))
    x[:, 0] = 1.0
    truth = np.zeros((len(FEATURES), 4))
    truth[0], truth[10, 0], truth[11, 1] = 0.05, 0.8, 0.8         # edges follow the extreme members
    y = x @ truth + rng.normal(0, 0.01, (500, 4))
    regressor = fit_box_regressor(x, y, l2=1.0)
    assert np.abs(regressor.offsets(x) - y).mean() < 0.02
    path = tmp_path / "r.json"
    regressor.save(path)
    assert np.allclose(BoxRegressor.load(path).offsets(x), regressor.offsets(x))
    with pytest.raises(BoxRegressorError):
        fit_box_regressor(x[:5], y[:5])


@pytest.mark.parametrize("change", [
    {"format": "something else"}, {"version": 99}, {"features": ["a"]}, {"weights": [[1.0] * 4]},
    {"std": [0.0] * len(FEATURES)}, {"mean": [float("nan")] * len(FEATURES)}, {"mean": "abc"}])
def test_a_malformed_box_regressor_is_refused(tmp_path, change):
    good = BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), np.zeros((len(FEATURES), 4))).to_dict()
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({**good, **change}))
    with pytest.raises(BoxRegressorError):
        BoxRegressor.load(path)


def test_detector_with_a_box_regressor_needs_the_cascade_backend_and_moves_the_boxes(tmp_path):
    verifier = tmp_path / "v.json"
    Verifier(np.zeros(len(VERIFIER_FEATURES)), np.ones(len(VERIFIER_FEATURES)), np.zeros(len(VERIFIER_FEATURES)),
             5.0).save(verifier)                                   # accepts every group
    grow = np.zeros((len(FEATURES), 4))
    grow[0] = (-0.1, 0.1, -0.1, 0.1)                               # every edge 10 % outwards
    regressor = tmp_path / "r.json"
    BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), grow).save(regressor)
    with pytest.raises(ConfigError, match="box regressor needs the cascade backend"):
        validate(DetectorConfig(backend="opencv", model="cars.xml", box_regressor=str(regressor)))
    with pytest.raises(ConfigError, match="box regressor"):
        validate(DetectorConfig(verifier=str(verifier), box_regressor=str(tmp_path / "missing.json")))
    image = np.full((240, 320, 3), 120, np.uint8)
    windows = np.array([[50, 60, 48, 24], [54, 60, 48, 24], [50, 64, 48, 24], [200, 150, 24, 48], [204, 150, 24, 48]],
                       float)
    margins = np.array([2.0, 1.5, 1.2, 3.0, 2.5])
    detectors = [Detector(DetectorConfig(model="uav_vehicles_heading_all_views.json", verifier=str(verifier),
                                         min_neighbors=2, containment=1.0, window_margin=1.0, **extra))
                 for extra in ({}, {"box_regressor": str(regressor)})]
    for det in detectors:             # the same windows for both: only the grouping and what follows it run
        det.raw = lambda gray, margin: (windows, margins)
    plain, moved = detectors
    a, b = plain.detect(image), moved.detect(image)
    assert len(a) == 2 and len(b) == 2
    assert np.allclose(b["w"], a["w"] * 1.2) and np.allclose(b["x"] + b["w"] / 2, a["x"] + a["w"] / 2)
    assert np.allclose(b["score"], a["score"])


def test_a_box_regressor_without_the_verifier_moves_the_groups_and_keeps_their_scores(tmp_path):
    """The drone-view set-up's form: no verifier, the grouped windows' boxes refined before containment."""
    grow = np.zeros((len(FEATURES), 4))
    grow[0] = (-0.1, 0.1, -0.1, 0.1)                               # every edge 10 % outwards
    regressor = tmp_path / "r.json"
    BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), grow).save(regressor)
    validate(DetectorConfig(box_regressor=str(regressor)))
    image = np.full((240, 320), 120, np.uint8)
    windows = np.array([[50, 60, 48, 24], [54, 60, 48, 24], [50, 64, 48, 24], [200, 150, 24, 48], [204, 150, 24, 48]],
                       float)
    margins = np.array([2.0, 1.5, 1.2, 3.0, 2.5])
    detectors = [Detector(DetectorConfig(min_neighbors=2, containment=1.0, window_margin=1.0, **extra))
                 for extra in ({"box_regressor": ""}, {"box_regressor": str(regressor)})]
    for det in detectors:
        det.raw = lambda gray, margin: (windows, margins)
    plain, moved = detectors
    assert plain.box_regressor is None and moved.box_regressor is not None
    a, b = plain.detect(image), moved.detect(image)
    assert len(a) == 2 and len(b) == 2
    assert np.allclose(b["w"], a["w"] * 1.2) and np.allclose(b["h"], a["h"] * 1.2)
    assert np.allclose(b["y"] + b["h"] / 2, a["y"] + a["h"] / 2) and np.allclose(b["score"], a["score"])
