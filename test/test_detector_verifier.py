"""The colour verifier of the cascade's groups (multi_target_tracker/verifier.py) and the group statistics."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError, validate
from multi_target_tracker.detector import Detector, DetectorConfig, DetectorError, group_stats, group_windows
from multi_target_tracker.verifier import (
    FEATURES, TreeVerifier, Verifier, VerifierError, colour_features, fit_tree_verifier, fit_verifier, group_features,
    load_verifier_model)


def test_group_stats_counts_and_sums_the_windows_of_each_group():
    rng = np.random.default_rng(0)
    cluster = np.array([100, 100, 40, 20]) + np.column_stack([rng.integers(-2, 3, (6, 2)), np.zeros((6, 2))])
    lone = np.array([[400, 300, 40, 20]])
    boxes = np.vstack([cluster, lone]).astype(float)
    margins = np.array([1.0, 2.0, 0.5, 1.5, 1.2, 0.8, 3.0])
    group_boxes, counts, sums, best = group_stats(boxes, margins, 0.3, margin_floor=0.5)
    assert sorted(counts.tolist()) == [1, 6]
    big = int(np.argmax(counts))
    assert sums[big] == pytest.approx((margins[:6] - 0.5).sum()) and best[big] == 2.0
    assert sums[1 - big] == pytest.approx(2.5) and best[1 - big] == 3.0     # the lone window's own margin
    assert np.allclose(group_boxes[big], cluster.mean(axis=0))
    only_big = group_stats(boxes, margins, 0.3, margin_floor=0.5, min_count=2)
    assert only_big[1].tolist() == [6] and np.allclose(only_big[0][0], group_boxes[big])
    grouped, scores = group_windows(boxes, margins, 0.3, min_neighbors=2, containment=1.0)
    assert len(grouped) == 1 and np.allclose(grouped[0], group_boxes[big]) and 6 < scores[0] < 7


def test_colour_features_tell_a_painted_box_from_canopy_and_refuse_grey_images():
    image = np.zeros((100, 200, 3), np.uint8)
    image[:, :100] = (40, 120, 50)          # green canopy (BGR)
    image[:, 100:] = (40, 40, 200)          # a red car
    f = colour_features(image, np.array([[10, 10, 60, 60], [120, 10, 60, 60]], float))
    assert f.shape == (2, len(FEATURES) - 3)
    assert f[0, 1] > f[0, 2] + 0.2 and f[1, 2] > f[1, 1] + 0.4           # mean green / mean red
    assert f[0, 6] != pytest.approx(f[1, 6], abs=0.1)                     # hue differs
    with pytest.raises(VerifierError):
        colour_features(image[:, :, 0], np.array([[0, 0, 10, 10]], float))
    edge = colour_features(image, np.array([[190, 90, 40, 40], [-30, -30, 20, 20]], float))   # clipped, no crash
    assert np.isfinite(edge).all()


def test_colour_features_are_numpy_s_statistics_of_the_inner_half_of_each_box():
    """The compiled statistics against NumPy's on OpenCV's HSV, box by box (sums in another order: 1e-12)."""
    rng = np.random.default_rng(4)
    image = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    image[40:80, 50:120] = (30, 60, 200)                            # a flat patch: zero spread
    boxes = np.array([[10, 20, 80, 60], [57, 45, 40, 20], [150, 110, 30, 30], [-40, -40, 45, 45], [3, 4, 1, 1]],
                     float)
    f = colour_features(image, boxes)
    for k, (x, y, w, h) in enumerate(boxes):
        x0, x1 = int(np.clip(x + w / 4, 0, 159)), int(np.clip(x + 3 * w / 4, 0, 159))
        y0, y1 = int(np.clip(y + h / 4, 0, 119)), int(np.clip(y + 3 * h / 4, 0, 119))
        inner = image[y0:max(y1, y0 + 1), x0:max(x1, x0 + 1)]
        pixels = inner.reshape(-1, 3).astype(float)
        hsv = cv2.cvtColor(inner, cv2.COLOR_BGR2HSV).reshape(-1, 3).astype(float)
        hue = hsv[:, 0] * np.pi / 90
        expected = np.r_[pixels.mean(axis=0), pixels.std(axis=0), np.mean(np.cos(hue) * hsv[:, 1]),
                         np.mean(np.sin(hue) * hsv[:, 1]), hsv[:, 1].mean(), hsv[:, 2].std()] / 255
        assert np.allclose(f[k], expected, rtol=1e-12, atol=1e-14), k
    assert f[1, 3:6].tolist() == [0, 0, 0] and f[1, :3] == pytest.approx(np.array([30, 60, 200]) / 255)


def test_fit_verifier_orders_separable_groups_and_round_trips_through_json(tmp_path):
    rng = np.random.default_rng(1)
    n = 400
    labels = rng.random(n) < 0.3
    x = rng.normal(size=(n, len(FEATURES)))
    x[:, 2] += np.where(labels, 1.5, -1.5)          # red paint on vehicles, none on the background
    verifier = fit_verifier(x, labels)
    logit = verifier.logit(x)
    # with classes 3 standard deviations apart the positives rank above the negatives almost always
    auc = (logit[labels][:, None] > logit[~labels][None, :]).mean()
    assert auc > 0.95
    path = tmp_path / "v.json"
    verifier.save(path)
    again = Verifier.load(path)
    assert np.allclose(again.logit(x), logit)
    with pytest.raises(VerifierError):
        fit_verifier(x, np.ones(n, bool))             # one class only


@pytest.mark.parametrize("change", [
    {"format": "something else"}, {"version": 99}, {"features": ["a"]}, {"weights": [1.0]},
    {"std": [0.0] * len(FEATURES)}, {"bias": float("nan")}, {"mean": "abc"}])
def test_a_malformed_verifier_is_refused(tmp_path, change):
    good = Verifier(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), np.ones(len(FEATURES)), 0.0).to_dict()
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({**good, **change}))
    with pytest.raises(VerifierError):
        Verifier.load(path)


def test_group_features_are_finite_for_any_group():
    f = group_features(np.array([1, 8, 30]), np.array([-0.5, 4.0, 40.0]), np.array([0.1, 2.0, 6.0]))
    assert f.shape == (3, 3) and np.isfinite(f).all() and (np.diff(f[:, 0]) > 0).all()


def test_detector_with_a_verifier_needs_colour_and_the_cascade_backend(tmp_path):
    path = tmp_path / "v.json"
    Verifier(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), np.zeros(len(FEATURES)), 5.0).save(path)
    det = Detector(DetectorConfig(verifier=str(path)))
    assert det.needs_colour and not Detector(DetectorConfig()).needs_colour
    with pytest.raises(DetectorError):
        det.detect(np.zeros((120, 160), np.uint8))
    table = det.detect(np.zeros((120, 160, 3), np.uint8))
    assert len(table) == 0 or ((table["score"] > 0) & (table["score"] < 1)).all()   # probabilities
    with pytest.raises(ConfigError, match="verifier"):
        validate(DetectorConfig(verifier=str(tmp_path / "missing.json")))
    with pytest.raises(ConfigError, match="verifier needs the cascade backend"):
        validate(DetectorConfig(backend="opencv", model="x.xml", verifier=str(path)))


def _two_paints(seed: int, n: int = 600):
    """Vehicles painted red or blue (two clusters on feature 2), background between them: no one linear
    boundary separates the classes."""
    rng = np.random.default_rng(seed)
    labels = rng.random(n) < 0.4
    x = rng.normal(size=(n, len(FEATURES)))
    x[:, 2] = np.where(labels, np.where(rng.random(n) < 0.5, 3.0, -3.0), 0.0) + rng.normal(0, 0.5, n)
    return x, labels


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tree_verifier_separates_two_paints_a_logistic_regression_cannot(seed, tmp_path):
    x, labels = _two_paints(seed)
    auc = lambda logit: (logit[labels][:, None] > logit[~labels][None, :]).mean()  # noqa: E731
    trees = fit_tree_verifier(x, labels, rounds=60)
    assert auc(trees.logit(x)) > 0.95 and auc(fit_verifier(x, labels).logit(x)) < 0.75
    held_x, held_labels = _two_paints(seed + 10)                    # and on samples it was not fitted on
    held = trees.logit(held_x)
    assert (held[held_labels][:, None] > held[~held_labels][None, :]).mean() > 0.9
    path = tmp_path / "t.json"
    trees.save(path)
    again = load_verifier_model(path)
    assert isinstance(again, TreeVerifier) and again.colour_box == "refined"
    assert np.allclose(again.logit(x), trees.logit(x))
    assert isinstance(load_verifier_model(_saved(tmp_path, fit_verifier(x, labels))), Verifier)
    with pytest.raises(VerifierError):
        fit_tree_verifier(x, np.zeros(len(x), bool))


def _saved(tmp_path, verifier):
    path = tmp_path / "any.json"
    verifier.save(path)
    return path


@pytest.mark.parametrize("change", [
    {"features": ["a"]}, {"colour_box": "upright"}, {"feature": [[0, 0, 99]]}, {"leaf": [[0.0, 1.0]]},
    {"leaf": [[0.0, float("nan"), 0.0, 0.0]]}, {"bias": "x"}, {"threshold": "abc"}])
def test_a_malformed_tree_verifier_is_refused(tmp_path, change):
    good = TreeVerifier(np.zeros((1, 3), np.int64), np.array([[0.0, np.inf, 1.0]]), np.zeros((1, 4)), 0.0).to_dict()
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({**good, **change}))
    with pytest.raises(VerifierError):
        load_verifier_model(path)
    path.write_text(json.dumps(good))
    assert np.allclose(load_verifier_model(path).logit(np.zeros((2, len(FEATURES)))), 0.0)
