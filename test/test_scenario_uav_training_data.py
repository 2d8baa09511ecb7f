"""tools/uav_training_data.py --heading: every chip holds its vehicle along x, inside the labelled box."""
from __future__ import annotations

import importlib.util

import cv2
import numpy as np

from aircraft_docking_tracker.scenarios.uav import STATE_VISIBLE, UAV_TRAIN_SEEDS, UavScene, UavSceneConfig, detection_truth
from multi_target_tracker.train_cascade import truncated

from conftest import REPO


def load_tool():
    spec = importlib.util.spec_from_file_location("uav_training_data", REPO / "tools" / "uav_training_data.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_heading_chips_turn_each_vehicle_along_x():
    """On a training scene's frame with everything but the vehicles blanked out, the chip cut with the scene's
    own heading (no turn jitter) shows a blob longer along x than along y, centred in the box, about the box's
    size without its context; turned by 90 degrees more, the same vehicle lies along y."""
    tool = load_tool()
    scene = UavScene(UavSceneConfig(frames=24, difficulty=0, ground_resolution=3.0), seed=UAV_TRAIN_SEEDS[0])
    checked = 0
    for k, frame in enumerate(scene.frames()):
        if k % 6 != 3:
            continue
        boxes, ignore = detection_truth(frame.ground_truth)
        counted = ~ignore & ~truncated(boxes, (frame.image.shape[1], frame.image.shape[0]))
        for vid in frame.ground_truth["id"][counted]:
            v = int(vid) - 1
            mask = np.zeros(frame.image.shape[:2], np.uint8)   # this vehicle's footprint only
            sh, sw = scene.sprites[v][1].shape
            a = scene.vehicle_affine(v, k)
            corners = np.array([[0, 0], [sw, 0], [sw, sh], [0, sh]], np.float64) @ a[:2, :2].T + a[:2, 2]
            cv2.fillConvexPoly(mask, np.round(cv2.perspectiveTransform(corners[None], frame.homography)[0])
                               .astype(np.int32), 255)
            centre, length, width, heading = tool.vehicle_axes(scene, v, k, frame.homography)
            assert length > width > 0
            chip, box = tool.heading_chip(np.dstack([mask] * 3), centre, length, width, heading, 1.25)
            ys, xs = np.nonzero(chip[..., 0] > 128)
            extent_x, extent_y = np.ptp(xs) + 1, np.ptp(ys) + 1
            assert extent_x > 1.4 * extent_y, (vid, extent_x, extent_y)
            x, y, w, h = box
            assert abs(xs.mean() - (x + w / 2)) < 0.1 * w and abs(ys.mean() - (y + h / 2)) < 0.15 * h
            assert 0.6 * w < extent_x <= w and extent_y <= h                   # inside the 1.25x context box
            across, _ = tool.heading_chip(np.dstack([mask] * 3), centre, length, width, heading + 90, 1.25)
            ys, xs = np.nonzero(across[..., 0] > 128)
            assert np.ptp(ys) > np.ptp(xs)
            checked += 1
    assert checked >= 5


def test_partly_visible_chips_are_added_beside_the_same_counted_chips(tmp_path):
    """--partly-visible V adds pSEED_ chips of the vehicles V to 70 % visible (not cut by the border), from their own
    random stream: the counted vehicles' cSEED_ chips are the same files as without it."""
    tool = load_tool()
    seed = UAV_TRAIN_SEEDS[0] + 1                      # difficulty 2: canopy and smoke over some vehicles
    common = ["--heading", "--seeds", str(seed), str(seed), "--frames", "48", "--every", "8"]
    assert tool.main([str(tmp_path / "plain")] + common) == 0
    assert tool.main([str(tmp_path / "partly"), "--partly-visible", "0.4"] + common) == 0
    plain = sorted(p.name for p in (tmp_path / "plain" / "images").iterdir())
    partly = sorted(p.name for p in (tmp_path / "partly" / "images").iterdir())
    added = [n for n in partly if n.startswith("p")]
    assert [n for n in partly if not n.startswith("p")] == plain and added
    for name in (n for n in plain if n.startswith("c")):
        assert (tmp_path / "plain" / "images" / name).read_bytes() == (tmp_path / "partly" / "images" / name).read_bytes()
    scene = UavScene(UavSceneConfig(frames=48, difficulty=(1, 2, 1, 2, 0)[seed % 5], ground_resolution=3.0), seed=seed)
    expected = set()
    for k, frame in enumerate(scene.frames()):
        if k % 8 != 4:
            continue
        gt = frame.ground_truth
        boxes, _ = detection_truth(gt)
        cut = truncated(boxes, (frame.image.shape[1], frame.image.shape[0]))
        partly_seen = (gt["state"] == STATE_VISIBLE) & (gt["score"] >= 0.4) & (gt["score"] < 0.7) & ~cut
        expected |= {f"p{seed:04d}_f{k:03d}_v{int(v):02d}_{t}.png" for v in gt["id"][partly_seen] for t in (0, 1)}
    assert set(added) == expected
