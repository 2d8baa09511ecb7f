"""The compiled grouping (group_windows, suppress_contained) gives exactly what the plain Python
greedy loops it replaced gave, on the raw windows of real drone-view tiles and on random boxes; grouped by
the windows' turned rectangles (group_shape turned) it parts neighbours their upright boxes would join."""
import cv2
import numpy as np
import pytest
from scipy.special import expit

from aircraft_docking_tracker.geometry import box_iou, box_to_quad, quad_to_box
from multi_target_tracker.detector import Detector, DetectorConfig, group_windows, suppress_contained
from multi_target_tracker.train_cascade import read_yolo_folder


def _containment_reference(a, b):
    ix = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    iy = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.clip(ix, 0.0, None) * np.clip(iy, 0.0, None)
    smaller = np.minimum((a[:, 2] * a[:, 3])[:, None], (b[:, 2] * b[:, 3])[None, :])
    return inter / np.maximum(smaller, 1e-12)


def suppress_reference(boxes, scores, containment, limit=None, iou=1.0, exempt=None):
    """The former O(n^2) Python loop, with greedy IoU suppression beside containment (not applied to ``exempt``)."""
    order = np.argsort(-scores, kind="stable")
    limit = len(order) if limit is None else limit
    if (containment >= 1.0 and iou >= 1.0) or len(order) < 2:
        return order[:limit]
    kept = []
    for k in order:
        if len(kept) >= limit:
            break
        inside = containment < 1.0 and not (exempt is not None and exempt[k]) and \
            (_containment_reference(boxes[k:k + 1], boxes[kept])[0] >= containment).any()
        overlapping = iou < 1.0 and (box_iou(boxes[k:k + 1], boxes[kept]) >= iou).any()
        if not kept or not (inside or overlapping):
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
        boxes, margins, _ = det.raw(item.load())
        total += len(boxes)
        _same(boxes, margins, settings)
    assert total > 500   # the comparison saw real crowds of overlapping windows


def test_detector_applies_its_suppression_iou(shared_data):
    """The detector's own suppression reads ``suppression_iou``: IoU 0 keeps only the best detection of a tile that
    has several, and a loose IoU keeps every one containment 1 keeps (the drone-view groups hardly overlap)."""
    tiles = read_yolo_folder(shared_data / "detect" / "drone-view-vehicles", include=["1_"])
    image = next(item.load() for item in tiles[::10] if len(Detector(DetectorConfig()).detect(item.load())) >= 3)
    kept = {iou: len(Detector(DetectorConfig(containment=1.0, suppression_iou=iou)).detect(image)) for iou in (0.0, 1.0)}
    assert kept[0.0] == 1 and kept[1.0] >= 3, kept


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
            for iou in (0.0, 0.3, 0.6):
                assert suppress_contained(boxes, scores, settings["containment"], limit, iou).tolist() == \
                    suppress_reference(boxes, scores, settings["containment"], limit, iou).tolist()
            for share in (0.0, 0.3, 1.0):
                exempt = rng.random(n) < share
                for iou in (0.4, 1.0):
                    assert suppress_contained(boxes, scores, settings["containment"], limit, iou, exempt).tolist() == \
                        suppress_reference(boxes, scores, settings["containment"], limit, iou, exempt).tolist()


def test_overlap_suppression_keeps_overlapping_neighbours_that_containment_drops():
    """Two vehicles parked nose over tail (IoU 0.27, half the smaller inside the larger) and a second box on the
    first (IoU 0.81): containment 0.5 drops the neighbour with the duplicate, IoU 0.5 drops the duplicate only."""
    boxes = np.array([[0.0, 0.0, 40.0, 80.0], [10.0, 40.0, 40.0, 60.0], [2.0, 4.0, 40.0, 76.0]])
    scores = np.array([0.9, 0.8, 0.7])
    assert box_iou(boxes[0], boxes[2]) > 0.8 and box_iou(boxes[0], boxes[1]) < 0.3
    assert suppress_contained(boxes, scores, 0.5).tolist() == [0]
    assert suppress_contained(boxes, scores, 1.0, iou=0.5).tolist() == [0, 1]
    assert suppress_contained(boxes, scores, 1.0).tolist() == [0, 1, 2]      # both 1: nothing dropped


