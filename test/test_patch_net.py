"""The patch network (multi_target_tracker/patch_net.py): its patch geometry, its model files, the detector with it."""
from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError, validate
from aircraft_docking_tracker.geometry import box_iou
from aircraft_docking_tracker.scenarios.uav import (
    UAV_EVAL_SEEDS, UAV_SETUP_GROUND_RESOLUTION, UavScene, UavSceneConfig, detection_truth)
from multi_target_tracker.detector import Detector, DetectorConfig, DetectorError, resolve_model
from multi_target_tracker.patch_net import (
    OUTPUTS, PATCH_NET_FORMAT, PATCH_NET_VERSION, PatchNet, PatchNetError, decode_boxes, encode_boxes, patches,
    square_regions)

SHIPPED = "uav_vehicles_patch_net.json"


def test_regions_are_squares_of_the_longer_side_about_the_box_centre():
    regions = square_regions(np.array([[10.0, 20.0, 40.0, 20.0], [0.0, 0.0, 10.0, 30.0]]), 1.5)
    np.testing.assert_allclose(regions, [[30.0, 30.0, 60.0], [5.0, 15.0, 45.0]])


def test_box_edges_encode_and_decode_back_and_are_cut_to_the_frame():
    rng = np.random.default_rng(0)
    boxes = np.column_stack([rng.uniform(50, 400, 20), rng.uniform(50, 300, 20), rng.uniform(10, 90, (20, 2))])
    regions = square_regions(boxes + rng.normal(0, 5, boxes.shape), 1.6)
    edges = encode_boxes(boxes, regions)
    np.testing.assert_allclose(decode_boxes(edges, regions, (640, 480)), boxes, atol=1e-9)
    # a box past the frame's corner keeps its part inside
    regions = square_regions(np.array([[600.0, 450.0, 60.0, 60.0]]), 1.6)
    cut = decode_boxes(encode_boxes(np.array([[600.0, 450.0, 60.0, 60.0]]), regions), regions, (640, 480))
    np.testing.assert_allclose(cut, [[600.0, 450.0, 40.0, 30.0]])


def test_patches_show_the_region_around_the_box_with_the_frame_reflected():
    image = np.zeros((120, 160, 3), np.uint8)
    image[40:60, 60:100] = (0, 0, 255)                    # a red 40x20 "vehicle"
    crop = patches(image, np.array([[60.0, 40.0, 40.0, 20.0]]), 32, 2.0)[0]
    # the region is 80 px a side, 0.4 px of patch a pixel: the vehicle is the central 16x8 patch pixels
    red = crop[:, :, 2] > 128
    rows, cols = np.flatnonzero(red.any(axis=1)), np.flatnonzero(red.any(axis=0))
    assert abs(rows.min() - 12) <= 1 and abs(rows.max() - 19) <= 1
    assert abs(cols.min() - 8) <= 1 and abs(cols.max() - 23) <= 1
    # beyond the frame's edge the image is reflected, not black
    edge = np.zeros((120, 160, 3), np.uint8)
    edge[:, :10] = 200
    crop = patches(edge, np.array([[0.0, 50.0, 20.0, 20.0]]), 32, 2.0)[0]
    assert (crop[:, :8] > 100).all()
    with pytest.raises(PatchNetError, match="BGR uint8"):
        patches(image[:, :, 0], np.array([[0.0, 0.0, 10.0, 10.0]]), 32, 2.0)


@pytest.fixture(scope="module")
def shipped():
    return PatchNet.load(resolve_model(SHIPPED))


def test_the_shipped_network_is_small_and_gives_finite_outputs(shipped):
    header = resolve_model(SHIPPED)
    graph = header.with_suffix(".onnx")
    assert graph.stat().st_size < 5_000_000 and shipped.size == 48 and 1.0 < shipped.grow < 3.0
    assert shipped.info["train_seeds"] and shipped.info["vehicles"] > 1000 and shipped.info["background"] > 1000
    rng = np.random.default_rng(1)
    out = shipped.forward(rng.integers(0, 256, (5, shipped.size, shipped.size, 3), dtype=np.uint8))
    assert out.shape == (5, len(OUTPUTS)) and np.isfinite(out).all()
    assert shipped.forward(np.zeros((0, shipped.size, shipped.size, 3), np.uint8)).shape == (0, len(OUTPUTS))


