"""bench/docking.py --diagnose measures what it says: per-frame IoU, signed parameter errors and the IoU one
exact parameter group would win, on quadrilaterals whose errors are known."""
import importlib.util
from pathlib import Path

import numpy as np

from aircraft_docking_tracker.docking import affine_group as ag

_SPEC = importlib.util.spec_from_file_location("bench_docking", Path(__file__).resolve().parents[1] / "bench" / "docking.py")
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def quads(params):
    return ag.to_quad(ag.from_params(np.asarray(params, dtype=float)))


def truth_params(n=6):
    t = np.linspace(0, 1, n)
    return np.stack([200 + 100 * t, 150 + 20 * t, 40 * (1 + 3 * t), np.full(n, 2.0), np.deg2rad(30) * (1 - t),
                     np.zeros(n)], axis=1)


def test_an_exact_track_scores_one_and_nothing_to_win():
    truth = quads(truth_params())
    e = bench.frame_errors(truth.copy(), truth)
    assert np.allclose(e["iou"], 1.0, atol=1e-6)
    for c in bench.COMPONENTS:
        assert np.abs(e[f"gain_{c}"]).max() < 1e-6
    assert np.abs(e["log_scale"]).max() < 1e-9 and np.abs(e["rotation_deg"]).max() < 1e-6


def test_known_errors_are_recovered_with_their_sign_and_the_right_group_wins():
    p = truth_params()
    truth = quads(p)
    wrong = p.copy()
    wrong[:, 2] *= 1.3                                  # 30 % too large
    wrong[:, 4] -= np.deg2rad(20)                       # turned 20 deg
    e = bench.frame_errors(quads(wrong), truth)
    assert np.allclose(e["log_scale"], np.log(1.3), atol=1e-6)
    assert np.allclose(e["rotation_deg"], -20, atol=1e-6)
    assert np.allclose(e["log_aspect"], 0, atol=1e-6) and np.abs(e["du"]).max() < 1e-6
    assert (e["iou"] < 0.8).all()
    assert (e["gain_scale"] > 0.05).all() and (e["gain_rotation"] > 0.02).all()
    assert np.abs(e["gain_skew"]).max() < 1e-6 and np.abs(e["gain_centre"]).max() < 1e-6


def test_a_centre_offset_is_measured_along_the_true_axes_and_missing_frames_count_as_zero():
    p = truth_params()
    truth = quads(p)
    g = ag.from_params(p)
    moved = g @ np.array([[1, 0, 0.0], [0, 1, 0.1], [0, 0, 1]])   # a tenth of the height down its own v axis
    pred = ag.to_quad(moved)
    pred[0] = np.nan                                                # no track in the first frame
    e = bench.frame_errors(pred, truth)
    assert e["iou"][0] == 0.0 and np.isnan(e["dv"][0])
    assert np.allclose(e["dv"][1:], 0.1, atol=1e-6) and np.allclose(e["du"][1:], 0.0, atol=1e-6)
    assert (e["gain_centre"][1:] > 0.05).all()


def test_failure_kinds():
    n = 100
    assert bench.failure_kind(np.full(n, 0.8), 0.7) == "ok"
    lost = np.r_[np.full(30, 0.7), np.full(70, 0.05)]
    assert bench.failure_kind(lost, 0.25) == "lost"
    slow = np.r_[np.full(30, 0.3), np.full(70, 0.6)]
    assert bench.failure_kind(slow, 0.45) == "slow start"
    assert bench.failure_kind(np.full(n, 0.55), 0.45) == "poor fit"


def test_real_only_sweep_and_stride(tmp_path):
    """--sweep gives one candidate per value (an unknown key is refused); --real-stride N keeps every N-th frame with
    its own ground-truth box."""
    import cv2  # noqa: PLC0415
    import pytest  # noqa: PLC0415

    assert bench.parse_sweep(["update_relative=1,3"]) == {"update_relative=1": {"update_relative": 1},
                                                          "update_relative=3": {"update_relative": 3}}
    with pytest.raises(SystemExit):
        bench.parse_sweep(["no_such_field=1,2"])
    folder = tmp_path / "sot" / "Car4" / "img"
    folder.mkdir(parents=True)
    for i in range(10):
        cv2.imwrite(str(folder / f"{i + 1:04d}.png"), np.full((20, 30), i * 10, np.uint8))
    (tmp_path / "sot" / "Car4" / "groundtruth_rect.txt").write_text(
        "\n".join(f"{i + 1},2,5,6" for i in range(10)) + "\n")          # OTB: 1-based
    seq, = bench.real_sequences(tmp_path, 9, stride=3)
    assert [Path(f).name for f in seq["files"]] == ["0001.png", "0004.png", "0007.png"]
    assert seq["gt_boxes"][:, 0].tolist() == [0, 3, 6] and seq["size"] == [30, 20]
