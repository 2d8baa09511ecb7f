"""The boosted cascade: training on a tiny synthetic set finds its targets; model file; grouping."""
import json

import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.geometry import box_iou
from multi_target_tracker.cascade import Cascade, CascadeError, CascadeTrainConfig, Stage, train_cascade
from multi_target_tracker.detector import Detector, DetectorConfig, DetectorError, group_windows, suppress_contained
from multi_target_tracker.train_cascade import LabelledImage, NegativeMiner, photometric, positive_vectors, window_shaped

WINDOW = (48, 24)


def _scene(rng, n_targets, size=(200, 160)):
    """Textured background with dark 48x24 'vehicles' (bright roof, dark windows)."""
    w, h = size
    image = cv2.GaussianBlur(rng.integers(60, 200, (h, w), dtype=np.uint8), (0, 0), 3)
    image = cv2.add(image, rng.integers(0, 30, (h, w), dtype=np.uint8))
    for _ in range(6):  # clutter: lines and blobs
        p = rng.integers(0, (w, h), 2)
        q = p + rng.integers(-60, 60, 2)
        cv2.line(image, tuple(int(v) for v in p), tuple(int(v) for v in q), int(rng.integers(0, 255)), 2)
    boxes = []
    while len(boxes) < n_targets:
        bw, bh = int(rng.integers(44, 56)), 0
        bh = bw // 2
        x, y = int(rng.integers(4, w - bw - 4)), int(rng.integers(4, h - bh - 4))
        if boxes and box_iou(np.array(boxes, float), np.array([x, y, bw, bh], float)).max() > 0:
            continue
        cv2.rectangle(image, (x, y), (x + bw, y + bh), 25, -1)
        cv2.rectangle(image, (x + bw // 4, y + 3), (x + 3 * bw // 4, y + bh - 4), 235, -1)
        cv2.rectangle(image, (x + bw // 4 - 5, y + 4), (x + bw // 4 - 2, y + bh - 5), 90, -1)
        boxes.append([x, y, bw, bh])
    return image, np.array(boxes, float)


def train_tiny_model(path):
    """A 48x24 cascade trained on 20 synthetic scenes (a few seconds); saved to ``path``."""
    rng = np.random.default_rng(7)
    data = []
    for k in range(20):
        image, boxes = _scene(rng, 3)
        data.append(LabelledImage(f"s{k}", lambda image=image: image, boxes))
    xp, heights = positive_vectors(data, WINDOW, "fused", 40.0, False, "hv", rng=rng, jitter=2,
                                   jitter_shift=2 / 32, jitter_scale=1.15 ** 0.5)
    assert 3 * 4 * 60 - 10 <= len(xp) <= 3 * 4 * 60 and heights.min() >= 22  # a jitter may leave the frame
    miner = NegativeMiner(data, [], dict(scale_factor=1.15, stride=4, min_size=20, max_size=30), False, 0.3, rng)
    cfg = CascadeTrainConfig(stages=6, negatives=400, max_stumps=15, hit_rate=0.995, false_alarm_rate=0.5)
    cascade = train_cascade(xp, miner, cfg, WINDOW, 40.0)
    cascade.save(path)
    return cascade


TINY_DETECTOR = dict(scale_factor=1.1, min_size=20, max_size=30, min_neighbors=2, group_iou=0.2)


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "tiny.json"
    return path, train_tiny_model(path)


def test_tiny_cascade_finds_its_targets(tiny_model):
    path, cascade = tiny_model
    assert len(cascade.stages) >= 2
    det = Detector(DetectorConfig(model=str(path), **TINY_DETECTOR))
    rng = np.random.default_rng(123)
    found = total = false = 0
    for _ in range(3):
        image, truth = _scene(rng, 3)
        out = det.detect(image)
        boxes = np.column_stack([out["x"], out["y"], out["w"], out["h"]])
        iou = box_iou(boxes[:, None, :], truth[None, :, :]) if len(boxes) else np.zeros((0, 3))
        found += int((iou.max(axis=0) >= 0.5).sum()) if len(boxes) else 0
        false += int((iou.max(axis=1) < 0.5).sum()) if len(boxes) else 0
        total += len(truth)
    assert found >= total - 1, (found, total)
    assert false <= 3, false


def test_model_round_trip_and_bad_files(tiny_model, tmp_path):
    path, cascade = tiny_model
    again = Cascade.load(path)
    assert again.window == WINDOW and again.feature_set == "fused" and again.n_stumps == cascade.n_stumps
    x = np.random.default_rng(0).integers(0, 256, (50, 1152), dtype=np.uint8)
    assert np.array_equal(cascade.evaluate_vectors(x)[0], again.evaluate_vectors(x)[0])
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(CascadeError):
        Cascade.load(bad)
    d = json.loads(path.read_text())
    d["stages"][0]["features"][0] = 5000
    bad.write_text(json.dumps(d))
    with pytest.raises(CascadeError):
        Cascade.load(bad)
    d = json.loads(path.read_text())
    d["feature_set"] = "lbp"
    d["stages"][0]["features"][0] = 1100  # a contour feature in an lbp-only model
    bad.write_text(json.dumps(d))
    with pytest.raises(CascadeError):
        Cascade.load(bad)
    with pytest.raises(DetectorError):
        Detector(DetectorConfig(model=str(tmp_path / "missing.json")))


def test_stage_and_cascade_evaluation_by_hand():
    stage = Stage(np.array([0, 1024]), np.array([100, 10]), np.array([-1.0, -0.5]), np.array([1.0, 0.5]), 0.9)
    cascade = Cascade((32, 32), "fused", 40.0, [stage])
    x = np.zeros((3, 1152), np.uint8)
    x[0, 0], x[0, 1024] = 150, 20     # 1 + 0.5 = 1.5 >= 0.9
    x[1, 0], x[1, 1024] = 150, 5      # 1 - 0.5 = 0.5 < 0.9
    x[2, 0], x[2, 1024] = 99, 255     # -1 + 0.5
    idx, score = cascade.evaluate_vectors(x)
    assert idx.tolist() == [0] and score == pytest.approx([0.6])
    idx, _ = cascade.evaluate_vectors(x, last_stage_margin=-0.5)
    assert idx.tolist() == [0, 1]


def test_group_windows_by_hand():
    # three windows on one object (margins 1, 3, 2), a lone window elsewhere (margin 5)
    boxes = np.array([[10, 10, 40, 20], [12, 11, 40, 20], [11, 9, 40, 20], [100, 100, 40, 20]], float)
    margins = np.array([1.0, 3.0, 2.0, 5.0])
    grouped, scores = group_windows(boxes, margins, group_iou=0.3, min_neighbors=1, containment=1.0)
    # the lone window seeds first; the cluster's box is the mean of its three windows
    assert grouped.tolist() == [[11, 10, 40, 20], [100, 100, 40, 20]]
    assert scores == pytest.approx([3 + 1 / (1 + np.exp(-3.0)), 1 + 1 / (1 + np.exp(-5.0))])
    grouped, scores = group_windows(boxes, margins, group_iou=0.3, min_neighbors=2, containment=1.0)
    assert grouped.tolist() == [[11, 10, 40, 20]]           # the lone window has no neighbour
    grouped, scores = group_windows(boxes, margins, group_iou=0.9, min_neighbors=1, containment=1.0)
    assert len(grouped) == 4                                  # nothing overlaps that much
    empty, no_scores = group_windows(np.zeros((0, 4)), np.zeros(0))
    assert empty.shape == (0, 4) and no_scores.shape == (0,)


def test_contained_groups_are_suppressed():
    # a window on half a car (inside the car's box) and a car box: IoU 0.5, containment 1
    boxes = np.array([[0, 0, 40, 20], [0, 0, 20, 20], [60, 0, 40, 20]], float)
    scores = np.array([5.0, 4.0, 3.0])
    assert suppress_contained(boxes, scores, 0.4).tolist() == [0, 2]
    assert suppress_contained(boxes, scores, 1.0).tolist() == [0, 1, 2]   # 1 disables it
    # a box touching another by a sliver stays
    assert suppress_contained(np.array([[0, 0, 40, 20], [38, 0, 40, 20]], float), np.array([2.0, 1.0]),
                              0.4).tolist() == [0, 1]


def test_discrete_adaboost_trains_too():
    rng = np.random.default_rng(0)
    xp = rng.integers(100, 256, (200, 1152), dtype=np.uint8)
    xp[:, 1024:] = 0

    def mine(cascade, n):
        x = rng.integers(0, 156, (n, 1152), dtype=np.uint8)
        return x[cascade.evaluate_vectors(x)[0]] if cascade.stages else x

    cfg = CascadeTrainConfig(stages=2, negatives=200, boost="discrete", feature_set="lbp", max_stumps=5)
    cascade = train_cascade(xp, mine, cfg, (32, 32), 40.0)
    assert cascade.used_features().max() < 1024
    assert len(cascade.evaluate_vectors(xp)[0]) >= 190


def test_negative_pool_replaces_image_scans_once_small(tiny_model):
    _, cascade = tiny_model
    rng = np.random.default_rng(3)
    loads = []
    data = []
    for k in range(6):
        image, boxes = _scene(rng, 3)
        data.append(LabelledImage(f"p{k}", lambda image=image, k=k: loads.append(k) or image, boxes))
    scan = dict(scale_factor=1.15, stride=4, min_size=20, max_size=30)
    one_stage = Cascade(cascade.window, cascade.feature_set, cascade.edge_threshold, cascade.stages[:1])
    two_stages = Cascade(cascade.window, cascade.feature_set, cascade.edge_threshold, cascade.stages[:2])

    pooled = NegativeMiner(data, [], scan, False, 0.3, np.random.default_rng(0), pool_size=10 ** 6)
    first = pooled(one_stage, 50)
    assert pooled.pool is not None and len(first) == 50
    loads_after_pool = len(loads)
    assert loads_after_pool >= len(data)                 # one full pass over every image built the pool
    assert len(one_stage.evaluate_vectors(pooled.pool)[0]) == len(pooled.pool)
    second = pooled(two_stages, 10 ** 6)                 # filtered, not scanned again
    assert len(loads) == loads_after_pool
    assert len(second) == len(pooled.pool) and len(two_stages.evaluate_vectors(second)[0]) == len(second)

    scanning = NegativeMiner(data, [], scan, False, 0.3, np.random.default_rng(0), pool_size=0)
    scanning(one_stage, 50)
    assert scanning.pool is None                         # pool_size 0: every stage scans images


def test_positives_reshaped_to_the_window():
    # a 40x40 box reshaped to a 2:1 window keeps its centre (30, 40) and area 1600
    assert window_shaped([10, 20, 40, 40], (64, 32)) == pytest.approx([30 - 28.2843, 40 - 14.1421, 56.5685, 28.2843],
                                                                     abs=1e-3)
    image = np.full((120, 160), 90, np.uint8)
    cv2.rectangle(image, (50, 40), (89, 79), 200, -1)
    data = [LabelledImage("square", lambda: image, np.array([[50.0, 40.0, 40.0, 40.0]]))]
    as_box, heights_box = positive_vectors(data, (64, 32), "fused", 40.0, False, "none")
    as_window, heights_window = positive_vectors(data, (64, 32), "fused", 40.0, False, "none",
                                                 positive_aspect="window")
    assert heights_box.tolist() == [40.0] and heights_window == pytest.approx([28.2843], abs=1e-3)
    assert len(as_box) == len(as_window) == 1 and not np.array_equal(as_box, as_window)


def test_train_cascade_command_on_a_yolo_folder(tmp_path, capsys):
    from multi_target_tracker.train_cascade import main as train_main

    rng = np.random.default_rng(11)
    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    for k in range(8):
        image, boxes = _scene(rng, 3)
        cv2.imwrite(str(tmp_path / "images" / f"a_{k}.png"), image)
        h, w = image.shape
        rows = [f"0 {(x + bw / 2) / w:.6f} {(y + bh / 2) / h:.6f} {bw / w:.6f} {bh / h:.6f}" for x, y, bw, bh in boxes]
        (tmp_path / "labels" / f"a_{k}.txt").write_text("\n".join(rows) + "\n")
    from multi_target_tracker.train_cascade import read_yolo_folder
    items = read_yolo_folder(tmp_path)
    assert [item.size for item in items] == [image.shape[::-1]] * 8      # (width, height), known without a read
    model = tmp_path / "model.json"
    # a 60x30 window is larger than every 44..56 x 22..28 box: the trainer says so and searches from 30 px
    code = train_main(["--yolo", str(tmp_path), "--window", "60", "30", "--stages", "2", "--negatives", "100",
                       "--max-stumps", "5", "--positive-aspect", "window", "--output", str(model)])
    assert code == 0
    said = capsys.readouterr().out
    assert "lower than the 30 px window" in said and "stage 2/2" in said
    cascade = Cascade.load(model)
    assert len(cascade.stages) == 2 and cascade.window == (60, 30)
    assert cascade.info["positive_aspect"] == "window" and cascade.info["search_min_size"] == 30.0
    assert train_main(["--yolo", str(tmp_path / "missing"), "--output", str(model)]) == 2


def test_threads_give_the_same_detections(tiny_model):
    path, _ = tiny_model
    image, _ = _scene(np.random.default_rng(5), 3)
    one = Detector(DetectorConfig(model=str(path), **TINY_DETECTOR, orientation="both")).detect(image)
    two = Detector(DetectorConfig(model=str(path), **TINY_DETECTOR, orientation="both", threads=2)).detect(image)
    assert len(one) > 0 and np.array_equal(one, two)


def test_contained_suppression_stops_at_the_limit():
    boxes = np.array([[100.0 * k, 0, 40, 20] for k in range(10)])
    assert suppress_contained(boxes, np.arange(10.0), 0.4, limit=3).tolist() == [9, 8, 7]
    assert suppress_contained(boxes, np.arange(10.0), 1.0, limit=3).tolist() == [9, 8, 7]


def test_photometric_augmentation_changes_grey_levels_only():
    rng = np.random.default_rng(3)
    crop = rng.integers(60, 200, (40, 70), dtype=np.uint8)
    augment = photometric(np.random.default_rng(0), 1.0)
    outs = [augment(crop) for _ in range(20)]
    assert all(o.shape == crop.shape and o.dtype == np.uint8 for o in outs)
    means = [float(o.mean()) for o in outs]
    assert np.ptp(means) > 10                                        # brightness varies
    assert any(np.abs(o.astype(int) - crop).max() > 5 for o in outs)
    same = photometric(np.random.default_rng(0), 1.0)
    assert all(np.array_equal(o, same(crop)) for o in outs)          # reproducible from the seed


def test_photometric_strength_zero_keeps_the_positives():
    rng = np.random.default_rng(2)
    image, boxes = _scene(rng, 3)
    data = [LabelledImage("a", lambda: image, boxes)]
    plain, _ = positive_vectors(data, (32, 32), "fused", 40.0, False, "h", rng=np.random.default_rng(1), jitter=2)
    zero, _ = positive_vectors(data, (32, 32), "fused", 40.0, False, "h", rng=np.random.default_rng(1), jitter=2,
                               photometric_strength=0.0)
    strong, _ = positive_vectors(data, (32, 32), "fused", 40.0, False, "h", rng=np.random.default_rng(1), jitter=2,
                                 photometric_strength=1.0)
    assert np.array_equal(plain, zero)                               # strength 0: the former positives
    assert abs(len(strong) - len(plain)) <= 3 and not np.array_equal(strong[:len(plain)], plain[:len(strong)])


def test_turned_positive_is_cut_from_the_box_with_its_surroundings():
    from multi_target_tracker.train_cascade import positive_vector
    rng = np.random.default_rng(4)
    image, boxes = _scene(rng, 2)
    box = boxes[0]
    plain = positive_vector(image, box, "fused", 40.0)
    assert np.array_equal(positive_vector(image, box, "fused", 40.0, angle=360.0), plain)   # the same frame pixels
    turned = [positive_vector(image, box, "fused", 40.0, angle=a) for a in (-15.0, 15.0)]
    assert all(t is not None and not np.array_equal(t, plain) for t in turned)
    assert not np.array_equal(turned[0], turned[1])


def test_turn_jitter_zero_keeps_the_positives_and_turns_only_the_copies():
    rng = np.random.default_rng(2)
    image, boxes = _scene(rng, 3)
    data = [LabelledImage("a", lambda: image, boxes)]
    run = lambda **kw: positive_vectors(data, (32, 32), "fused", 40.0, False, "none",  # noqa: E731
                                        rng=np.random.default_rng(1), jitter=2, **kw)[0]
    plain, zero, turned = run(), run(turn_jitter=0.0), run(turn_jitter=20.0)
    assert np.array_equal(plain, zero)                               # 0: the former positives, same draws
    assert abs(len(turned) - len(plain)) <= 3                        # a turned copy's larger box may leave the frame
    assert np.array_equal(turned[0], plain[0])                       # the labelled box itself is never turned
    assert not np.array_equal(turned, plain)


def test_turned_box_bounds_the_turned_rectangle():
    from multi_target_tracker.train_cascade import turned_box
    box = np.array([10.0, 20.0, 40.0, 20.0])
    assert np.allclose(turned_box(box, 0.0), box) and np.allclose(turned_box(box, 90.0), [20, 10, 20, 40])
    diag = turned_box(box, 45.0)
    assert np.allclose(diag[2], diag[3]) and np.allclose(diag[2], 60 / np.sqrt(2))
    assert np.allclose(diag[:2] + diag[2:] / 2, box[:2] + box[2:] / 2)          # same centre


def test_boxes_clipped_one_pixel_inside_the_frame_count_as_cut():
    from multi_target_tracker.train_cascade import truncated
    boxes = np.array([[0.0, 50, 40, 20], [1.0, 50, 40, 20], [50, 50, 40, 20], [50, 1.0, 40, 20],
                      [159.0 - 40, 50, 40, 20], [3.0, 50, 40, 20]])
    assert truncated(boxes, (160, 120)).tolist() == [True, True, False, True, True, False]


def test_negative_miner_scans_the_detectors_turned_views(tiny_model, tmp_path):
    """With ``angles`` the miner meets the windows the detector's scan meets (turned and transposed views,
    mapped back to the image), minus those on a labelled box; without, it is the upright miner as before."""
    _, cascade = tiny_model
    one_stage = Cascade(cascade.window, cascade.feature_set, cascade.edge_threshold, cascade.stages[:1])
    one_stage.save(tmp_path / "one.json")
    image, boxes = _scene(np.random.default_rng(11), 3)
    scan = dict(scale_factor=1.15, stride=4, min_size=20, max_size=30)
    data = [LabelledImage("s", lambda: image, boxes)]
    upright = NegativeMiner(data, [], scan, True, 0.3, np.random.default_rng(0))
    same = NegativeMiner(data, [], scan, True, 0.3, np.random.default_rng(0), angles=(0.0,))
    assert np.array_equal(upright._scan(one_stage, image, boxes, None)[0], same._scan(one_stage, image, boxes, None)[0])
    turned = NegativeMiner(data, [], scan, True, 0.3, np.random.default_rng(0), angles=(0.0, 45.0))
    vectors, accepted = turned._scan(one_stage, image, boxes, None)
    detector = Detector(DetectorConfig(model=str(tmp_path / "one.json"), angles=[0.0, 45.0], orientation="both",
                                       stride=4, scale_factor=1.15, min_size=20, max_size=30))
    windows = detector.raw(image, 0.0).boxes
    away = box_iou(windows[:, None, :], boxes[None, :, :]).max(axis=1) < 0.3
    assert accepted == len(vectors) == int(away.sum())
    assert accepted > upright._scan(one_stage, image, boxes, None)[1]