def test_the_shipped_network_moves_shifted_boxes_onto_held_out_vehicles_and_tells_them_from_ground(shipped):
    """Held-out UAV scenes (never trained or tuned on): each whole, uncut vehicle's box shifted by a quarter of its
    width (IoU 0.6 with it) is moved back towards it, with log odds that say vehicle, and boxes on bare ground get
    log odds that say background (measured on these frames: median IoU 0.60 -> 0.73, log odds 3-10 on the vehicles
    and -6 to -9 on the ground)."""
    rng = np.random.default_rng(3)
    config = UavSceneConfig(frames=80, fps=10.0, difficulty=1, ground_resolution=UAV_SETUP_GROUND_RESOLUTION)
    before, after, vehicle_logit, ground_logit = [], [], [], []
    for seed in UAV_EVAL_SEEDS[900:902]:
        for k, frame in enumerate(UavScene(config, seed=seed).frames()):
            if k % 20 != 10:
                continue
            truth, hidden = detection_truth(frame.ground_truth, 0.9)
            inside = ((truth[:, 0] > 5) & (truth[:, 1] > 5) & (truth[:, 0] + truth[:, 2] < 635)
                      & (truth[:, 1] + truth[:, 3] < 475) & ~hidden)
            shifted = truth[inside] + np.column_stack([0.25 * truth[inside, 2], np.zeros((inside.sum(), 3))])
            logit, moved = shipped.predict(frame.image, shifted)
            before += box_iou(shifted, truth[inside]).tolist()
            after += box_iou(moved, truth[inside]).tolist()
            vehicle_logit += logit.tolist()
            ground = []
            while len(ground) < 5:
                box = np.array([rng.uniform(0, 580), rng.uniform(0, 420), 50.0, 30.0])
                if not len(truth) or box_iou(box[None], truth).max() < 0.01:
                    ground.append(box)
            ground_logit += shipped.predict(frame.image, np.array(ground))[0].tolist()
    assert len(before) >= 30, len(before)
    assert np.median(after) >= np.median(before) + 0.05, (np.median(before), np.median(after))
    assert np.mean(np.array(vehicle_logit) > 0) >= 0.8, vehicle_logit
    assert np.mean(np.array(ground_logit) < 0) >= 0.9, ground_logit


def _header(tmp_path, **changes):
    shutil.copy(resolve_model(SHIPPED).with_suffix(".onnx"), tmp_path / "net.onnx")
    header = {"format": PATCH_NET_FORMAT, "version": PATCH_NET_VERSION, "outputs": list(OUTPUTS), "onnx": "net.onnx",
              "size": 48, "grow": 1.6, "info": {}, **changes}
    path = tmp_path / "net.json"
    path.write_text(json.dumps(header))
    return path


@pytest.mark.parametrize("changes, message", [
    ({"format": "something/else"}, "not a"),
    ({"version": 9}, "version 9 unsupported"),
    ({"outputs": ["log_odds"]}, "outputs"),
    ({"size": 4}, "size 4"),
    ({"size": 40}, "does not run"),
    ({"grow": "big"}, "grow"),
    ({"onnx": "../net.onnx"}, "file name beside"),
    ({"onnx": "missing.onnx"}, "cannot read its graph"),
])
def test_a_bad_header_is_refused_with_its_reason(tmp_path, changes, message):
    with pytest.raises(PatchNetError, match=message):
        PatchNet.load(_header(tmp_path, **changes))


def test_a_graph_that_is_not_onnx_is_refused(tmp_path):
    path = _header(tmp_path)
    (tmp_path / "net.onnx").write_bytes(b"\x08\x07 not a protobuf graph" * 10)
    with pytest.raises(PatchNetError, match="cannot read it as ONNX|does not run"):
        PatchNet.load(path)
    path.write_text("{not json")
    with pytest.raises(PatchNetError, match="cannot read patch network"):
        PatchNet.load(path)


def test_the_detector_config_refuses_a_patch_net_without_a_verifier_or_that_does_not_load(tmp_path):
    with pytest.raises(ConfigError, match="needs the verifier"):
        validate(DetectorConfig(patch_net=SHIPPED))
    bad = _header(tmp_path, version=9)
    with pytest.raises(ConfigError, match="patch network"):
        validate(DetectorConfig(verifier="uav_vehicles_verifier_trees.json", patch_net=str(bad)))
    with pytest.raises(DetectorError, match="version 9"):
        Detector(DetectorConfig(verifier="uav_vehicles_verifier_trees.json", patch_net=str(bad)))


def test_the_detector_config_refuses_a_patch_net_beside_a_box_regressor_with_image_stages():
    """Both would place the published box: the configuration says which one does, rather than one being skipped."""
    trees = "uav_vehicles_verifier_trees.json"
    with pytest.raises(ConfigError, match="image stages") as refused:
        validate(DetectorConfig(verifier=trees, patch_net=SHIPPED, box_regressor="uav_vehicles_box_regressor_image.json"))
    assert set(refused.value.fields) == {"patch_net", "box_regressor"}
    validate(DetectorConfig(verifier=trees, patch_net=SHIPPED, box_regressor="uav_vehicles_box_regressor.json"))
    validate(DetectorConfig(verifier=trees, box_regressor="uav_vehicles_box_regressor_image.json"))


def test_each_detector_has_its_own_network():
    """OpenCV's network keeps its input between calls: two detectors (two nodes in one process) must not share one."""
    config = DetectorConfig(verifier="uav_vehicles_verifier_trees.json", patch_net=SHIPPED)
    a, b = Detector(config), Detector(dataclasses.replace(config))
    assert a.patch_net is not None and a.patch_net.net is not b.patch_net.net
