"""make_scenario and convert_dataset write bags whose ground truth reads back as generated."""
from __future__ import annotations

import json

import numpy as np
import pytest

from aircraft_docking_tracker.io.bag import BagReader
from aircraft_docking_tracker.evaluation import evaluate as ev
from aircraft_docking_tracker.images import to_bgr8
from aircraft_docking_tracker.object_table import cloud_to_table
from aircraft_docking_tracker.scenarios import convert_dataset as cd
from aircraft_docking_tracker.scenarios import datasets
from aircraft_docking_tracker.scenarios import make_scenario as ms
from aircraft_docking_tracker.docking.guidance import GUIDANCE_DTYPE
from aircraft_docking_tracker.docking.stand import load_stand
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
from conftest import require_data


def test_make_scenario_docking_bag(tmp_path):
    out = tmp_path / "d.mcap"
    strip = tmp_path / "strip.png"
    stand_file = tmp_path / "stand.yaml"
    assert ms.main(["--kind", "docking", "--seed", "2", "--out", str(out), "--frames", "8", "--width", "320",
                    "--height", "240", "--fps", "20", "--quiet", "--strip", str(strip), "--lateral-offset-m", "1",
                    "--stand-file", str(stand_file)]) == 0
    reader = BagReader(out)
    assert {t: i.type_name for t, i in reader.topics.items()} == {
        "image": "sensor_msgs/msg/Image", "ground_truth/polygon": "geometry_msgs/msg/PolygonStamped",
        "ground_truth/nose": "geometry_msgs/msg/PointStamped", "ground_truth/stand": "std_msgs/msg/String",
        "ground_truth/guidance": "sensor_msgs/msg/PointCloud2"}
    scene = DockingScene(DockingSceneConfig(frames=8, width=320, height=240, fps=20.0, lateral_offset_m=1.0), seed=2)
    guidance = np.concatenate([cloud_to_table(m, GUIDANCE_DTYPE) for _, m, _ in reader.ros_messages(["ground_truth/guidance"])])
    np.testing.assert_allclose(guidance["distance_m"], scene.guidance_truth()[:, 0], rtol=1e-6)
    np.testing.assert_allclose(guidance["lateral_m"], scene.guidance_truth()[:, 1], atol=1e-6)
    assert guidance["state"][0] == 1 and (guidance["state"] == 3).any()        # 8 frames: in, then STOP at the mark
    assert "synthetic_a320" in load_stand(stand_file).aircraft
    frames = list(scene.frames())
    polys = [msg for _, msg, _ in reader.ros_messages(["ground_truth/polygon"])]
    assert len(polys) == 8 and polys[3].header.frame_id == "camera"
    np.testing.assert_allclose([[p.x, p.y] for p in polys[3].polygon.points], frames[3].quad, atol=1e-3)
    assert polys[1].header.stamp.nanosec - polys[0].header.stamp.nanosec == 50_000_000
    image = to_bgr8(next(msg for _, msg, _ in reader.ros_messages(["image"])))
    np.testing.assert_array_equal(image, frames[0].image)
    stand = json.loads(next(msg for _, msg, _ in reader.ros_messages(["ground_truth/stand"])).data)
    assert stand["image_size"] == [320, 240] and len(stand["stop_line_image"]) == 2
    assert strip.stat().st_size > 10_000


def test_make_scenario_uav_bag_with_detections_scores(tmp_path):
    out = tmp_path / "u.mcap"
    assert ms.main(["--kind", "uav", "--seed", "1", "--out", str(out), "--frames", "10", "--detections",
                    "--miss-rate", "0", "--clutter-rate", "0", "--jitter", "0", "--quiet"]) == 0
    reader = BagReader(out)
    assert set(reader.topics) == {"image", "ground_truth", "detections"}
    gt = [cloud_to_table(msg) for _, msg, _ in reader.ros_messages(["ground_truth"])]
    assert all("id" in t.dtype.names for t in gt) and sum(len(t) for t in gt) > 0
    det = ev.evaluate_bags(out)["detection"]
    assert det["detection_rate"] == pytest.approx(1.0) and det["false_alarm_rate"] == 0.0


