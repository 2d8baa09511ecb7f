"""Report plots are written for ordinary and degenerate runs (all lost, nothing detected)."""
from __future__ import annotations

import numpy as np

from aircraft_docking_tracker.evaluation import plots
from aircraft_docking_tracker.evaluation.detection_metrics import detection_summary
from aircraft_docking_tracker.evaluation.sot_metrics import score_sequence
from aircraft_docking_tracker.scenarios import strips


def test_sot_plots_with_a_lost_run(tmp_path):
    gt = np.array([[0, 0, 10, 10]] * 5, float)
    runs = {"good": score_sequence(gt + 1, gt), "lost": score_sequence(np.full((5, 4), np.nan), gt)}
    for name, fn in (("sp.png", plots.success_precision_plot), ("iou.png", plots.iou_over_time_plot)):
        assert fn(runs, tmp_path / name).stat().st_size > 5000
    assert plots.iou_over_time_plot({"lost": runs["lost"]}, tmp_path / "only_lost.png").exists()


def test_detection_and_mot_plots(tmp_path):
    runs = {"a": detection_summary([0.9, 0.5], [True, False], 3), "none": detection_summary([], [], 3)}
    assert plots.pr_plot(runs, tmp_path / "pr.png").stat().st_size > 5000
    cont = [{"gt_id": 1, "first_frame": 1, "last_frame": 9, "frames_present": 9, "frames_tracked": 7,
             "longest_continuous": 5}]
    assert plots.continuity_bars({"x": cont, "y": []}, tmp_path / "c.png").stat().st_size > 5000
    assert plots.timeline_plot({1: [(1, 3), (2, None), (3, 4)]}, tmp_path / "t.png").stat().st_size > 3000


def test_strip_of_plain_images(tmp_path):
    images = [np.full((48, 64, 3), v, np.uint8) for v in (0, 128, 255)]
    strip = strips.strip_image(images, tile_width=32)
    assert strip.shape == (24, 3 * 34, 3)
    assert strips.frame_strip(images, tmp_path / "s.png").exists()
