"""`evaluate` on hand-made bags and files: the same numbers as motmetrics and as hand computation."""
from __future__ import annotations

import json

import motmetrics
import numpy as np
import pytest

from aircraft_docking_tracker.io.bag import BagWriter
from aircraft_docking_tracker.evaluation import evaluate as ev
from aircraft_docking_tracker.geometry import box_iou, box_to_quad
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, TRACK_DTYPE
from aircraft_docking_tracker.scenarios import messages as m
from aircraft_docking_tracker.scenarios.render import frame_stamp_ns

A, B = [10, 10, 20, 20], [100, 10, 20, 20]
FAR = [300, 300, 20, 20]
# frame -> ground truth {id: box}; hypotheses {id: box}
GT = [{1: A, 2: B}] * 4
HYP = [{1: A, 2: B}, {1: A, 2: B}, {2: A, 1: B}, {2: A, 7: FAR}]   # swap at frame 3, miss + FP at 4


def _table(rows: dict, dtype=TRACK_DTYPE, state=1):
    t = np.zeros(len(rows), dtype)
    for k, (i, (x, y, w, h)) in enumerate(rows.items()):
        t[k]["x"], t[k]["y"], t[k]["w"], t[k]["h"] = x, y, w, h
        t[k]["score"] = 1.0
        if "id" in dtype.names:
            t[k]["id"], t[k]["state"] = i, state
    return t


def _write(path, topic_frames: dict):
    with BagWriter(path) as bag:
        for topic, frames in topic_frames.items():
            for k, table in enumerate(frames):
                if table is None:
                    continue
                stamp = frame_stamp_ns(k, 10.0)
                hdr = m.header(stamp)
                msg = m.quad_to_polygon(table, hdr) if topic.endswith("polygon") else m.cloud_msg(table, hdr)
                bag.write(topic, msg, stamp + (5_000_000 if topic in (m.TRACKS, m.DOCKING_POLYGON) else 0))
    return path


def _motmetrics_reference():
    acc = motmetrics.MOTAccumulator(auto_id=False)
    for frame, (g, h) in enumerate(zip(GT, HYP), start=1):
        gb, hb = np.array(list(g.values()), float), np.array(list(h.values()), float)
        dist = 1.0 - box_iou(gb[:, None], hb[None])
        dist[dist > 0.5] = np.nan
        acc.update(list(g), list(h), dist, frameid=frame)
    return motmetrics.metrics.create().compute(acc, metrics=["mota", "idf1", "num_switches"], name="x").loc["x"]


def test_mot_same_numbers_as_motmetrics_and_by_hand(tmp_path):
    bag = _write(tmp_path / "mot.mcap", {m.GROUND_TRUTH: [_table(g) for g in GT], m.TRACKS: [_table(h) for h in HYP]})
    r = ev.evaluate_bags(bag)["mot"]
    ref = _motmetrics_reference()
    assert r["mota"] == pytest.approx(ref["mota"]) and r["idf1"] == pytest.approx(ref["idf1"])
    # by hand: 8 GT boxes, 1 miss, 1 false positive, 2 switches -> MOTA 1 - 4/8;
    # IDF1: best id pairing (1-1, 2-2) shares 4 boxes of 8 GT + 8 hypotheses -> 2*4/16
    assert r["mota"] == pytest.approx(0.5) and r["idf1"] == pytest.approx(0.5)
    assert (r["num_switches"], r["num_misses"], r["num_false_positives"]) == (2, 1, 1)
    cont = {c["gt_id"]: c for c in r["continuity"]}
    assert cont[1]["longest_continuous"] == 2 and cont[2]["frames_tracked"] == 3
    assert r["timeline"][2] == [[1, 2], [2, 2], [3, 1], [4, None]]


def test_mot_hidden_ground_truth_is_ignored(tmp_path):
    gt = [_table({1: A}), _table({1: A})]
    gt[1]["state"], gt[1]["score"] = 2, 0.0                          # hidden in frame 2
    hyp = [_table({5: A}), _table({5: A})]                           # the tracker coasts on it: no FP
    r = ev.evaluate_bags(_write(tmp_path / "h.mcap", {m.GROUND_TRUTH: gt, m.TRACKS: hyp}))["mot"]
    assert r["num_false_positives"] == 0 and r["num_misses"] == 0 and r["mota"] == pytest.approx(1.0)
    assert r["hota"] == pytest.approx(1.0) and r["assa"] == pytest.approx(1.0)   # HOTA beside CLEAR MOT


