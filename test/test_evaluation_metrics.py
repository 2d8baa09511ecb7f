"""SOT, detection and speed metrics pinned to hand-computed cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from aircraft_docking_tracker import geometry
from aircraft_docking_tracker.evaluation import detection_metrics as dm
from aircraft_docking_tracker.evaluation import sot_metrics as sm
from aircraft_docking_tracker.evaluation import speed


def test_box_iou_shifted_boxes():
    a = [[0, 0, 10, 10]] * 4
    b = [[5, 0, 10, 10], [5, 5, 10, 10], [20, 20, 5, 5], [0, 0, 10, 10]]
    np.testing.assert_allclose(geometry.box_iou(np.array(a), np.array(b)), [1 / 3, 1 / 7, 0.0, 1.0])


def test_box_iou_pairwise_matrix_and_degenerate():
    a = np.array([[0, 0, 10, 10], [0, 0, 0, 10]], float)
    b = np.array([[5, 0, 10, 10], [np.nan, 0, 1, 1]], float)
    m = geometry.box_iou(a[:, None], b[None])
    np.testing.assert_allclose(m, [[1 / 3, 0.0], [0.0, 0.0]])


def test_polygon_iou_matches_box_iou_and_rotated_square():
    boxes_a = np.array([[0, 0, 10, 10], [3, 4, 8, 6]], float)
    boxes_b = np.array([[5, 0, 10, 10], [4, 5, 8, 6]], float)
    np.testing.assert_allclose(sm.polygon_iou(geometry.box_to_quad(boxes_a), geometry.box_to_quad(boxes_b)),
                               geometry.box_iou(boxes_a, boxes_b), atol=1e-6)
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    r = math.sqrt(2)
    diamond = np.array([[0, -r], [r, 0], [0, r], [-r, 0]], float)
    # square minus four corner triangles of legs 2 - sqrt 2: intersection 4 - 2 (2 - sqrt 2)^2
    inter = 4 - 2 * (2 - r) ** 2
    expected = inter / (8 - inter)
    assert sm.polygon_iou(square, diamond)[0] == pytest.approx(expected, abs=1e-5)
    assert sm.polygon_iou(square[::-1], diamond)[0] == pytest.approx(expected, abs=1e-5)
    assert sm.polygon_iou(square, np.full((4, 2), np.nan))[0] == 0.0


def test_center_errors_and_quads():
    gt = np.array([[0, 0, 10, 10], [0, 0, 10, 10]], float)
    pred = np.array([[3, 4, 10, 10], [np.nan] * 4])
    err = sm.center_errors(pred, gt)
    assert err[0] == pytest.approx(5.0) and np.isinf(err[1])
    np.testing.assert_allclose(sm.center_errors(geometry.box_to_quad(pred[:1]), geometry.box_to_quad(gt[:1])), [5.0])
    np.testing.assert_allclose(geometry.quad_to_box(geometry.box_to_quad(gt)), gt)


def test_success_curve_and_auc_hand_computed():
    ious = [0.0, 0.3, 0.5, 1.0]
    curve = sm.success_curve(ious)
    assert len(curve) == 21
    assert curve[0] == 0.75            # IoU > 0
    assert curve[10] == 0.25           # IoU > 0.5: 0.5 itself does not count (OTB uses >)
    assert curve[-1] == 0.0
    # 1.0 exceeds 20 thresholds, 0.5 exceeds 10, 0.3 exceeds 6: (20 + 10 + 6) / (4 * 21)
    assert sm.success_auc(ious) == pytest.approx(36 / 84)


def test_precision_at_20():
    errors = [0.0, 10.0, 20.0, 30.0, np.inf]
    assert sm.precision_at(errors, 20) == pytest.approx(3 / 5)
    assert sm.precision_curve(errors)[0] == pytest.approx(1 / 5)
    assert len(sm.precision_curve(errors)) == 51


def test_score_sequence_missed_frame_and_absent_gt():
    gt = np.array([[0, 0, 10, 10]] * 5, float)
    gt[4] = np.nan                                        # target absent: not scored
    pred = gt.copy()
    pred[1] = [5, 0, 10, 10]                              # shifted: IoU 1/3, error 5
    pred[2] = np.nan                                      # tracker reported nothing: lost
    pred[3] = [40, 40, 10, 10]                            # far away: lost
    s = sm.score_sequence(pred, gt)
    assert s["frames"] == 5 and s["scored_frames"] == 4
    np.testing.assert_allclose(s["iou"], [1.0, 1 / 3, 0.0, 0.0])
    assert s["lost_frames"] == 2 and s["longest_loss"] == 2
    assert s["precision"] == pytest.approx(0.5)           # errors 0, 5, inf, 56.6
    assert s["mean_iou"] == pytest.approx((1 + 1 / 3) / 4)
    assert s["center_error"][2] is None


def test_score_sequence_rejects_mismatched_lengths():
    with pytest.raises(sm.MetricInputError):
        sm.score_sequence(np.zeros((3, 4)), np.zeros((2, 4)))
    with pytest.raises(ValueError):
        geometry.box_iou(np.zeros((2, 3)), np.zeros((2, 3)))


def test_greedy_matching_by_score():
    gt = [[0, 0, 10, 10], [20, 0, 10, 10]]
    dets = [[0, 0, 10, 10], [1, 0, 10, 10], [25, 0, 10, 10]]
    det_gt, ignored = dm.match_frame(dets, [0.9, 0.8, 0.7], gt)
    assert det_gt.tolist() == [0, -1, -1]                 # duplicate, and IoU 1/3 < 0.5
    assert not ignored.any()
    # the higher score takes the box even if a lower-score detection overlaps it better
    det_gt, _ = dm.match_frame([[2, 0, 10, 10], [0, 0, 10, 10]], [0.9, 0.5], gt[:1])
    assert det_gt.tolist() == [0, -1]


def test_detection_and_false_alarm_rates():
    acc = dm.DetectionAccumulator()
    acc.add_frame([[0, 0, 10, 10], [1, 0, 10, 10], [25, 0, 10, 10]], [0.9, 0.8, 0.7],
                  [[0, 0, 10, 10], [20, 0, 10, 10]])
    acc.add_frame(np.zeros((0, 4)), [], [[50, 50, 10, 10]])       # a missed frame
    s = acc.summary()
    assert (s["true_positives"], s["false_positives"], s["misses"], s["ground_truth"]) == (1, 2, 2, 3)
    assert s["detection_rate"] == pytest.approx(1 / 3)
    assert s["false_alarm_rate"] == pytest.approx(2 / 3)
    assert s["average_precision"] == pytest.approx(1 / 3)        # precision 1 up to recall 1/3


def test_average_precision_all_point_interpolation():
    precision, recall, _ = dm.pr_curve([0.9, 0.8, 0.7], [True, False, True], n_gt=4)
    np.testing.assert_allclose(precision, [1, 0.5, 2 / 3])
    np.testing.assert_allclose(recall, [0.25, 0.25, 0.5])
    # 0.25 * 1 + 0.25 * 2/3 (the dip to 0.5 is interpolated away)
    assert dm.average_precision(precision, recall) == pytest.approx(0.25 + 0.25 * 2 / 3)


def test_ignored_ground_truth_is_neither_miss_nor_false_alarm():
    acc = dm.DetectionAccumulator()
    acc.add_frame([[0, 0, 10, 10], [30, 30, 10, 10]], [0.9, 0.8],
                  [[0, 0, 10, 10], [30, 30, 10, 10], [60, 60, 10, 10]], gt_ignore=[False, True, True])
    s = acc.summary()
    assert s["ground_truth"] == 1 and s["detections"] == 1
    assert s["detection_rate"] == 1.0 and s["false_alarm_rate"] == 0.0


def test_speed_helpers():
    assert speed.fps([0.1, 0.1, 0.2]) == pytest.approx(7.5)
    p = speed.latency_percentiles(np.arange(1, 101) / 1000.0)
    assert p["p50_ms"] == pytest.approx(50.5) and p["max_ms"] == pytest.approx(100.0)
    assert speed.stream_fps([0, 100_000_000, 200_000_000]) == pytest.approx(10.0)
    ticks = iter([0.0, 0.5, 1.0, 3.0])
    results, lat = speed.time_calls(lambda x: 2 * x, [1, 2], clock=lambda: next(ticks))
    assert results == [2, 4] and lat.tolist() == [0.5, 2.0]


def test_geometry_boxes_and_quadrilaterals_broadcast_and_refuse_wrong_shapes():
    quads = geometry.box_to_quad(np.array([[0, 0, 4, 2], [1, 1, 2, 2]], float))
    stacked = np.stack([quads, quads + 1])                                 # (2, 2, 4, 2)
    assert geometry.quad_to_box(stacked).shape == (2, 2, 4)
    np.testing.assert_allclose(geometry.quad_to_box(stacked)[1, 0], [1, 1, 4, 2])
    with pytest.raises(ValueError):
        geometry.box_to_quad(np.zeros((2, 8)))
    with pytest.raises(ValueError):
        geometry.quad_to_box(np.zeros((3, 2)))


def test_geometry_scale_boxes_keeps_the_centre():
    boxes = np.array([[10, 20, 40, 20], [0, 0, 1, 1]], float)
    scaled = geometry.scale_boxes(boxes, 0.5)
    np.testing.assert_allclose(scaled, [[20, 25, 20, 10], [0.25, 0.25, 0.5, 0.5]])
    np.testing.assert_allclose(scaled[:, :2] + scaled[:, 2:] / 2, boxes[:, :2] + boxes[:, 2:] / 2)
    np.testing.assert_allclose(geometry.scale_boxes(boxes, 1.0), boxes)
