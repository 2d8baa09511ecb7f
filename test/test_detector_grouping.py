"""The compiled grouping (group_windows, suppress_contained) gives exactly what the plain Python
greedy loops it replaced gave, on the raw windows of real drone-view tiles and on random boxes."""
import cv2
import numpy as np
import pytest
from scipy.special import expit

from aircraft_docking_tracker.geometry import box_iou
from multi_target_tracker.detector import Detector, DetectorConfig, group_windows, suppress_contained
from multi_target_tracker.train_cascade import read_yolo_folder


def _containment_reference(a, b):
    ix = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    iy = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.clip(ix, 0.0, None) * np.clip(iy, 0.0, None)
    smaller = np.minimum((a[:, 2] * a[:, 3])[:, None], (b[:, 2] * b[:, 3])[None, :])
    return inter / np.maximum(smaller, 1e-12)


def suppress_reference(boxes, scores, containment, limit=None):
    """The former O(n^2) Python loop."""
    order = np.argsort(-scores, kind="stable")
    limit = len(order) if limit is None else limit
    if containment >= 1.0 or len(order) < 2:
        return order[:limit]
    kept = []
    for k in order:
        if len(kept) >= limit:
            break
        if not kept or not (_containment_reference(boxes[k:k + 1], boxes[kept])[0] >= containment).any():
            kept.append(int(k))
    return np.asarray(kept, int)


def group_reference(boxes, margins, group_iou=0.3, min_neighbors=3, containment=0.4, max_detections=500):
    """The former Python loop over seeds (box_iou against every free window)."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    margins = np.asarray(margins, np.float64).reshape(-1)
    order = np.argsort(-margins, kind="stable")
    boxes, margins = boxes[order], margins[order]
    free = np.ones(len(boxes), bool)
    group_boxes, group_scores = [], []
    for seed in range(len(boxes)):
        if not free[seed]:
            continue
        candidates = np.flatnonzero(free)
        members = candidates[box_iou(boxes[seed], boxes[candidates]) >= group_iou]
        members = np.union1d(members, [seed])
        free[members] = False
        if len(members) < min_neighbors:
            continue
        group_boxes.append(boxes[members].mean(axis=0))
        group_scores.append(len(members) + expit(margins[seed]))
    if not group_boxes:
        return np.zeros((0, 4)), np.zeros(0)
    group_boxes, group_scores = np.asarray(group_boxes), np.asarray(group_scores)
    keep = suppress_reference(group_boxes, group_scores, containment, max_detections)
    return group_boxes[keep], group_scores[keep]


SETTINGS = [dict(group_iou=0.3, min_neighbors=3, containment=0.4), dict(group_iou=0.5, min_neighbors=1, containment=0.6),
            dict(group_iou=0.0, min_neighbors=2, containment=0.0), dict(group_iou=0.3, min_neighbors=1, containment=1.0,
                                                                           max_detections=5)]


def _same(boxes, margins, settings):
    new_boxes, new_scores = group_windows(boxes, margins, **settings)
    old_boxes, old_scores = group_reference(boxes, margins, **settings)
    assert new_boxes.shape == old_boxes.shape
    np.testing.assert_allclose(new_boxes, old_boxes, rtol=0, atol=1e-9)
    np.testing.assert_allclose(new_scores, old_scores, rtol=0, atol=1e-12)


@pytest.mark.parametrize("settings", SETTINGS)
def test_grouping_matches_the_python_loop_on_real_tiles(shared_data, settings):
    tiles = read_yolo_folder(shared_data / "detect" / "drone-view-vehicles", include=["1_", "4_", "Drone2_"])
    det = Detector(DetectorConfig(window_margin=-1.0))   # below the trained margin: many raw windows
    total = 0
    for item in tiles[::40][:6]:
        boxes, margins = det.raw(item.load())
        total += len(boxes)
        _same(boxes, margins, settings)
    assert total > 500   # the comparison saw real crowds of overlapping windows


@pytest.mark.parametrize("seed", range(5))
def test_grouping_matches_the_python_loop_on_random_boxes(seed):
    rng = np.random.default_rng(seed)
    n = 300
    boxes = np.column_stack([rng.uniform(0, 200, (n, 2)), rng.uniform(5, 60, (n, 2))])
    boxes[rng.random(n) < 0.05, 2] = 0.0                   # a few empty boxes (IoU 0)
    margins = np.round(rng.normal(size=n), 1)              # ties: the stable order must hold
    for settings in SETTINGS:
        _same(boxes, margins, settings)
        scores = rng.integers(0, 5, n).astype(float)
        for limit in (None, 7):
            assert suppress_contained(boxes, scores, settings["containment"], limit).tolist() == \
                suppress_reference(boxes, scores, settings["containment"], limit).tolist()


@pytest.mark.parametrize("angle", [45.0, -30.0, 135.0])
def test_turned_view_maps_an_aligned_window_back_to_the_objects_upright_box(angle):
    """A bar turned by ``angle`` in the frame lies along x in the view turned by ``angle``; its box there,
    mapped back, is the bar's upright box in the frame (what the ground truth boxes); windows whose
    centre falls in the view's reflected border are dropped."""
    from multi_target_tracker.detector import map_back, turned_view

    gray = np.zeros((240, 320), np.uint8)
    corners = cv2.boxPoints(((150.0, 110.0), (80.0, 30.0), angle))   # along x turned by angle (y down)
    cv2.fillConvexPoly(gray, np.round(corners).astype(np.int32), 255)
    view, back = turned_view(gray, angle)
    forward = cv2.invertAffineTransform(back)
    cx, cy = forward[:, :2] @ (150.0, 110.0) + forward[:, 2]
    _, labels = cv2.connectedComponents((view > 128).astype(np.uint8))   # the border reflects copies of it
    ys, xs = np.nonzero(labels == labels[int(round(cy)), int(round(cx))])
    aligned = np.array([[xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1]], float)
    assert aligned[0, 2] == pytest.approx(80, abs=3) and aligned[0, 3] == pytest.approx(30, abs=3)  # along x
    boxes, scores = map_back(aligned, np.ones(1), back, (320, 240))
    truth = np.r_[corners.min(axis=0), corners.max(axis=0) - corners.min(axis=0)]
    assert len(boxes) == 1 and box_iou(boxes[0], truth) > 0.9
    outside = np.array([[0.0, 0.0, 20.0, 20.0]])                        # the view's corner: reflected border
    assert len(map_back(outside, np.ones(1), back, (320, 240))[0]) == 0
    assert turned_view(gray, 0.0)[1] is None and turned_view(gray, 0.0)[0] is gray


