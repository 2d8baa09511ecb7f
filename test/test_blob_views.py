"""Colour blobs as extra cascade views (multi_target_tracker/blob_views.py) and their place in the detector."""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError, load_yaml_parameters, package_config_dir, validate
from aircraft_docking_tracker.geometry import box_iou
from aircraft_docking_tracker.offline import build_processor
from aircraft_docking_tracker.scenarios.uav import (UAV_SETUP_GROUND_RESOLUTION, UAV_TUNING_SEEDS, UavScene,
                                                    UavSceneConfig)
from multi_target_tracker.blob_views import MAX_BLOBS, Blob, _row_ends, blob_view, colour_blobs, window_height
from multi_target_tracker.detector import Detector, DetectorConfig, DetectorError
from multi_target_tracker.train_cascade import read_yolo_folder, truncated
from conftest import require_data

GROUND = (70, 140, 90)       # BGR: a green field
PAINT = (190, 70, 40)        # a blue car
ASPECT, CONTEXT = 2.0, 1.25  # the UAV model's 48x24 window and its chips' context
SETUP = package_config_dir() / "uav_camera.yaml"


def test_the_row_ends_of_each_region_keep_its_convex_hull():
    """colour_blobs hands cv2.minAreaRect each region's first and last pixel per row: the same hull (vertices and
    area) as all its pixels, region by region, for blobs, rings, single rows and columns, points in any order."""
    rng = np.random.default_rng(5)
    regions = []
    for k in range(40):
        mask = np.zeros((40, 50), np.uint8)
        centre = (int(rng.integers(10, 40)), int(rng.integers(10, 30)))
        axes = (int(rng.integers(1, 15)), int(rng.integers(0, 12)))
        cv2.ellipse(mask, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, -1 if k % 3 else 2)
        ys, xs = np.nonzero(mask)
        regions.append(rng.permutation(np.column_stack([xs, ys]).astype(np.int32)))
    regions += [np.array([[5, 7], [6, 7], [9, 7]], np.int32), np.array([[3, 2], [3, 9], [3, 4]], np.int32)]
    counts = np.array([len(r) for r in regions])
    ends, firsts, sizes = _row_ends(np.concatenate(regions), counts)
    assert sizes.sum() < counts.sum() / 2
    for region, first, size in zip(regions, firsts, sizes):
        kept = ends[first:first + size]
        assert {tuple(p) for p in kept} <= {tuple(p) for p in region}
        hull, full = cv2.convexHull(kept).reshape(-1, 2), cv2.convexHull(region).reshape(-1, 2)
        assert {tuple(p) for p in hull} == {tuple(p) for p in full}
        assert cv2.contourArea(hull) == cv2.contourArea(full)


def _field(shape=(480, 640)) -> np.ndarray:
    rng = np.random.default_rng(0)
    noise = rng.normal(0, 3, (*shape, 3))
    return np.clip(np.array(GROUND, float) + noise, 0, 255).astype(np.uint8)


def _car(image, centre, size, angle, colour=PAINT):
    corners = cv2.boxPoints((centre, size, angle)).astype(np.int32)
    cv2.fillPoly(image, [corners], colour)
    return image


def _axis_difference(a: float, b: float) -> float:
    """Angle between two undirected axes [deg], in [0, 90]."""
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0, 71.0, 100.0, 152.0])
def test_a_painted_rectangle_is_one_blob_with_its_centre_axis_and_sides(angle):
    image = _car(_field(), (300.0, 250.0), (90.0, 40.0), angle)
    blobs = colour_blobs(image, 122.0, 0.5, ASPECT, CONTEXT, 25.0, 106.0)
    blob = blobs[0]                                      # the best filled
    assert abs(blob.x - 300) < 3 and abs(blob.y - 250) < 3
    assert abs(blob.length - 90) < 5 and abs(blob.width - 40) < 5    # its pixels' centres: about a pixel short
    assert _axis_difference(blob.angle, angle) < 4
    assert 0.85 < blob.fill <= 1.1
    for other in blobs[1:]:     # the car with the ground next to it (its colour leaks into that ground's mean)
        assert abs(other.x - 300) < 4 and abs(other.y - 250) < 4 and other.length > blob.length