def test_make_scenario_rejects_bad_options(tmp_path, capsys):
    assert ms.main(["--kind", "docking", "--out", str(tmp_path / "x.mcap"), "--frames", "0", "--quiet"]) == 2
    assert "frames" in capsys.readouterr().err


def test_sot_readers_otb_and_tlp(tmp_path):
    otb = tmp_path / "otb.txt"
    otb.write_text("1,1,10,20\n5\t6\t7\t8\n")
    boxes, fmt = datasets.read_sot_boxes(otb)
    assert fmt == "otb"
    np.testing.assert_allclose(boxes, [[0, 0, 10, 20], [4, 5, 7, 8]])
    tlp = tmp_path / "tlp.txt"
    tlp.write_text("1,5,6,7,8,0\n2,5,6,7,8,1\n")
    boxes, fmt = datasets.read_sot_boxes(tlp)
    assert fmt == "tlp" and np.isnan(boxes[1]).all()
    np.testing.assert_allclose(boxes[0], [5, 6, 7, 8])
    bad = tmp_path / "bad.txt"
    bad.write_text("1,2,x,4\n")
    with pytest.raises(datasets.DatasetError, match="bad.txt:1"):
        datasets.read_sot_boxes(bad)


def test_yolo_labels_and_truncated_image(tmp_path):
    lab = tmp_path / "a.txt"
    lab.write_text("0 0.5 0.5 0.25 0.1\n")
    t = datasets.read_yolo_labels(lab, 640, 640)
    np.testing.assert_allclose([t["x"][0], t["y"][0], t["w"][0], t["h"][0]], [240, 288, 160, 64])
    assert len(datasets.read_yolo_labels(tmp_path / "none.txt", 640, 640)) == 0
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(b"\xff\xd8\xff\xe0 truncated")
    with pytest.raises(datasets.DatasetError, match="broken.jpg"):
        cd.read_image(broken)


def test_convert_otb_sequence(tmp_path):
    folder = require_data("sot/Car4")
    out = tmp_path / "car4.mcap"
    summary = cd.convert(folder, out, max_frames=5, progress=False)
    assert summary["kind"] == "sot" and summary["frames"] == 5
    reader = BagReader(out)
    first = next(msg for _, msg, _ in reader.ros_messages(["ground_truth/polygon"]))
    x, y, w, h = np.loadtxt(folder / "groundtruth_rect.txt", delimiter=",", max_rows=1)
    np.testing.assert_allclose([first.polygon.points[0].x, first.polygon.points[2].y], [x - 1, y - 1 + h])
    image = to_bgr8(next(msg for _, msg, _ in reader.ros_messages(["image"])))
    assert image.shape == (240, 360, 3)


def test_convert_tlp_sequence(tmp_path):
    folder = require_data("sot/CarChase2")
    summary = cd.convert(folder, tmp_path / "cc.mcap", max_frames=3, progress=False)
    assert summary["format"] == "tlp"
    reader = BagReader(tmp_path / "cc.mcap")
    image = to_bgr8(next(msg for _, msg, _ in reader.ros_messages(["image"])))
    assert image.shape == (720, 1280, 3)
    _, x, y, w, h, _ = np.loadtxt(folder / "groundtruth_rect.txt", delimiter=",", max_rows=1)
    first = next(msg for _, msg, _ in reader.ros_messages(["ground_truth/polygon"]))
    np.testing.assert_allclose([first.polygon.points[0].x, first.polygon.points[2].y], [x, y + h])