def test_exempt_boxes_are_dropped_by_iou_only():
    """The same three boxes: exempting the neighbour from containment keeps it beside the first; the duplicate is
    dropped by containment unless exempt too, and then by an IoU of 0.5 still."""
    boxes = np.array([[0.0, 0.0, 40.0, 80.0], [10.0, 40.0, 40.0, 60.0], [2.0, 4.0, 40.0, 76.0]])
    scores = np.array([0.9, 0.8, 0.7])
    assert suppress_contained(boxes, scores, 0.5, exempt=np.array([False, True, False])).tolist() == [0, 1]
    assert suppress_contained(boxes, scores, 0.5, exempt=np.ones(3, bool)).tolist() == [0, 1, 2]
    assert suppress_contained(boxes, scores, 0.5, iou=0.5, exempt=np.ones(3, bool)).tolist() == [0, 1]
    assert suppress_contained(boxes, scores, 0.5, exempt=np.zeros(3, bool)).tolist() == [0]
    with pytest.raises(ValueError, match="exempt"):
        suppress_contained(boxes, scores, 0.5, exempt=np.ones(2, bool))


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


def test_windows_of_several_views_map_back_at_once_as_each_view_maps_them():
    """One map per window (the detector maps all its blob views' windows in one call) gives each view's windows
    exactly what mapping them view by view gives, with the same windows dropped."""
    from multi_target_tracker.detector import map_back, turned_view

    rng = np.random.default_rng(4)
    gray = rng.integers(0, 255, (240, 320), np.uint8)
    backs = [turned_view(gray, angle, 16)[1] for angle in (0.0, 30.0, 45.0, 100.0)]
    windows = [np.column_stack([rng.uniform(-20, 380, (n, 2)), rng.uniform(10, 60, (n, 2))]) for n in (7, 0, 12, 9)]
    scores = [rng.random(len(w)) for w in windows]
    one_by_one = [map_back(w, sc, back, (320, 240), with_quads=True) for w, sc, back in zip(windows, scores, backs)]
    per_window = np.repeat(np.stack(backs), [len(w) for w in windows], axis=0)
    at_once = map_back(np.concatenate(windows), np.concatenate(scores), per_window, (320, 240), with_quads=True)
    for k in range(3):
        assert np.array_equal(at_once[k], np.concatenate([m[k] for m in one_by_one]))
    assert 0 < len(at_once[0]) < sum(map(len, windows))               # some windows centred outside are dropped


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


def _turned_rectangle(centre, size, angle):
    """Corners (4, 2) of a ``size`` (length, width) rectangle about ``centre`` turned by ``angle`` degrees."""
    return cv2.boxPoints((tuple(map(float, centre)), tuple(map(float, size)), float(angle))).astype(np.float64)


def test_quad_intersection_is_opencvs_on_turned_rectangles():
    """The grouping's compiled convex-quadrilateral intersection gives OpenCV's area, in either vertex order, and the
    plain cases exactly: disjoint 0, one inside the other its own area, a quarter overlap a quarter."""
    from multi_target_tracker.detector import quad_intersection

    rng = np.random.default_rng(0)
    for _ in range(500):
        a = _turned_rectangle(rng.uniform(0, 60, 2), rng.uniform(4, 40, 2), rng.uniform(0, 180))
        b = _turned_rectangle(rng.uniform(0, 60, 2), rng.uniform(4, 40, 2), rng.uniform(0, 180))
        b = b[::-1].copy() if rng.random() < 0.5 else b
        expected, _ = cv2.intersectConvexConvex(a.astype(np.float32), b.astype(np.float32))
        assert quad_intersection(a, b) == pytest.approx(expected, rel=1e-4, abs=1e-3)
    square = box_to_quad(np.array([0.0, 0.0, 10.0, 10.0]))[0]
    assert quad_intersection(square, box_to_quad(np.array([20.0, 0.0, 10.0, 10.0]))[0]) == 0.0
    assert quad_intersection(square, box_to_quad(np.array([2.0, 3.0, 4.0, 5.0]))[0]) == pytest.approx(20.0)
    assert quad_intersection(square, box_to_quad(np.array([5.0, 5.0, 10.0, 10.0]))[0]) == pytest.approx(25.0)