def test_sot_from_bags_shift_and_missing_output(tmp_path):
    gt = [box_to_quad([0, 0, 10, 10])[0]] * 4
    out = [box_to_quad([5, 0, 10, 10])[0], gt[0], None, box_to_quad([50, 50, 10, 10])[0]]
    bag = _write(tmp_path / "s.mcap", {m.GT_POLYGON: gt, m.DOCKING_POLYGON: out})
    held = ev.evaluate_bags(bag)["sot"]
    np.testing.assert_allclose(held["iou"], [1 / 3, 1, 1, 0])        # frame 3 holds frame 2's output
    assert held["missing_outputs"] == 1 and held["lost_frames"] == 1
    lost = ev.evaluate_bags(bag, config=ev.EvaluateConfig(missing="lost"))["sot"]
    np.testing.assert_allclose(lost["iou"], [1 / 3, 1, 0, 0])
    assert lost["lost_frames"] == 2 and lost["longest_loss"] == 2
    assert lost["precision"] == pytest.approx(0.5)


def test_detection_from_bag_and_speed(tmp_path):
    gt = [_table({0: [0, 0, 10, 10], 1: [20, 0, 10, 10]}, DETECTION_DTYPE)]
    dets = np.zeros(3, DETECTION_DTYPE)
    for k, (box, s) in enumerate([([0, 0, 10, 10], 0.9), ([1, 0, 10, 10], 0.8), ([25, 0, 10, 10], 0.7)]):
        dets[k]["x"], dets[k]["y"], dets[k]["w"], dets[k]["h"] = box
        dets[k]["score"] = s
    r = ev.evaluate_bags(_write(tmp_path / "d.mcap", {m.GROUND_TRUTH: gt, m.DETECTIONS: [dets]}))
    assert r["detection"]["detection_rate"] == pytest.approx(0.5)
    assert r["detection"]["false_alarm_rate"] == pytest.approx(2 / 3)


def test_latency_from_log_times(tmp_path):
    gt = [_table({1: A})] * 3
    bag = _write(tmp_path / "l.mcap", {m.GROUND_TRUTH: gt, m.DETECTIONS: [_table({0: A}, DETECTION_DTYPE)] * 3,
                                      m.TRACKS: [_table({1: A})] * 3})
    speed = ev.evaluate_bags(bag)["speed"]
    assert speed["tracks"]["p50_ms"] == pytest.approx(5.0) and speed["tracks"]["latency_from"] == "detections"
    assert speed["tracks"]["rate_hz"] == pytest.approx(10.0)


def test_nothing_to_score_is_a_clear_error(tmp_path):
    bag = _write(tmp_path / "n.mcap", {m.GROUND_TRUTH: [_table({1: A})]})
    with pytest.raises(ev.EvaluationError, match="nothing to score"):
        ev.evaluate_bags(bag)


def test_results_files_otb_and_mot(tmp_path):
    gt = tmp_path / "groundtruth_rect.txt"
    gt.write_text("11,11,10,10\n11,11,10,10\n")                      # OTB: 1-based
    res = tmp_path / "res.txt"
    res.write_text("10,10,10,10\n15,10,10,10\n")                     # ours: 0-based
    r = ev.evaluate_files(res, gt)["sot"]
    np.testing.assert_allclose(r["iou"], [1.0, 1 / 3])
    mot_gt = tmp_path / "gt.txt"
    mot_res = tmp_path / "tracks.txt"
    mot_gt.write_text("".join(f"{f},{i},{b[0]},{b[1]},{b[2]},{b[3]},1,-1,-1,-1\n"
                              for f, g in enumerate(GT, 1) for i, b in g.items()))
    mot_res.write_text("".join(f"{f},{i},{b[0]},{b[1]},{b[2]},{b[3]},1,-1,-1,-1\n"
                               for f, h in enumerate(HYP, 1) for i, b in h.items()))
    r = ev.evaluate_files(mot_res, mot_gt)["mot"]
    assert r["mota"] == pytest.approx(0.5) and r["idf1"] == pytest.approx(0.5)