def test_convert_mot_sequence(tmp_path):
    folder = require_data("mot/airport-2")
    out = tmp_path / "airport.mcap"
    summary = cd.convert(folder, out, max_frames=20, progress=False)
    assert summary["fps"] == 30.0 and summary["frames"] == 20
    reader = BagReader(out)
    assert reader.topics["detections"].count == 20 and reader.topics["ground_truth"].count == 20
    gt = [cloud_to_table(msg) for _, msg, _ in reader.ros_messages(["ground_truth"])]
    first = np.loadtxt(folder / "gt.txt", delimiter=",", max_rows=1)
    row = gt[0][gt[0]["id"] == int(first[1])][0]
    np.testing.assert_allclose([row["x"], row["y"], row["w"], row["h"]], first[2:6], rtol=1e-5)
    stamps = [t for _, _, t in reader.ros_messages(["ground_truth"])]
    assert stamps[1] - stamps[0] == pytest.approx(1e9 / 30, abs=1)
    assert "detection" in ev.evaluate_bags(out)                     # the public detections score


def test_convert_detect_tiles(tmp_path):
    folder = require_data("detect/drone-view-vehicles")
    summary = cd.convert(folder, tmp_path / "tiles.mcap", max_frames=3, progress=False)
    assert summary["kind"] == "detect" and summary["frames"] == 3 and summary["boxes"] > 0
    gt = [cloud_to_table(msg) for _, msg, _ in BagReader(tmp_path / "tiles.mcap").ros_messages(["ground_truth"])]
    assert "id" not in gt[0].dtype.names and (gt[0]["w"] > 10).all()


def test_perfect_tracker_on_a_docking_bag_scores_full_marks(tmp_path):
    out = tmp_path / "d.mcap"
    assert ms.main(["--kind", "docking", "--seed", "6", "--out", str(out), "--frames", "6", "--width", "320",
                    "--height", "240", "--quiet"]) == 0
    frames = list(DockingScene(DockingSceneConfig(frames=6, width=320, height=240), seed=6).frames())
    quads = tmp_path / "quads.txt"
    quads.write_text("".join(",".join(f"{v:.4f}" for v in f.quad.ravel()) + "\n" for f in frames))
    r = ev.evaluate_files(quads, out)["sot"]
    assert r["success_auc"] == pytest.approx(20 / 21)            # IoU 1 passes every threshold but 1.0
    assert r["precision"] == 1.0 and r["lost_frames"] == 0
    assert r["nose_error_median"] < 0.01
    assert r["stop_error_m"] == pytest.approx(0.0, abs=1e-3)
    # a quadrilateral of half the area around the same nose reads the aircraft sqrt(2) times farther
    stand = json.loads(DockingScene(DockingSceneConfig(frames=6, width=320, height=240), seed=6).stand_json())
    last = frames[-1]
    small = last.nose + (last.quad - last.nose) / np.sqrt(2)
    quads.write_text("".join(",".join(f"{v:.4f}" for v in q.ravel()) + "\n"
                             for q in [f.quad for f in frames[:-1]] + [small]))
    r = ev.evaluate_files(quads, out)["sot"]
    depth = stand["camera"]["focal_px"] * stand["metres_per_template_px"] / np.sqrt(
        abs(np.linalg.det(last.affine[:2, :2])))
    assert r["stop_along_m"] == pytest.approx(depth * (np.sqrt(2) - 1), rel=1e-3)
    assert abs(r["stop_lateral_m"]) < 1e-3


def test_evaluate_report_with_strip_and_video_of_a_scene_bag(tmp_path):
    import cv2

    out = tmp_path / "u.mcap"
    assert ms.main(["--kind", "uav", "--seed", "3", "--out", str(out), "--frames", "12", "--width", "320",
                    "--height", "240", "--detections", "--quiet"]) == 0
    rep = tmp_path / "rep"
    assert ev.main([str(out), "--report", str(rep), "--video", "--quiet"]) == 0
    assert (rep / "pr.png").exists() and (rep / "strip.png").stat().st_size > 10_000
    video = cv2.VideoCapture(str(rep / "annotated.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 12
    assert video.get(cv2.CAP_PROP_FPS) == pytest.approx(25.0, rel=0.01)