def test_turned_grouping_keeps_two_diagonal_neighbours_apart():
    """Two vehicles side by side along 45 degrees, three windows each (48x24, 4 px apart along the vehicle, 20 px
    between the vehicles' axes): their upright boxes overlap by IoU 0.35 across the vehicles (one group), their own
    rectangles by 0.09 (two groups, each the mean of its own vehicle's windows)."""
    axis, across = np.array([1.0, 1.0]) / np.sqrt(2), np.array([-1.0, 1.0]) / np.sqrt(2)
    centres = [np.array([200.0, 200.0]) + k * 20.0 * across + shift * axis for k in (0, 1) for shift in (-4, 0, 4)]
    quads = np.array([_turned_rectangle(c, (48, 24), 45.0) for c in centres])
    boxes = quad_to_box(quads)
    margins = np.array([3.0, 2.0, 1.0, 2.5, 1.5, 0.5])
    assert box_iou(boxes[0], boxes[3:]).min() > 0.33                              # upright: the neighbours join
    upright, _ = group_windows(boxes, margins, 0.3, min_neighbors=1, containment=1.0)
    turned, _ = group_windows(boxes, margins, 0.3, min_neighbors=1, containment=1.0, quads=quads)
    assert len(upright) == 1 and len(turned) == 2
    np.testing.assert_allclose(np.sort(turned[:, 0]), np.sort([boxes[:3, 0].mean(), boxes[3:, 0].mean()]))


@pytest.mark.parametrize("seed", range(3))
def test_turned_grouping_of_upright_windows_is_the_upright_grouping(seed):
    """Windows whose rectangles are their own upright boxes group the same either way (random crowds)."""
    rng = np.random.default_rng(seed)
    boxes = np.column_stack([rng.uniform(0, 200, (300, 2)), rng.uniform(10, 60, (300, 2))])
    margins = rng.normal(0, 1, 300)
    upright = group_windows(boxes, margins, 0.3, min_neighbors=2, containment=0.5)
    turned = group_windows(boxes, margins, 0.3, min_neighbors=2, containment=0.5, quads=box_to_quad(boxes))
    for a, b in zip(upright, turned):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_raw_windows_carry_their_turned_rectangles():
    """Each raw window of the UAV set-up (upright, 45-degree and blob views) comes with its own rectangle in the
    frame, whose upright box clipped to the frame is the window's box; the 45-degree views' are turned."""
    from aircraft_docking_tracker.config import package_config_dir
    from aircraft_docking_tracker.offline import build_processor
    from aircraft_docking_tracker.scenarios.uav import (UAV_SETUP_GROUND_RESOLUTION, UAV_TUNING_SEEDS, UavScene,
                                                        UavSceneConfig)

    frame = next(iter(UavScene(UavSceneConfig(frames=80, fps=10.0, ground_resolution=UAV_SETUP_GROUND_RESOLUTION),
                               seed=UAV_TUNING_SEEDS[0]).frames()))
    detector = build_processor("detector", package_config_dir() / "uav_camera.yaml", {}).detector
    windows = detector.raw(frame.image)
    assert len(windows.boxes) > 30 and windows.quads.shape == (len(windows.boxes), 4, 2)
    lo = np.maximum(windows.quads.min(axis=1), 0)
    hi = np.minimum(windows.quads.max(axis=1), frame.image.shape[1::-1])
    np.testing.assert_allclose(np.column_stack([lo, hi - lo]), windows.boxes, atol=1e-9)
    edge = windows.quads[:, 1] - windows.quads[:, 0]
    angle = np.degrees(np.arctan2(edge[:, 1], edge[:, 0])) % 90
    assert ((angle > 40) & (angle < 50)).sum() > 0.2 * len(angle)               # the 45-degree views' windows
    assert detector.config.group_shape == "turned"