def test_cli_writes_table_json_and_plots(tmp_path, capsys):
    bag = _write(tmp_path / "mot.mcap", {m.GROUND_TRUTH: [_table(g) for g in GT], m.TRACKS: [_table(h) for h in HYP]})
    sot = _write(tmp_path / "sot.mcap", {m.GT_POLYGON: [box_to_quad(A)[0]] * 3,
                                        m.DOCKING_POLYGON: [box_to_quad(B)[0], box_to_quad(A)[0], box_to_quad(A)[0]]})
    rep = tmp_path / "report"
    assert ev.main([str(bag), str(sot), "--report", str(rep), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "MOTA" in text and "HOTA" in text and "AUC" in text
    data = json.loads((rep / "report.json").read_text())
    assert data["mot"]["mot"]["mota"] == pytest.approx(0.5)
    assert data["sot"]["sot"]["lost_frames"] == 1
    for name in ("success_precision.png", "continuity.png", "timeline_mot.png"):
        assert (rep / name).stat().st_size > 1000
    assert ev.main([str(tmp_path / "missing.mcap")]) == 2


def test_results_file_of_quadrilaterals_shorter_than_ground_truth(tmp_path):
    gt = tmp_path / "groundtruth_rect.txt"
    gt.write_text("1,1,10,10\n" * 5)
    quads = tmp_path / "quads.txt"
    quads.write_text("0,0,10,0,10,10,0,10\n5,0,15,0,15,10,5,10\n")   # TL, TR, BR, BL
    r = ev.evaluate_files(quads, gt)["sot"]
    np.testing.assert_allclose(r["iou"], [1.0, 1 / 3])
    assert r["scored_frames"] == 2 and r["ground_truth_frames"] == 5
    bad = tmp_path / "bad.txt"
    bad.write_text("1,2,3\n")
    with pytest.raises(ValueError, match="columns"):
        ev.evaluate_files(bad, gt)


def test_truncated_bag_is_flagged_or_refused_clearly(tmp_path):
    frames = [_table(GT[0])] * 200
    bag = _write(tmp_path / "full.mcap", {m.GROUND_TRUTH: frames, m.TRACKS: frames})
    data = bag.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.9)])
    r = ev.evaluate_bags(cut)
    assert r["inputs"]["truncated"] == [str(cut)]
    assert r["mot"]["mota"] == pytest.approx(1.0)
    cut.write_bytes(data[:40])
    with pytest.raises(ValueError, match="cut.mcap"):
        ev.evaluate_bags(cut)


def test_topics_of_live_recordings_resolve_to_the_agreed_names():
    live = {"/tracks": 0, "/ground_truth": 0, "/image": 0}
    assert ev.resolve_topics(live, ("tracks", "ground_truth")) == {"/tracks": "tracks", "/ground_truth": "ground_truth"}
    two = {"/cam0/tracks": 0, "/cam1/tracks": 0}
    with pytest.raises(ev.EvaluationError, match="namespace"):
        ev.resolve_topics(two, ("tracks",))
    assert ev.resolve_topics(two, ("tracks",), "cam1") == {"/cam1/tracks": "tracks"}
    assert ev.resolve_topics({"docking/polygon": 0, "ground_truth/polygon": 0}, ("docking/polygon",)) == \
        {"docking/polygon": "docking/polygon"}


def test_guidance_scored_against_its_ground_truth(tmp_path):
    """docking/guidance against ground_truth/guidance: errors within the last 15 m, where STOP was first shown, the
    state accuracy; a frame without output holds the last row; the report's table and plot."""
    from aircraft_docking_tracker.docking.guidance import true_guidance

    distances = np.array([40.0, 20.0, 14.0, 8.0, 3.0, 1.2, 0.4, 0.0, 0.0, 0.0])
    truth = true_guidance(distances, np.full(10, 0.1), np.r_[-np.diff(distances) * 10, 0.0])
    shown = truth.copy()
    shown["distance_m"] += 0.2                                    # 0.2 m long throughout
    shown["lateral_m"] -= np.linspace(0.0, 0.45, 10)
    shown["state"][5] = 3                                         # STOP 1.2 m early (1.4 m shown)
    rows = [shown[k:k + 1] for k in range(10)]
    rows[8] = None                                                # no output: holds frame 7's row
    bag = _write(tmp_path / "g.mcap", {m.GT_GUIDANCE: [truth[k:k + 1] for k in range(10)],
                                       m.DOCKING_GUIDANCE: rows})
    g = ev.evaluate_bags(bag)["guidance"]
    assert g["frames"] == 10 and g["missing_frames"] == 1 and g["near_frames"] == 8
    assert g["distance_near_median"] == pytest.approx(0.2, abs=1e-5) and g["distance_near_p95"] == pytest.approx(0.2, abs=1e-5)
    held = np.linspace(0.0, 0.45, 10)
    held[8] = held[7]
    assert g["lateral_near_p95"] == pytest.approx(np.percentile(held[2:], 95), abs=1e-5)
    assert g["stop_frame"] == 5 and g["stop_at_m"] == pytest.approx(1.2) and g["stop_early"] and not g["stop_within"]
    assert g["state_accuracy"] == pytest.approx(0.9)             # frame 5 shows STOP where the truth shows slow down
    text = ev.report.format_report({"run": {"guidance": g}})
    assert "docking guidance" in text and "1.20" in text
    assert ev.write_plots({"run": {"guidance": g}}, tmp_path)[0].name == "guidance_errors.png"
