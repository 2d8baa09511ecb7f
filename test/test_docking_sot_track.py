"""sot_track over a real OTB folder (skipped without the data), a video and a bag."""
from __future__ import annotations

import cv2
import numpy as np

from aircraft_docking_tracker.docking import affine_group as ag
from aircraft_docking_tracker import sot_track
from aircraft_docking_tracker.io.bag import BagWriter
from aircraft_docking_tracker.geometry import box_iou
from aircraft_docking_tracker.images import numpy_to_image
from aircraft_docking_tracker.scenarios.datasets import read_sot_boxes
from aircraft_docking_tracker.scenarios.messages import header, quad_to_polygon

from conftest import require_data
from test_docking_filter import moving_target_scene


def test_sot_track_on_the_first_frames_of_car4(tmp_path, capsys):
    folder = require_data("sot/Car4")
    out, quads = tmp_path / "car4.txt", tmp_path / "car4_quads.txt"
    assert sot_track.main([str(folder), "--out", str(out), "--quads", str(quads), "--max-frames", "40",
                           "--no-progress"]) == 0
    boxes = np.loadtxt(out, delimiter=",")
    gt = read_sot_boxes(folder / "groundtruth_rect.txt")[0][:40]
    assert boxes.shape == (40, 4) and np.loadtxt(quads, delimiter=",").shape == (40, 8)
    assert np.allclose(boxes[0], gt[0])
    assert box_iou(boxes, gt).mean() > 0.6
    assert "success AUC" in capsys.readouterr().out


def test_on_blurred_footage_the_anchor_term_keeps_the_box_on_the_car():
    """OTB Car4's first 300 frames blurred (σ 2 px, a defocused camera), 3 tracker seeds: without the anchor term
    the box grows while the car shrinks, every patch still scoring over 0.9 (median success AUC 0.67 natively, 0.38
    and 0.37 with OPENBLAS_CORETYPE Prescott and Haswell; boxes up to 3x the frame's width). With the moving
    camera's anchor at its default (``moving_anchor_weight`` 0.5) every run of 6 seeds on each of three kernels
    measured 0.795-0.851 (session 25; at 0.3 up to three runs of six fell to 0.29-0.65), so the worst of the three
    seeds is asserted as well as the median, each with margin."""
    from aircraft_docking_tracker.docking.tracker import DockingConfig  # noqa: PLC0415
    from aircraft_docking_tracker.evaluation.sot_metrics import success_auc  # noqa: PLC0415

    folder = require_data("sot/Car4")
    files = sorted((folder / "img").glob("*.jpg"))[:300]
    frames = [cv2.GaussianBlur(cv2.imread(str(f), cv2.IMREAD_COLOR), (0, 0), 2.0) for f in files]
    gt = read_sot_boxes(folder / "groundtruth_rect.txt")[0][:len(frames)]
    default = DockingConfig().moving_anchor_weight
    assert default > 0
    aucs, widest = {}, {}
    for beta in (0.0, default):
        for seed in range(3):
            run = sot_track.track(iter(frames), gt[0], DockingConfig(seed=seed, moving_anchor_weight=beta),
                                  len(frames), progress=False)
            aucs.setdefault(beta, []).append(success_auc(box_iou(run.boxes, gt)))
            widest.setdefault(beta, []).append(float(np.nanmax(run.boxes[:, 2:])))
    assert np.median(aucs[default]) > 0.75 and np.median(aucs[default]) > np.median(aucs[0.0]) + 0.05, aucs
    assert min(aucs[default]) > 0.65, aucs
    assert max(widest[default]) < frames[0].shape[1] / 2, widest     # the car is 60-110 px wide, the frame 360


def test_sot_track_pf_on_a_video_with_an_init_box(tmp_path):
    scene = list(moving_target_scene(40))[:15]
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    for frame, _ in scene:
        writer.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
    writer.release()
    init = ",".join(f"{v:.1f}" for v in ag.to_box(scene[0][1]))
    out = tmp_path / "r.txt"
    assert sot_track.main([str(video), "--init", init, "--method", "pf", "--pf-particles", "200",
                           "--out", str(out), "--no-progress"]) == 0
    boxes = np.loadtxt(out, delimiter=",")
    truth = np.array([ag.to_box(X) for _, X in scene])
    assert len(boxes) == 15 and box_iou(boxes, truth).mean() > 0.6


def test_sot_track_on_a_bag_takes_the_first_ground_truth_polygon(tmp_path, capsys):
    scene = list(moving_target_scene(40))[:10]
    bag = tmp_path / "scene.mcap"
    with BagWriter(bag) as writer:
        for k, (frame, X) in enumerate(scene):
            hdr = header(int(1e9 + k * 1e8))
            writer.write("/image", numpy_to_image(frame, "mono8", hdr), int(1e9 + k * 1e8))
            writer.write("/ground_truth/polygon", quad_to_polygon(ag.to_quad(X), hdr), int(1e9 + k * 1e8))
    out = tmp_path / "r.txt"
    assert sot_track.main([str(bag), "--out", str(out), "--no-progress"]) == 0
    assert len(np.loadtxt(out, delimiter=",")) == 10
    assert "success AUC" in capsys.readouterr().out


def test_sot_track_guides_a_docking_bag_and_times_the_guidance_beside_the_tracker(tmp_path, capsys):
    """With a stand file each frame is guided as the node guides it; the guidance's own time per frame is kept
    apart from the tracker's (issue 15 asks that it add under a millisecond) and both are printed."""
    from aircraft_docking_tracker.docking.guidance import GuidanceConfig
    from aircraft_docking_tracker.docking.tracker import DockingConfig
    from aircraft_docking_tracker.scenarios import make_scenario

    bag, stand, rows = tmp_path / "d.mcap", tmp_path / "stand.yaml", tmp_path / "g.csv"
    assert make_scenario.main(["--kind", "docking", "--seed", "2", "--out", str(bag), "--frames", "12", "--width",
                               "320", "--height", "240", "--quiet", "--stand-file", str(stand)]) == 0
    assert sot_track.main([str(bag), "--guidance.stand-file", str(stand), "--guidance", str(rows),
                           "--no-progress"]) == 0
    line = capsys.readouterr().out
    assert "ms/frame" in line and "beside the tracker's" in line and "within the last 15 m" in line
    table = np.loadtxt(rows, delimiter=",", skiprows=1)
    assert table.shape == (12, 5) and set(table[:, 4]) <= {0, 1, 2, 3, 4, 5}
    seq = sot_track.open_sequence(bag)
    guidance, stamps = sot_track.guidance_for(GuidanceConfig(stand_file=str(stand)), seq.stamps, 10.0)
    run = sot_track.track(seq.frames, seq.gt[0], DockingConfig(), seq.count, guidance=guidance,
                          stamps=stamps)
    assert run.guidance_seconds.shape == run.step_seconds.shape == (12,) and (run.guidance_seconds > 0).all()


def test_sot_track_refuses_bad_inputs(tmp_path, capsys):
    assert sot_track.main([str(tmp_path / "nothing.txt"), "--init", "1,2,3,4", "--no-progress"]) == 2
    folder = tmp_path / "frames"
    folder.mkdir()
    cv2.imwrite(str(folder / "0001.png"), np.zeros((20, 20), np.uint8))
    assert sot_track.main([str(folder), "--no-progress"]) == 2                   # no init, no ground truth
    assert sot_track.main([str(folder), "--init", "1,2,3", "--no-progress"]) == 2
    assert sot_track.main([str(folder), "--init", "1,2,3,4", "--n-initial", "0", "--no-progress"]) == 2
    assert "sot_track:" in capsys.readouterr().err