@pytest.mark.parametrize("angle", [0.0, 30.0, 118.0])
def test_a_quarter_size_search_finds_the_same_rectangle_at_a_quarter_of_the_cost(angle):
    """``scale`` 0.25 (the drone-view set-up's ``blob_scale``): the same blob, its sides a few pixels coarser (the
    pixels' centres of a 4x smaller map: about 4 px short), over a quarter of the pixels."""
    image = _car(_field(), (300.0, 250.0), (90.0, 40.0), angle)
    half = colour_blobs(image, 122.0, 0.5, ASPECT, 1.0, 32.0, 90.0)[0]
    quarter = colour_blobs(image, 122.0, 0.5, ASPECT, 1.0, 32.0, 90.0, scale=0.25)[0]
    # centres within the small map's pixel (colour_blobs maps its pixel i to i / scale: 1.5 px up-left at a quarter)
    assert abs(half.x - 300) < 2 and abs(half.y - 250) < 2 and abs(quarter.x - 300) < 3 and abs(quarter.y - 250) < 3
    assert abs(quarter.length - 90) < 9 and abs(quarter.width - 40) < 9
    assert _axis_difference(quarter.angle, angle) < 6
    small = _car(_field(), (300.0, 250.0), (24.0, 12.0), angle)     # 6 x 3 px at a quarter: still its rectangle
    blob = colour_blobs(small, 122.0, 0.5, ASPECT, 1.0, 8.0, 90.0, scale=0.25)[0]
    assert abs(blob.x - 300) < 3 and abs(blob.y - 250) < 3 and abs(blob.length - 24) < 6 and abs(blob.width - 12) < 6


def test_a_patch_that_does_not_fill_its_rectangle_or_is_too_small_is_not_a_blob():
    image = _field()
    triangle = np.array([[100, 100], [190, 100], [100, 150]], np.int32)    # fills half its rectangle
    cv2.fillPoly(image, [triangle], PAINT)
    _car(image, (450.0, 120.0), (12.0, 6.0), 30.0)                         # far below the smallest window
    assert colour_blobs(image, 122.0, 0.6, ASPECT, CONTEXT, 25.0, 106.0) == []
    loose = colour_blobs(image, 122.0, 0.3, ASPECT, CONTEXT, 25.0, 106.0)   # a looser fill takes the triangle
    assert len(loose) >= 1 and all(abs(b.x - 130) < 20 and abs(b.y - 117) < 20 for b in loose)
    assert colour_blobs(image, 122.0, 0.3, ASPECT, CONTEXT, 25.0, 40.0) == []   # its window above the range