def test_border_lets_windows_reach_past_the_frame_onto_a_cut_object():
    """With ``border`` the upright view is the frame with reflected pixels around it: a window on a bar the
    frame's edge cuts (centre inside the frame) maps back as the bar's visible part, a window centred in the
    reflected border is dropped; without it the frame itself is scanned (the default set-up unchanged)."""
    from multi_target_tracker.detector import map_back, turned_view

    gray = np.zeros((240, 320), np.uint8)
    gray[100:130, 290:320] = 255                                      # 30 of a 60-px bar, cut by the right edge
    view, back = turned_view(gray, 0.0, 32)
    assert view.shape == (240 + 64, 320 + 64)
    assert (view[132:162, 322:382] == 255).all()                      # the reflection makes the bar whole again
    window = np.array([[290.0 + 32 - 5, 100.0 + 32, 60.0, 30.0]])     # on the whole (reflected) bar
    boxes, _ = map_back(window, np.ones(1), back, (320, 240))
    assert len(boxes) == 1 and box_iou(boxes[0], np.array([290.0, 100.0, 30.0, 30.0])) > 0.8
    outside = np.array([[320.0 + 32 + 1, 100.0 + 32, 24.0, 30.0]])    # centred in the border
    assert len(map_back(outside, np.ones(1), back, (320, 240))[0]) == 0
    assert turned_view(gray, 0.0, 0)[1] is None and turned_view(gray, 0.0, 0)[0] is gray


def test_turned_crop_keeps_the_central_square_of_the_turned_view():
    """With ``crop`` a turned view is the central square of the whole turned canvas (crop times the square root of
    the frame's area a side), mapped back to the same frame points; the upright view is never cropped."""
    from multi_target_tracker.detector import turned_view

    rng = np.random.default_rng(0)
    gray = cv2.GaussianBlur(rng.integers(0, 256, (240, 320), dtype=np.uint8), (0, 0), 4)   # smooth: half-pixel shifts
    whole, back = turned_view(gray, 45.0)
    crop, crop_back = turned_view(gray, 45.0, crop=1.1)
    side = int(round(1.1 * np.sqrt(240 * 320)))
    assert crop.shape == (side, side) and whole.shape[0] > side and whole.shape[1] > side
    offset = (np.array(whole.shape[::-1]) - side) / 2                  # where the square sits in the whole canvas
    centre = np.array([side / 2, side / 2])
    assert np.allclose(crop_back @ [*centre, 1.0], back @ [*(centre + offset), 1.0])   # the same frame point
    assert np.allclose(crop_back[:, :2], back[:, :2])
    x0, y0 = np.round(offset).astype(int)
    inner = (slice(8, side - 8), slice(8, side - 8))
    assert np.abs(crop[inner].astype(int) - whole[y0:y0 + side, x0:x0 + side][inner].astype(int)).mean() < 3
    assert turned_view(gray, 0.0, crop=1.1)[0] is gray and turned_view(gray, 0.0, 32, crop=1.1)[0].shape == (304, 384)
