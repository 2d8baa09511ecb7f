"""The box regressor of the verified groups (multi_target_tracker/box_regression.py)."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError, load_yaml_parameters, package_config_dir, validate
from aircraft_docking_tracker.geometry import box_iou, box_to_quad
from conftest import require_data
from multi_target_tracker.box_regression import (
    FEATURES, BoxRegressor, BoxRegressorError, ImageStage, apply_offsets, edge_offsets, fit_box_regressor,
    column_medians, fit_image_stage, image_feature_names, image_features, image_stage_features, member_features,
    percentile)
from multi_target_tracker.detector import MODELS_DIR, Detector, DetectorConfig, Windows, group_members, members_stats
from multi_target_tracker.train_cascade import read_yolo_folder, truncated
from multi_target_tracker.verifier import FEATURES as VERIFIER_FEATURES, Verifier


def test_percentile_and_column_medians_give_numpys_bits():
    """The regressor's features were measured with np.percentile / np.median: the fast versions must give the same
    bits and dtype (float64 member edges, float32 image profiles): ties, zeros of either sign, NaN and infinities,
    the 0 / 100 ends included."""
    def same(ours, numpys):
        ours, numpys = np.asarray(ours), np.asarray(numpys)
        return (ours.dtype == numpys.dtype and np.array_equal(ours, numpys, equal_nan=True)
                and np.array_equal(np.signbit(ours), np.signbit(numpys)))

    rng = np.random.default_rng(0)
    with np.errstate(invalid="ignore"):               # inf - inf on the way to NumPy's own NaN
        for trial in range(800):
            dtype = (np.float32, np.float64)[trial % 2]
            values = (rng.normal(size=int(rng.integers(1, 50))) * 10 ** rng.uniform(-3, 3)).astype(dtype)
            table = rng.normal(size=(int(rng.integers(1, 40)), 3)).astype(dtype)
            if trial % 3 == 0:
                values, table = np.round(values), np.round(table)      # ties and zeros of both signs
            if trial % 5 == 0:
                values[rng.integers(len(values))] = rng.choice([np.inf, -np.inf, np.nan, -0.0])
                table[rng.integers(len(table)), rng.integers(3)] = rng.choice([np.inf, -np.inf, np.nan, -0.0])
            for q in (0, 5, 10, 20, 50, 90, 95, 100, float(rng.uniform(0, 100))):
                assert same(percentile(values, q), np.percentile(values, q)), (values, q)
            assert same(column_medians(table), np.median(table, axis=0)), table
    with pytest.raises(BoxRegressorError):
        percentile(np.zeros(0), 10)


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


def test_member_features_are_numpy_s_statistics_of_each_group():
    """The compiled pass against NumPy's calls, group by group: percentiles and extremes to the bit, sums to 1e-12
    (their order differs). Groups of 1, 2, 7 and 300 members (NumPy sums 300 values pairwise), ragged labels."""
    rng = np.random.default_rng(3)
    sizes = {4: 1, 9: 2, 2: 7, 7: 300}
    label = rng.permutation(np.repeat(list(sizes), list(sizes.values())))
    boxes = np.column_stack([rng.uniform(-20, 600, len(label)), rng.uniform(-20, 440, len(label)),
                             rng.uniform(5, 90, len(label)), rng.uniform(5, 90, len(label))])
    margins = rng.normal(1.0, 1.0, len(label))
    margins[label == 9] = 0.5                                   # nothing above the floor: equal weights
    groups = np.array([7, 2, 9, 4])
    group_boxes = np.array([boxes[label == g].mean(axis=0) for g in groups])
    group_boxes[3, :2] = (0.5, 470.0)                           # at the left and bottom borders
    f = member_features(boxes, margins, label, groups, group_boxes, 0.8, (640, 480))
    for k, g in enumerate(groups):
        mb, mm = boxes[label == g], margins[label == g]
        gx, gy, gw, gh = group_boxes[k]
        x0, y0, x1, y1 = mb[:, 0], mb[:, 1], mb[:, 0] + mb[:, 2], mb[:, 1] + mb[:, 3]
        above = np.maximum(mm - 0.8, 0.0)
        weight = above / above.sum() if above.sum() > 0 else np.full(len(mm), 1 / len(mm))
        aspect = np.log(mb[:, 2] / mb[:, 3])
        exact = [(np.percentile(x0, 10) - gx) / gw, (np.percentile(x1, 90) - gx - gw) / gw,
                 (np.percentile(y0, 10) - gy) / gh, (np.percentile(y1, 90) - gy - gh) / gh,
                 (x0.min() - gx) / gw, (x1.max() - gx - gw) / gw, (y0.min() - gy) / gh, (y1.max() - gy - gh) / gh]
        assert f[k, 6:14].tolist() == exact
        assert f[k, 22:].tolist() == [float(gx < 2), float(gy < 2), float(gx + gw > 638), float(gy + gh > 478)]
        summed = [1.0, np.log(len(mb)), np.log1p(above.sum()), mm.max(), np.log(gw / gh), np.log(gw * gh) / 8]
        summed += [((x0 + x1) / 2).std() / gw, ((y0 + y1) / 2).std() / gh, aspect.std(), np.abs(aspect).mean(),
                   (weight @ x0 - gx) / gw, (weight @ x1 - gx - gw) / gw, (weight @ y0 - gy) / gh,
                   (weight @ y1 - gy - gh) / gh]
        assert np.allclose(np.r_[f[k, :6], f[k, 14:22]], summed, rtol=1e-12, atol=1e-12)
    assert f[3, 22] == 1 and f[3, 25] == 1
    with pytest.raises(BoxRegressorError):
        member_features(boxes, margins, label, np.array([7, 5]), group_boxes[:2], 0.8, (640, 480))


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


def accept_all_verifier(tmp_path):
    """A verifier model file that accepts every group (zero weights, threshold 5 below the bias)."""
    path = tmp_path / "v.json"
    Verifier(np.zeros(len(VERIFIER_FEATURES)), np.ones(len(VERIFIER_FEATURES)), np.zeros(len(VERIFIER_FEATURES)),
             5.0).save(path)
    return path


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
    verifier = accept_all_verifier(tmp_path)
    grow = np.zeros((len(FEATURES), 4))
    grow[0] = (-0.1, 0.1, -0.1, 0.1)                               # every edge 10 % outwards
    regressor = tmp_path / "r.json"
    BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), grow).save(regressor)
    with pytest.raises(ConfigError, match="box regressor needs the cascade backend"):
        validate(DetectorConfig(backend="opencv", model="cars.xml", box_regressor=str(regressor)))
    with pytest.raises(ConfigError, match="box regressor"):
        validate(DetectorConfig(verifier=str(verifier), box_regressor=str(tmp_path / "missing.json")))
    a, b = _without_and_with(verifier, regressor)
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
        # the scan behind detect()
        det._raw = lambda image, gray, margin: Windows(windows, margins, box_to_quad(windows))
    plain, moved = detectors
    assert plain.box_regressor is None and moved.box_regressor is not None
    a, b = plain.detect(image), moved.detect(image)
    assert len(a) == 2 and len(b) == 2
    assert np.allclose(b["w"], a["w"] * 1.2) and np.allclose(b["h"], a["h"] * 1.2)
    assert np.allclose(b["y"] + b["h"] / 2, a["y"] + a["h"] / 2) and np.allclose(b["score"], a["score"])


def test_the_shipped_drone_view_setup_loads_its_regressor_and_moves_the_boxes_onto_the_vehicles():
    """config/detector.yaml names the drone-view regressor: it loads, belongs to the shipped model's recipe, and
    on drone-view tiles its boxes move and fit the labels at least as well as the mean boxes (bench/detector.py
    measures it on held-out prefix folds; these tiles were in the training of both, so only the direction is checked)."""
    params = load_yaml_parameters(package_config_dir() / "detector.yaml", "detector")
    config = DetectorConfig(**{k: v for k, v in params.items() if "." not in k})
    shipped = Detector(config)
    assert shipped.box_regressor is not None
    model_info = json.loads((MODELS_DIR / config.model).read_text())["info"]
    assert shipped.box_regressor.info["recipe"] in model_info["recipe"]         # the shipped model's recipe
    plain = Detector(dataclasses.replace(config, box_regressor=""))
    tiles = require_data("detect/drone-view-vehicles")
    items = read_yolo_folder(tiles, include=["1_", "4_"])[::25][:8]
    moved, iou_plain, iou_shipped = [], [], []
    for item in items:
        bgr = item.load_colour()    # the set-up's blob views read colour
        counted = item.boxes[~truncated(item.boxes, bgr.shape[1::-1], 1.5)]
        a, b = plain.detect(bgr), shipped.detect(bgr)
        boxes = [np.column_stack([t["x"], t["y"], t["w"], t["h"]]) for t in (a, b)]
        if len(a) == len(b) and len(a):
            moved.append(np.abs(boxes[1] - boxes[0]).max(axis=1))
        for out, bx in ((iou_plain, boxes[0]), (iou_shipped, boxes[1])):
            if len(counted):
                out.extend(box_iou(bx[:, None], counted[None]).max(axis=0) if len(bx) else np.zeros(len(counted)))
    assert len(iou_plain) >= 20 and moved
    assert np.median(np.concatenate(moved)) > 0.5                  # pixels: the boxes do move
    assert np.mean(iou_shipped) >= np.mean(iou_plain) - 0.01        # ... and not off the vehicles


def _blob_scene(rng, n: int = 1):
    """A ground-coloured image with one vehicle-like rectangle (its box) and a box placed off it."""
    image = np.zeros((160, 200, 3), np.uint8)
    image[:] = rng.integers(60, 140, 3)
    w, h = rng.uniform(30, 60), rng.uniform(20, 50)
    x, y = rng.uniform(40, 200 - 40 - w), rng.uniform(40, 160 - 40 - h)
    image[int(round(y)):int(round(y + h)), int(round(x)):int(round(x + w))] = rng.integers(0, 256, 3)
    truth = np.array([round(x), round(y), round(x + w) - round(x), round(y + h) - round(y)], float)
    box = truth + np.concatenate([rng.normal(0, 0.12, 2) * truth[2:], np.zeros(2)])
    box[2:] *= np.exp(rng.normal(0, 0.12, 2))
    return image, truth, box


def test_image_features_place_a_contrasting_blob_in_the_box_coordinates():
    name = {n: k for k, n in enumerate(image_feature_names(32))}
    image = np.full((160, 200, 3), 90, np.uint8)
    image[60:100, 70:130] = (30, 40, 200)                           # a 60 x 40 px vehicle on even ground
    on, right = image_features(image, np.array([[70, 60, 60, 40], [76, 60, 60, 40]], float), 1.3, 32)
    assert on.shape == (len(image_feature_names(32)),) and np.isfinite(on).all()
    # an even blob: 5 % of its contrast mass lies in its first 5 % (box coordinates: 0 its left edge, 1 its right)
    assert on[name["contrast_x_q5"]] == pytest.approx(0.05, abs=0.06) and on[name["contrast_x_q95"]] == pytest.approx(
        0.95, abs=0.06)
    assert on[name["grad_x_peak_left"]] == pytest.approx(0.0, abs=0.08)
    assert on[name["grad_y_peak_bottom"]] == pytest.approx(1.0, abs=0.08)
    # the box 6 px (a tenth of its width) right of the vehicle: the vehicle's left edge shows at -0.1
    assert right[name["contrast_x_q5"]] - on[name["contrast_x_q5"]] == pytest.approx(-0.1, abs=0.04)
    assert right[name["grad_x_peak_left"]] == pytest.approx(-0.1, abs=0.05)
    assert right[name["contrast_y_q5"]] == pytest.approx(on[name["contrast_y_q5"]], abs=0.03)
    # a box at and beyond the frame's corner still reads a region (reflected), finite
    assert np.isfinite(image_features(image, np.array([[-20.0, 150.0, 40.0, 30.0]]), 1.3, 32)).all()


def test_fitted_image_stages_move_boxes_onto_the_blobs_and_round_trip_through_json(tmp_path):
    rng = np.random.default_rng(3)
    train, test = [_blob_scene(rng) for _ in range(400)], [_blob_scene(rng) for _ in range(100)]
    member = np.zeros((1, len(FEATURES)))
    regressor = BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), np.zeros((len(FEATURES), 4)))
    boxes = np.array([b for _, _, b in train])
    for _ in range(2):
        x = np.vstack([image_stage_features(img, b[None], member, 1.3, 32) for (img, _, _), b in zip(train, boxes)])
        stage = fit_image_stage(x, edge_offsets(boxes, np.array([t for _, t, _ in train])), 1.3, 32, l2=1.0)
        regressor.image_stages.append(stage)
        boxes = np.vstack([stage.refine(img, b[None], member) for (img, _, _), b in zip(train, boxes)])
    path = tmp_path / "image.json"
    regressor.save(path)
    loaded = BoxRegressor.load(path)
    assert json.loads(path.read_text())["version"] == 2 and len(loaded.image_stages) == 2
    before = np.array([box_iou(b, t) for _, t, b in test])
    after = np.array([box_iou(loaded.refine_image(img, b[None], member)[0], t) for img, t, b in test])
    assert np.mean(before) < 0.75 and np.mean(after) > np.mean(before) + 0.1
    assert np.allclose(loaded.refine_image(*test[0][::2], member), regressor.refine_image(*test[0][::2], member))
    assert np.array_equal(regressor.refine_image(test[0][0], np.zeros((0, 4)), np.zeros((0, len(FEATURES)))).shape,
                          (0, 4))


@pytest.mark.parametrize("change", [
    {"version": 1}, {"image_stages": []}, {"image_stages": [{"grow": 1.3}]}, {"image_stages": "x"},
    {"image_stages": [{"grow": 9.0, "size": 32}]}, {"version": 2, "features": ["a"]}])
def test_a_malformed_image_stage_is_refused(tmp_path, change):
    n = 1 + len(image_feature_names(16)) + len(FEATURES) - 1
    stage = ImageStage(1.3, 16, np.zeros(n), np.ones(n), np.zeros((n, 4)))
    good = BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), np.zeros((len(FEATURES), 4)),
                        image_stages=[stage]).to_dict()
    path = tmp_path / "good.json"
    path.write_text(json.dumps(good))
    assert len(BoxRegressor.load(path).image_stages) == 1
    path.write_text(json.dumps({**good, **change}))
    with pytest.raises(BoxRegressorError):
        BoxRegressor.load(path)


def test_image_stages_move_the_verified_groups_and_need_the_verifier(tmp_path):
    verifier = accept_all_verifier(tmp_path)
    n = 1 + len(image_feature_names(16)) + len(FEATURES) - 1
    weights = np.zeros((n, 4))
    weights[0] = (-0.1, 0.1, -0.1, 0.1)                            # every edge 10 % outwards
    regressor = tmp_path / "r.json"
    BoxRegressor(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), np.zeros((len(FEATURES), 4)),
                 image_stages=[ImageStage(1.3, 16, np.zeros(n), np.ones(n), weights)]).save(regressor)
    with pytest.raises(ConfigError, match="needs the verifier"):
        validate(DetectorConfig(box_regressor=str(regressor)))
    a, b = _without_and_with(verifier, regressor)
    assert len(a) == 2 and len(b) == 2
    assert np.allclose(b["w"], a["w"] * 1.2) and np.allclose(b["y"] + b["h"] / 2, a["y"] + a["h"] / 2)
    assert np.allclose(b["score"], a["score"])


def _without_and_with(verifier, regressor):
    """The detections of two UAV detectors with ``verifier``, without and with the box regressor ``regressor``, on the
    same five raw windows (two groups): only the grouping and what follows it run."""
    image = np.full((240, 320, 3), 120, np.uint8)
    windows = np.array([[50, 60, 48, 24], [54, 60, 48, 24], [50, 64, 48, 24], [200, 150, 24, 48], [204, 150, 24, 48]],
                       float)
    margins = np.array([2.0, 1.5, 1.2, 3.0, 2.5])
    found = []
    for extra in ({}, {"box_regressor": str(regressor)}):
        det = Detector(validate(DetectorConfig(model="uav_vehicles_heading_all_views.json", verifier=str(verifier),
                                               min_neighbors=2, containment=1.0, window_margin=1.0, **extra)))
        # the scan behind detect()
        det._raw = lambda image, gray, margin: Windows(windows, margins, box_to_quad(windows))
        found.append(det.detect(image))
    return found