def test_blobs_are_capped_best_filled_first():
    image = np.full((960, 1280, 3), GROUND, np.uint8)
    for k in range(80):
        _car(image, (60.0 + 130 * (k % 10), 60.0 + 110 * (k // 10)), (60.0, 30.0), 0.0)
    assert len(colour_blobs(image, 122.0, 0.5, ASPECT, CONTEXT, 25.0, 106.0)) == MAX_BLOBS


def test_the_blob_view_lays_the_blob_along_the_window_at_the_chips_scale():
    """The canvas shows the blob along the model window's x axis, centred, at the scale whose window frames it as
    the training chips framed a vehicle (length x width reshaped to the window's 2:1, enlarged 1.25x)."""
    angle = 33.0
    image = cv2.cvtColor(_car(_field(), (320.0, 240.0), (96.0, 44.0), angle), cv2.COLOR_BGR2GRAY)
    blob = Blob(320.0, 240.0, 96.0, 44.0, angle, 1.0)
    canvas, scale, back = blob_view(image, blob, (48, 24), CONTEXT)
    height = window_height(blob, ASPECT, CONTEXT)
    assert scale == pytest.approx(height / 24)
    assert height == pytest.approx(np.sqrt(96 * 44 / 2) * 1.25)
    painted = np.argwhere(canvas < 80)                              # the car is darker than the field in grey
    (y0, x0), (y1, x1) = painted.min(axis=0), painted.max(axis=0)
    assert abs((x1 - x0) - 96) <= 3 and abs((y1 - y0) - 44) <= 3    # along x now
    centre = np.array(canvas.shape[::-1]) / 2
    assert np.allclose([(x0 + x1) / 2, (y0 + y1) / 2], centre, atol=2)
    assert np.allclose(back @ [*centre, 1.0], [320, 240], atol=1e-6)   # the canvas centre is the blob's


def test_blob_views_need_colour_images_and_the_cascade_backend():
    with pytest.raises(ConfigError):
        validate(DetectorConfig(blob_views=True, backend="opencv", model="haarcascade_car.xml"))
    detector = Detector(DetectorConfig(blob_views=True))
    assert detector.needs_colour
    with pytest.raises(DetectorError, match="BGR"):
        detector.detect(np.zeros((120, 160), np.uint8))
    assert detector.detect(np.zeros((120, 160, 3), np.uint8)).size == 0
    for shape in ((1, 1, 3), (2, 3, 3), (7, 5, 3), (9, 12, 3), (10, 10, 3)):   # too small for any blob
        assert detector.detect(np.zeros(shape, np.uint8)).size == 0


def test_blob_views_add_windows_around_the_blobs_and_leave_the_scan_alone():
    """With blob views the raw windows are the scan's, unchanged and first, then those of the blobs' views, each
    about a blob (a frame of a tuning scene through the UAV set-up, with and without them)."""
    frame = next(iter(UavScene(UavSceneConfig(frames=80, fps=10.0, ground_resolution=UAV_SETUP_GROUND_RESOLUTION),
                               seed=UAV_TUNING_SEEDS[0]).frames()))
    plain = build_processor("detector", SETUP, {"blob_views": False}).detector
    viewed = build_processor("detector", SETUP, {"blob_views": True}).detector
    boxes, scores, _ = plain.raw(frame.image)
    more_boxes, more_scores, _ = viewed.raw(frame.image)
    n = len(boxes)
    assert len(more_boxes) > n
    assert np.array_equal(more_boxes[:n], boxes) and np.array_equal(more_scores[:n], scores)
    cfg = viewed.config
    blobs = colour_blobs(frame.image, cfg.blob_background, cfg.blob_min_fill, 2.0, cfg.blob_context,
                         viewed.min_size, viewed.max_size)
    centres = more_boxes[n:, :2] + more_boxes[n:, 2:] / 2
    nearest = np.hypot(*(centres[:, None] - [(b.x, b.y) for b in blobs]).transpose(2, 0, 1)).min(axis=1)
    reach = max(b.length for b in blobs)
    assert (nearest < reach).all()


def _turned_tiles(angle: float, every: int = 25, count: int = 8):
    """Drone-view tiles (prefixes 1_, 4_) turned by ``angle`` degrees about their centre, with the upright boxes of
    their labelled vehicles' turned corners (the vehicles the frame still holds whole)."""
    tiles = require_data("detect/drone-view-vehicles")
    for item in read_yolo_folder(tiles, include=["1_", "4_"])[::every][:count]:
        bgr = item.load_colour()
        h, w = bgr.shape[:2]
        turn = cv2.getRotationMatrix2D((w / 2, h / 2), angle, 1.0)
        boxes = item.boxes[~truncated(item.boxes, (w, h), 1.5)]
        corners = np.stack([boxes[:, :2], boxes[:, :2] + boxes[:, 2:] * (1, 0), boxes[:, :2] + boxes[:, 2:],
                            boxes[:, :2] + boxes[:, 2:] * (0, 1)], axis=1) @ turn[:, :2].T + turn[:, 2]
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        whole = (lo >= 2).all(axis=1) & (hi <= (w - 2, h - 2)).all(axis=1)
        yield cv2.warpAffine(bgr, turn, (w, h), borderMode=cv2.BORDER_REFLECT), np.column_stack([lo, hi - lo])[whole]


@pytest.mark.parametrize("angle", [30.0, 45.0])
def test_the_drone_view_setup_finds_vehicles_at_a_diagonal_heading(angle):
    """config/detector.yaml's blob views on real drone-view tiles turned so that their vehicles lie at a diagonal,
    a heading the upright scan's 64x32 windows (both orientations) overlap poorly: the set-up without the blob views
    finds 4 of 34 at 30 degrees and none at 45; with them 31 and 26 (session 34; 30 and 24 at session 49's grouping,
    with fewer false alarms). The tiles were in the model's
    training, upright only (the held-out figures are bench/detector.py's prefix folds)."""
    params = load_yaml_parameters(package_config_dir() / "detector.yaml", "detector")
    config = DetectorConfig(**{k: v for k, v in params.items() if "." not in k})
    assert config.blob_views
    detectors = {"blobs": Detector(config), "plain": Detector(dataclasses.replace(config, blob_views=False))}
    found, false, detections, vehicles = dict.fromkeys(detectors, 0), dict.fromkeys(detectors, 0), \
        dict.fromkeys(detectors, 0), 0
    for image, truth in _turned_tiles(angle):
        vehicles += len(truth)
        for name, detector in detectors.items():
            table = detector.detect(image)
            if not len(table) or not len(truth):
                continue
            iou = box_iou(np.column_stack([table["x"], table["y"], table["w"], table["h"]])[:, None], truth[None])
            found[name] += int((iou.max(axis=0) >= 0.5).sum())
            false[name] += int((iou.max(axis=1) < 0.5).sum())
            detections[name] += len(table)
    assert vehicles >= 30
    assert found["blobs"] >= 0.6 * vehicles and found["blobs"] >= found["plain"] + 0.4 * vehicles
    assert false["blobs"] <= 0.45 * detections["blobs"]
