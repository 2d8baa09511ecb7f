"""MOT metrics on a hand-made case whose numbers are worked out by hand, and MOTChallenge file I/O."""
from __future__ import annotations

import numpy as np
import pytest

from aircraft_docking_tracker.evaluation.mot_metrics import MotEvaluator, evaluate_rows, iou_distances
from aircraft_docking_tracker.io import motchallenge as mc


def test_iou_distances_hand_computed():
    gt = [[0, 0, 10, 10]]
    hyp = [[5, 0, 10, 10], [0, 0, 10, 10], [100, 100, 5, 5]]
    d = iou_distances(gt, hyp, iou_threshold=0.3)
    # half overlap: intersection 50, union 150 -> IoU 1/3 -> distance 2/3; identical -> 0; disjoint -> NaN
    assert d[0, 0] == pytest.approx(2.0 / 3.0)
    assert d[0, 1] == 0.0
    assert np.isnan(d[0, 2])
    assert np.isnan(iou_distances(gt, hyp, iou_threshold=0.5)[0, 0])


def _hand_made_case() -> MotEvaluator:
    """Two targets over 4 frames: a shifted box, a swapped id, a missed frame, one false positive.

    frame 1: A->track 1 exact, B->track 2 exact
    frame 2: A->track 1 shifted by 2 px (IoU 8*10/(12*10)=2/3), B->track 2 exact
    frame 3: A->track 2 (switch), B->track 1 (switch)   [ids swapped]
    frame 4: A missed, B->track 1 exact, plus a false positive track 9 far away
    """
    a, b = [0, 0, 10, 10], [50, 0, 10, 10]
    ev = MotEvaluator(0.5)
    ev.update(1, [1, 2], [a, b], [1, 2], [a, b])
    ev.update(2, [1, 2], [a, b], [1, 2], [[2, 0, 10, 10], b])
    ev.update(3, [1, 2], [a, b], [2, 1], [a, b])
    ev.update(4, [1, 2], [a, b], [1, 9], [b, [200, 200, 5, 5]])
    return ev


def test_hand_made_case_matches_hand_count():
    s = _hand_made_case().result()
    assert s.num_objects == 8
    assert s.num_matches + s.num_switches == 7  # motmetrics counts a switch apart from a match
    assert s.num_misses == 1
    assert s.num_false_positives == 1
    assert s.num_switches == 2
    # MOTA = 1 - (FN + FP + IDSW) / GT = 1 - (1 + 1 + 2) / 8
    assert s.mota == pytest.approx(0.5)
    # MOTP (mean IoU of matches): six exact matches and one of IoU 2/3
    assert s.motp == pytest.approx((6 + 2.0 / 3.0) / 7)
    assert s.num_unique_objects == 2
    cont = {c.gt_id: c for c in s.continuity}
    # A: tracked by 1,1,2 then missed -> longest run 2; B: 2,2,1,1 -> longest 2
    assert (cont[1].frames_present, cont[1].frames_tracked, cont[1].longest_continuous) == (4, 3, 2)
    assert (cont[2].frames_present, cont[2].frames_tracked, cont[2].longest_continuous) == (4, 4, 2)
    assert (cont[1].first_frame, cont[1].last_frame) == (1, 4)


def test_idf1_hand_computed():
    # IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN). Best identity mapping: 1->A (frames 1,2), 2->B (1,2),
    # or 1->B (3,4)...: A-1 gets 2, B-2 gets 2, then B-1 (2) conflicts with A-1; optimum IDTP = 4.
    s = _hand_made_case().result()
    idtp = 4
    n_gt, n_hyp = 8, 8
    assert s.idf1 == pytest.approx(2 * idtp / (n_gt + n_hyp))


def test_results_round_trip(tmp_path):
    rows = np.concatenate([mc.make_rows(1, [3, 4], [[1, 2, 3, 4], [5, 6, 7, 8]], [0.9, 0.8]),
                           mc.make_rows(3, [3], [[1.5, 2, 3, 4]])])
    path = tmp_path / "res.txt"
    mc.write_results(path, rows)
    back = mc.read_mot(path)
    assert back["frame"].tolist() == [1, 1, 3]
    assert back["id"].tolist() == [3, 4, 3]
    np.testing.assert_allclose(mc.boxes(back), mc.boxes(rows), atol=0.01)
    listed = [(f, len(r)) for f, r in mc.frames(back)]
    assert listed == [(1, 2), (2, 0), (3, 1)]
    assert evaluate_rows(back, rows).mota == pytest.approx(1.0)


def test_bad_file_raises(tmp_path):
    path = tmp_path / "det.txt"
    path.write_text("1,-1,2,3\n")
    with pytest.raises(mc.MotFormatError):
        mc.read_mot(path)
    path.write_text("1,-1,a,3,4,5,0.5\n")
    with pytest.raises(mc.MotFormatError):
        mc.read_mot(path)


def test_ground_truth_flag_zero_ignored(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_text("1,1,0,0,10,10,1,1,1\n1,2,0,0,10,10,0,1,1\n2,1,0,0,10,10,1,1,1\n")
    gt = mc.read_ground_truth(path)
    assert gt["id"].tolist() == [1, 1]


def test_hota_of_hand_made_case_pinned_to_trackeval():
    # Values printed by TrackEval 1.3.0 (trackeval.metrics.HOTA().eval_sequence, means over the 19 α)
    # for the same four frames, IoU similarities; the port must reproduce them.
    s = _hand_made_case().result()
    assert s.hota == pytest.approx(0.4789746250470161, abs=1e-12)
    assert s.deta == pytest.approx(0.7216374269005847, abs=1e-12)
    assert s.assa == pytest.approx(0.3182957393483709, abs=1e-12)
    assert s.loca == pytest.approx(0.9674185463659147, abs=1e-12)


def test_hota_properties():
    from aircraft_docking_tracker.evaluation.mot_metrics import HotaAccumulator

    rng = np.random.default_rng(0)
    boxes = rng.uniform(0, 500, (5, 4)) + [0, 0, 20, 20]
    perfect, renamed, empty = HotaAccumulator(), HotaAccumulator(), HotaAccumulator()
    for _ in range(10):
        sim = mc.iou_matrix(boxes, boxes)
        perfect.update(np.arange(5), np.arange(5), sim)
        renamed.update(np.arange(5), np.arange(5) + 100, sim)      # ids are only labels
        empty.update(np.arange(5), [], np.zeros((5, 0)))
    assert perfect.result() == pytest.approx(dict(hota=1.0, deta=1.0, assa=1.0, loca=1.0))
    assert renamed.result() == perfect.result()
    assert empty.result()["hota"] == 0.0 and empty.result()["deta"] == 0.0
    # one id split in two halves: detection perfect, association halved for that target
    split = HotaAccumulator()
    for t in range(10):
        split.update([1], [1 if t < 5 else 2], [[1.0]])
    r = split.result()
    assert r["deta"] == pytest.approx(1.0)
    assert r["assa"] == pytest.approx(0.5)
    assert r["hota"] == pytest.approx(np.sqrt(0.5))
