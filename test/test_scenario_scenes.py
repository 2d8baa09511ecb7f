"""Synthetic scenes: the ground truth matches what is drawn; the scenes do what the issue asks."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.evaluation.sot_metrics import polygon_iou
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig, template_corners
from aircraft_docking_tracker.scenarios.uav import STATE_HIDDEN, UavScene, UavSceneConfig, synthesize_detections


def _polygon_mask(quad, shape):
    mask = np.zeros(shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(quad * 16).astype(np.int32), 1, cv2.LINE_8, shift=4)
    return mask.astype(bool)


@pytest.fixture(scope="module")
def docking_frames():
    scene = DockingScene(DockingSceneConfig(frames=40, difficulty=0, weather="clear", occluder="vehicle"), seed=5)
    return scene, list(scene.frames())


def test_docking_aircraft_pixels_lie_inside_the_ground_truth_quad(docking_frames):
    scene, frames = docking_frames
    for f in frames[::5]:
        drawn = f.mask > 0.5
        inside = _polygon_mask(f.quad, drawn.shape)
        inside = cv2.dilate(inside.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        assert drawn.sum() > 50
        assert (drawn & ~inside).sum() / drawn.sum() < 0.005          # nothing drawn outside the GT
        fill = drawn.sum() / max(_polygon_mask(f.quad, drawn.shape).sum(), 1)
        assert 0.08 < fill < 0.6                                        # an aircraft, not a rectangle
        nose = np.round(f.nose).astype(int)
        assert f.mask[nose[1], nose[0]] > 0.5                           # the nose point is on the aircraft


def test_docking_pixels_differ_from_background_where_the_aircraft_is(docking_frames):
    scene, frames = docking_frames
    f = frames[-1]
    diff = np.abs(f.image.astype(np.int16) - scene.background.astype(np.int16)).max(axis=2)
    on = f.visible > 0.9
    off = ~cv2.dilate(_polygon_mask(f.quad, on.shape).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert np.median(diff[on]) > 3 * np.median(diff[off]) + 10


def test_docking_grows_turns_and_stops(docking_frames):
    scene, frames = docking_frames
    first, last = frames[0].quad, frames[-1].quad
    growth = np.linalg.norm(last[1] - last[0]) / np.linalg.norm(first[1] - first[0])
    assert growth >= 4.0
    angle = lambda q: np.degrees(np.arctan2(*(q[1] - q[0])[::-1]))   # noqa: E731
    assert 20.0 <= abs(angle(first) - angle(last)) <= 40.0
    np.testing.assert_allclose(frames[-1].nose_ground, [0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(frames[-1].quad, frames[-2].quad)       # standing at the stop line
    stand = json.loads(scene.stand_json())
    np.testing.assert_allclose(stand["stop_nose_image"], frames[-1].nose, atol=0.01)
    assert len(stand["lead_in_ground"]) == len(stand["lead_in_image"]) > 10
    assert stand["stop_line_image"][0][1] > frames[-1].nose[1]         # the stop bar is on the apron below


def test_docking_ground_truth_is_the_affine_image_of_the_template(docking_frames):
    _, frames = docking_frames
    f = frames[20]
    corners = template_corners() @ f.affine[:2, :2].T + f.affine[:2, 2]
    np.testing.assert_allclose(f.quad, corners)
    assert polygon_iou(f.quad, corners)[0] == pytest.approx(1.0)


def test_docking_vehicle_occludes_part_of_the_aircraft(docking_frames):
    _, frames = docking_frames
    occluded = [f.occluded_fraction for f in frames]
    assert 0.02 < max(occluded) < 0.9
    assert min(occluded) == 0.0


def test_docking_is_deterministic_by_seed_and_supports_720p():
    cfg = DockingSceneConfig(width=1280, height=720, frames=12, fps=25.0, difficulty=2)
    a = [f.image for f in DockingScene(cfg, seed=11).frames()]
    b = [f.image for f in DockingScene(cfg, seed=11).frames()]
    c = [f.image for f in DockingScene(cfg, seed=12).frames()]
    assert a[0].shape == (720, 1280, 3)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[5], c[5])


def test_docking_weather_changes_the_image():
    base = dict(frames=3, difficulty=1, occluder="none")
    clear = next(DockingScene(DockingSceneConfig(weather="clear", **base), seed=2).frames()).image
    rain = next(DockingScene(DockingSceneConfig(weather="rain", **base), seed=2).frames()).image
    sun = next(DockingScene(DockingSceneConfig(weather="low_sun", **base), seed=2).frames()).image
    assert np.abs(clear.astype(int) - rain.astype(int)).mean() > 5
    assert sun.mean() > clear.mean() + 5


@pytest.fixture(scope="module")
def uav_nadir():
    cfg = UavSceneConfig(frames=60, difficulty=0, view="nadir", min_in_frame=0.0, vehicles=8)
    scene = UavScene(cfg, seed=4)
    scene.noise_sigma = 0.0          # compare pixels exactly
    return scene, list(scene.frames())


def test_uav_vehicle_pixels_lie_in_their_boxes(uav_nadir):
    scene, frames = uav_nadir
    for f in frames[::10]:
        empty = cv2.warpPerspective(scene.world, f.homography, (scene.config.width, scene.config.height),
                                    flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        changed = np.abs(f.image.astype(np.int16) - empty.astype(np.int16)).max(axis=2) > 30
        boxes = np.zeros_like(changed)
        for r in f.ground_truth:
            x0, y0 = int(np.floor(r["x"])) - 2, int(np.floor(r["y"])) - 2
            x1, y1 = int(np.ceil(r["x"] + r["w"])) + 2, int(np.ceil(r["y"] + r["h"])) + 2
            boxes[max(y0, 0):y1, max(x0, 0):x1] = True
            if r["score"] > 0.9 and r["w"] * r["h"] > 150:
                box_changed = changed[int(r["y"]):int(r["y"] + r["h"]), int(r["x"]):int(r["x"] + r["w"])]
                assert box_changed.mean() > 0.2, f"vehicle {r['id']} not drawn in its box"
        assert changed.sum() > 0
        assert (changed & ~boxes).sum() == 0, "pixels changed outside every ground-truth box"


def test_uav_ground_truth_rows_are_sane(uav_nadir):
    scene, frames = uav_nadir
    for f in frames:
        gt = f.ground_truth
        assert len(np.unique(gt["id"])) == len(gt)
        assert (gt["x"] >= 0).all() and (gt["x"] + gt["w"] <= scene.config.width + 1e-3).all()
        assert ((gt["score"] >= 0) & (gt["score"] <= 1)).all()
    sizes = np.concatenate([np.maximum(f.ground_truth["w"], f.ground_truth["h"]) for f in frames
                            if len(f.ground_truth)])
    assert 10 < np.median(sizes) < 70


def test_uav_normal_scene_hides_and_moves_vehicles():
    scene = UavScene(UavSceneConfig(frames=150, difficulty=1), seed=8)
    assert 3 <= scene.n_vehicles <= 30
    hidden_runs = {}
    present = {}
    for f in scene.frames():
        for r in f.ground_truth:
            present.setdefault(int(r["id"]), []).append(f.index)
            if r["state"] == STATE_HIDDEN:
                hidden_runs[int(r["id"])] = max(hidden_runs.get(int(r["id"]), 0), int(r["misses"]))
    assert max(hidden_runs.values(), default=0) >= 10           # someone hides for a while
    spans = [(min(v), max(v)) for v in present.values()]
    assert any(a > 0 or b < 149 for a, b in spans)              # someone enters or leaves
    speeds = np.linalg.norm(np.diff(scene.track[:, :, :2], axis=1), axis=2)
    assert speeds.max() > 1.5 and speeds.min() < 1.0             # accelerating and braking


def test_uav_is_deterministic_by_seed():
    cfg = UavSceneConfig(frames=5, difficulty=2)
    a = list(UavScene(cfg, seed=3).frames())
    b = list(UavScene(cfg, seed=3).frames())
    assert all(np.array_equal(x.image, y.image) and np.array_equal(x.ground_truth, y.ground_truth)
               for x, y in zip(a, b))


def test_uav_lower_camera_scales_vehicles_and_keeps_the_default_scene():
    """ground_resolution is the camera height: vehicles' boxes grow by it; 1 is the default scene exactly."""
    base = UavSceneConfig(frames=6, difficulty=0, view="nadir", min_in_frame=1.0)
    default = list(UavScene(base, seed=5).frames())
    same = list(UavScene(UavSceneConfig(frames=6, difficulty=0, view="nadir", min_in_frame=1.0,
                                        ground_resolution=1.0), seed=5).frames())
    assert all(np.array_equal(a.image, b.image) for a, b in zip(default, same))
    low = list(UavScene(UavSceneConfig(frames=6, difficulty=0, view="nadir", min_in_frame=1.0,
                                       ground_resolution=2.0), seed=5).frames())
    # same vehicles, headings and camera path, seen from half the height: each box side about doubles
    ratios = []
    for a, b in zip(default, low):
        common = np.intersect1d(a.ground_truth["id"], b.ground_truth["id"])
        for vid in common:
            ra, rb = a.ground_truth[a.ground_truth["id"] == vid][0], b.ground_truth[b.ground_truth["id"] == vid][0]
            ratios.append(np.sqrt((rb["w"] * rb["h"]) / (ra["w"] * ra["h"])))
    assert len(ratios) >= 3
    assert 1.8 < np.median(ratios) < 2.2


def test_synthesize_detections():
    gt = np.zeros(3, dtype=UavFrame_dtype())
    gt["id"] = [1, 2, 3]
    gt["x"], gt["y"], gt["w"], gt["h"] = [10, 100, 200], [10, 50, 90], 20, 12
    gt["score"] = [1.0, 0.9, 0.1]                               # the third is hidden
    rng = np.random.default_rng(0)
    exact = synthesize_detections(gt, rng, miss_rate=0.0, clutter_rate=0.0, jitter_px=0.0)
    assert len(exact) == 2
    np.testing.assert_allclose(exact["x"], [10, 100])
    np.testing.assert_allclose(exact["w"], [20, 20])
    only_clutter = synthesize_detections(gt, rng, miss_rate=1.0, clutter_rate=50.0, jitter_px=0.0)
    assert len(only_clutter) > 20 and (only_clutter["x"] >= 0).all()
    with pytest.raises(ValueError):
        synthesize_detections(gt, rng, miss_rate=1.5)


def UavFrame_dtype():
    from aircraft_docking_tracker.object_table import TRACK_DTYPE
    return TRACK_DTYPE
