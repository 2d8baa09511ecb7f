"""mot_track on the real TUD-Campus detections (skips where ../shared/data is absent)."""
from __future__ import annotations

from conftest import require_data
from multi_target_tracker import motchallenge as mc
from multi_target_tracker.mot_track import main


def test_mot_track_on_tud_campus(tmp_path, capsys):
    seq = require_data("mot/TUD-Campus")
    out = tmp_path / "res.txt"
    code = main([str(seq / "det.txt"), "-o", str(out), "--fps", "25", "--gt", str(seq / "gt.txt"), "--json",
                 "--no-coasting", "--backfill"])
    assert code == 0
    import json
    scores = json.loads(capsys.readouterr().out)
    rows = mc.read_mot(out)
    assert rows["frame"].min() >= 1 and rows["frame"].max() <= 71
    assert len(set(rows["id"].tolist())) >= 8                 # 8 pedestrians, at least one id each
    assert scores["num_objects"] == 359
    # the target: SORT's published MOTA 62.7 with 6 ID switches on these detections
    assert scores["mota"] >= 0.627 and scores["num_switches"] <= 6


def test_mot_track_seed_preset_options(tmp_path, capsys):
    seq = require_data("mot/TUD-Campus")
    code = main([str(seq / "det.txt"), "--fps", "25", "--gt", str(seq / "gt.txt"), "--json", "--gate", "cost",
                 "--confirm-length", "15", "--iou-weight", "0", "--second-pass", "false"])
    assert code == 0
    import json
    scores = json.loads(capsys.readouterr().out)
    assert scores["mota"] < 0.3                                 # the seed's gate: most pairs refused


def test_mot_track_missing_file(tmp_path):
    assert main([str(tmp_path / "nope.txt")]) == 2


def test_mot_track_help_lists_every_parameter(capsys):
    import pytest
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "--mahalanobis-gate" in out and "--kalman-measurement-noise-per-px" in out and "--backfill" in out
