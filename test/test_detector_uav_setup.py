"""The UAV camera's detector set-up (config/uav_camera.yaml + its shipped model) on held-out UAV scenes.

Scenes at the camera height the set-up is made for (``UAV_SETUP_GROUND_RESOLUTION``), seeds from
``UAV_EVAL_SEEDS`` (never used for training or for choosing the operating point). The bounds hold
with margin: bench/uav_detector.py measures the set-up on more seeds (see its table).
"""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError, load_yaml_parameters, package_config_dir, validate
from aircraft_docking_tracker.evaluation.detection_metrics import DetectionAccumulator
from aircraft_docking_tracker.object_table import LOW_CONFIDENCE, confident_rows
from aircraft_docking_tracker.offline import build_processor
from aircraft_docking_tracker.scenarios.uav import (
    UAV_BEFORE_BLOBS as BEFORE_BLOBS, UAV_BEFORE_PATCH_NET as BEFORE_PATCH_NET, UAV_BEFORE_SPEED as BEFORE_SPEED, UAV_CASCADE_ONLY as CASCADE_ONLY, UAV_LOGISTIC as LOGISTIC, UAV_MEMBER_BOXES as MEMBER_BOXES,
    UAV_UPRIGHT as UPRIGHT, UAV_UPRIGHT_GROUPS as UPRIGHT_GROUPS,
    UAV_VERIFIER_ONLY as VERIFIER_ONLY, UAV_EVAL_SEEDS, UAV_SETUP_GROUND_RESOLUTION, UAV_TRAIN_SEEDS,
    UAV_TUNING_SEEDS, UavScene, UavSceneConfig, detection_truth)
from multi_target_tracker.cascade import Cascade
from multi_target_tracker.detector import EVERY_GROUP, NEVER_EXEMPT, Detector, DetectorConfig, resolve_model

SETUP = package_config_dir() / "uav_camera.yaml"
# pooled over seeds 3900-3903 (every 8th frame) the set-up with its colour verifier measured detection 0.52 at
# false alarms 0.19, the same cascade without it (window count, min_neighbors 8) 0.49 / 0.38 (before the verifier
# the set-up measured 0.49 / 0.38 at every 4th frame, the upright model 0.33 / 0.74): still below issue 12's
# 0.85 / 0.15; these bounds keep a margin under what the four seeds below measure
MIN_DETECTION, MAX_FALSE_ALARMS = 0.35, 0.35


@pytest.fixture(scope="module")
def detector():
    processor = build_processor("detector", SETUP)
    assert processor.detector is not None, processor.model_error
    return processor.detector


def test_uav_setup_validates_and_bounds_the_search_to_the_altitudes_vehicle_sizes(detector):
    params = load_yaml_parameters(SETUP, "detector")
    cfg = validate(DetectorConfig(**{k: v for k, v in params.items() if k in DetectorConfig.__dataclass_fields__}))
    assert cfg.min_size > 0 and cfg.max_size > cfg.min_size           # the altitude fixes the size range
    assert detector.min_size == cfg.min_size and detector.max_size == cfg.max_size
    model = Cascade.load(resolve_model(cfg.model))
    assert model.feature_set == "fused" and model.rotate90
    assert model.window[0] == 2 * model.window[1]                       # heading-aligned: along the vehicle
    assert sorted(cfg.angles) == [0.0, 45.0] and detector.both_orientations   # 0, 45, 90, 135 degrees
    assert cfg.min_size >= model.window[1]                              # no window below the model's
    assert resolve_model(cfg.model).stat().st_size < 5_000_000


def test_uav_protocol_seed_ranges_are_disjoint():
    ranges = [set(UAV_TRAIN_SEEDS), set(UAV_TUNING_SEEDS), set(UAV_EVAL_SEEDS)]
    assert all(not (a & b) for i, a in enumerate(ranges) for b in ranges[i + 1:])
    assert 106 not in ranges[0] | ranges[1]                             # the demo's seed is held out


HELD_OUT = UAV_EVAL_SEEDS[900:904]


@pytest.fixture(scope="module")
def held_out_frames():
    """Every 8th frame (image, ground truth) of four demo-like held-out scenes, rendered once for the module: the
    tests compare several set-ups side by side on the very same frames."""
    config = UavSceneConfig(frames=80, fps=10.0, difficulty=1, ground_resolution=UAV_SETUP_GROUND_RESOLUTION)
    return {seed: [(frame.image, frame.ground_truth) for k, frame in enumerate(UavScene(config, seed=seed).frames())
                   if k % 8 == 4] for seed in HELD_OUT}


@pytest.fixture(scope="module")
def counts_of(held_out_frames):
    """``counts_of(detector)``: (vehicles counted, detections, true detections) per held-out scene, an array of
    shape (4, 3); remembered per detector configuration, as several tests count the same set-up."""
    remembered = {}

    def counts(detector: Detector) -> np.ndarray:
        key = repr(detector.config)
        if key not in remembered:
            remembered[key] = np.array([_counts(detector, held_out_frames[seed]) for seed in HELD_OUT])
        return remembered[key]
    return counts


def _counts(detector, frames) -> tuple[int, int, int]:
    """(vehicles counted, detections, true detections) on one scene's frames."""
    acc = DetectionAccumulator()
    for image, ground_truth in frames:
        table = confident_rows(detector.detect(image))   # BGR: the set-up's colour verifier reads it
        boxes, ignore = detection_truth(ground_truth)
        acc.add_frame(np.column_stack([table["x"], table["y"], table["w"], table["h"]]), table["score"],
                      boxes, ignore)
    s = acc.summary()
    return s["ground_truth"], s["detections"], s["true_positives"]


def assert_side_by_side(counts_of, new, old, gain: float, slack: float, context=()) -> None:
    """``new`` against ``old`` on the same held-out scenes: the same vehicles counted, at least ``gain`` times their number
    more true detections (negative: at most that many fewer), and a false-alarm rate at most ``slack`` above ``old``'s
    (negative: at least that much below)."""
    vehicles, detections, true = counts_of(new).sum(axis=0)
    o_vehicles, o_detections, o_true = counts_of(old).sum(axis=0)
    assert vehicles == o_vehicles
    assert true >= o_true + gain * vehicles, (*context, true, o_true, vehicles)
    assert 1 - true / max(detections, 1) <= 1 - o_true / max(o_detections, 1) + slack, (
        *context, true, detections, o_true, o_detections)


def test_uav_setup_detects_the_vehicles_of_held_out_scenes(detector, counts_of):
    """Pooled over four held-out scenes (a scene at this altitude shows only a few vehicles at a time).
    Below issue 12's targets (see docs/uav_camera.md): the bounds say the set-up finds half the vehicles and is not
    drowned in false alarms, with margin under what bench/uav_detector.py measures; and that it beats
    the previous upright-window set-up side by side on both rates."""
    counts = counts_of(detector)
    vehicles, detections, true = counts.sum(axis=0)
    assert vehicles >= 20, counts
    assert true / vehicles >= MIN_DETECTION, counts
    assert 1 - true / max(detections, 1) <= MAX_FALSE_ALARMS, counts
    upright = counts_of(Detector(DetectorConfig(**UPRIGHT)))
    u_vehicles, u_detections, u_true = upright.sum(axis=0)
    assert true / vehicles >= u_true / u_vehicles + 0.08, (counts, upright)
    assert 1 - true / max(detections, 1) <= 1 - u_true / max(u_detections, 1) - 0.1, (counts, upright)


def test_the_colour_verifier_halves_the_cascades_false_alarms_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: the verifier removes false groups (canopy, smoke) the window
    count cannot tell from vehicles, without losing detections (measured 0.19 against 0.38 false alarms,
    0.52 against 0.49 detection)."""
    cascade_only = Detector(dataclasses.replace(detector.config, **CASCADE_ONLY))
    assert detector.needs_colour and not cascade_only.needs_colour
    vehicles, detections, true = counts_of(detector).sum(axis=0)
    c_vehicles, c_detections, c_true = counts_of(cascade_only).sum(axis=0)
    assert 1 - true / max(detections, 1) <= 1 - c_true / max(c_detections, 1) - 0.1
    assert true / vehicles >= c_true / c_vehicles - 0.05


def test_the_box_regressor_finds_more_vehicles_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: the box regressor moves groups that lie on a vehicle at IoU
    0.3-0.5 onto it, so more vehicles are found without more false alarms (measured 0.64 against 0.52
    detection, 0.14 against 0.19 false alarms)."""
    before = Detector(dataclasses.replace(detector.config, **VERIFIER_ONLY))
    after = Detector(dataclasses.replace(detector.config, **BEFORE_BLOBS))      # the same scan's windows
    assert after.box_regressor is not None and before.box_regressor is None
    assert_side_by_side(counts_of, after, before, gain=0.05, slack=0.03)


def test_the_tree_verifier_finds_more_vehicles_at_fewer_false_alarms_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: boosted trees on the refined box's colour against the
    logistic verifier on the mean box's colour (on these four scenes measured 0.72 / 0.16 against 0.64 / 0.14:
    17 more of 192 vehicles at about the same false alarms; on bench/uav_detector.py's 13 held-out scenes
    0.69 / 0.15 against 0.58 / 0.18). Both with the member-statistics box regressor (the image stages came after)."""
    logistic = Detector(dataclasses.replace(detector.config, **LOGISTIC))
    trees = Detector(dataclasses.replace(detector.config, **MEMBER_BOXES))
    assert_side_by_side(counts_of, trees, logistic, gain=0.04, slack=0.06)


def test_the_image_stages_cut_the_false_alarms_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: the box regressor's image stages (issue 12 session 13) move
    published groups off a vehicle's edge onto it or onto a partly hidden (ignored) vehicle, so fewer detections lie
    off every vehicle, and about as many vehicles are found (measured 128 of 192 vehicles in 142 detections,
    false alarms 0.10, against 130 in 153, 0.15; bench/uav_tracking.py's 12 held-out scenes: 0.685 / 0.085 against
    0.688 / 0.140, and tracking MOTA 0.485 against 0.415)."""
    members = Detector(dataclasses.replace(detector.config, **MEMBER_BOXES))
    stages = Detector(dataclasses.replace(detector.config, **BEFORE_BLOBS))     # the same scan's windows
    assert stages.box_regressor.image_stages and not members.box_regressor.image_stages
    assert_side_by_side(counts_of, stages, members, gain=-0.03, slack=-0.025)


def test_the_colour_blobs_views_find_more_vehicles_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: the windows of each colour blob's own view (issue 12 session 33)
    give groups on vehicles the fixed-heading scan gathers too few windows on, with the turned views cropped to pay
    for them. Measured with the windows grouped by their upright boxes, the grouping then (on these four scenes 137
    of 192 vehicles in 153 detections, false alarms 0.105, against 128 in 142, 0.099; with the whole turned canvases
    138 in 149; bench/uav_tracking.py's 12 held-out scenes: see docs/uav_camera.md). Grouped by the windows' turned
    rectangles (session 39, the set-up's) the scan without the blobs finds as many here (137 against the set-up's
    138): that grouping parts the neighbours the blobs' views had found for it. Across the tuning scenes the blobs
    still carry the set-up's MOTA (0.631 against 0.587 without them, 7 of 8 seeds; docs/uav_camera.md), so here they
    need only find as many within noise."""
    assert detector.config.blob_views and detector.config.group_shape == "turned"
    measured = Detector(dataclasses.replace(detector.config, **BEFORE_PATCH_NET))     # the set-up it was measured in
    upright = Detector(dataclasses.replace(detector.config, **UPRIGHT_GROUPS))
    for with_blobs, grouped_as_then in ((measured, False), (upright, True)):
        before = Detector(dataclasses.replace(detector.config, **{**BEFORE_BLOBS,
                                                                  "group_shape": with_blobs.config.group_shape}))
        assert not before.config.blob_views and before.config.group_shape == with_blobs.config.group_shape
        assert_side_by_side(counts_of, with_blobs, before, gain=0.025 if grouped_as_then else -0.02, slack=0.03,
                            context=(with_blobs.config.group_shape,))


def test_the_blob_views_scanned_in_one_atlas_give_each_views_own_windows(detector, held_out_frames):
    """scan_canvases (every blob view's level side by side in one scan) gives each view the windows and scores
    scan_level gives it alone, at the blob views' stride and at the set-up's, for the set-up's cascade and for its
    first stage read as fused, LBP-only and contour-only features with every window passing (so that each window's
    score shows its features); a view too small for a window gets none."""
    from multi_target_tracker import blob_views
    from multi_target_tracker.detector import scan_canvases, scan_level

    image = held_out_frames[HELD_OUT[0]][2][0]
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    canvases = [(canvas, scale) for canvas, scale, _ in detector.blob_canvases(image, gray)]
    canvases.append((gray[:20, :30], 1.0))                               # holds no window at any scale
    assert len(canvases) > 10
    cascade = detector.cascade
    # the same stumps, each read as the half's own kind of feature (LBP bins 0..1023, potentials 1024..1151)
    first = cascade.stages[0]
    as_lbp = dataclasses.replace(first, features=np.where(first.features < 1024, first.features, first.features - 1024))
    as_contour = dataclasses.replace(first, features=np.where(first.features >= 1024, first.features,
                                                              1024 + first.features % 128))
    every_window = -1e9                          # a one-stage cascade's last-stage margin that passes every window
    models = [(cascade, detector.config.window_margin),
              (Cascade(cascade.window, "fused", cascade.edge_threshold, [first]), every_window),
              (Cascade(cascade.window, "lbp", cascade.edge_threshold, [as_lbp]), every_window),
              (Cascade(cascade.window, "contour", cascade.edge_threshold, [as_contour]), every_window)]
    windows = 0
    for model, margin in models:
        for stride in (blob_views.STRIDE, 8):
            together = scan_canvases(canvases, model, stride, margin)
            for (canvas, scale), (boxes, scores) in zip(canvases, together):
                alone_boxes, alone_scores, _ = scan_level(canvas, model, scale, stride, margin)
                assert np.array_equal(boxes, alone_boxes) and np.array_equal(scores, alone_scores)
                windows += len(boxes)
            assert len(together[-1][0]) == 0
    assert windows > 100                        # the comparison is not between empty lists


def test_grouping_by_turned_rectangles_keeps_the_detections_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: the windows grouped by their own turned rectangles (the set-up's,
    session 39) against their upright boxes. On bench/uav_tracking.py's 12 held-out scenes it lifts MOTA (0.531
    against 0.512, 8 scenes better, 3 worse); on these four the detector alone moves by a vehicle or two (measured
    138 of 192 vehicles in 149 detections, false alarms 0.074, against 137 in 153, 0.105), so this checks that it
    finds as many vehicles within noise at no more false alarms."""
    turned = Detector(dataclasses.replace(detector.config, **BEFORE_PATCH_NET))       # the set-up it was measured in
    upright = Detector(dataclasses.replace(detector.config, **UPRIGHT_GROUPS))
    assert turned.config.group_shape == "turned" and upright.config.group_shape == "upright"
    assert_side_by_side(counts_of, turned, upright, gain=-0.02, slack=0.02)


def test_the_patch_network_finds_more_vehicles_at_fewer_false_alarms_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: the patch network (session 43) reads each group's colour patch, adds
    its log odds to the tree verifier's and places the box, against the set-up before it (the box regressor's image
    stages, the trees alone, no containment exemption; ``UAV_BEFORE_PATCH_NET``). Measured on these four scenes with
    session 43's network 148 of 192 vehicles in 162 detections (false alarms 0.086) against 138 in 149 (0.074); with
    session 45's (trained on 150 scenes, with the containment exemption) 164 in 183 (0.104); on bench/uav_tracking.py's
    12 held-out scenes 0.877 / 0.074 (session 43's: 0.825 / 0.098) against 0.768 / 0.118 (every 4th frame), tracking
    MOTA 0.653 (0.590) against 0.538."""
    before = Detector(dataclasses.replace(detector.config, **BEFORE_PATCH_NET))
    assert detector.patch_net is not None and before.patch_net is None and before.box_regressor.image_stages
    assert_side_by_side(counts_of, detector, before, gain=0.025, slack=0.03)


def test_the_containment_exemption_finds_vehicles_that_overlap_on_held_out_scenes(detector, counts_of):
    """Side by side on the same held-out scenes: groups the verifier and network are sure of (log odds >= 7) kept beside
    a better detection they lie half inside (session 45), against containment for all, the same network. Measured on
    these four scenes with the scan of sessions 45-47 (``UAV_BEFORE_SPEED``) 164 of 192 vehicles in 183 detections
    (false alarms 0.104) against 149 in 161 (0.075); on bench/uav_tracking.py's tuning seeds MOTA 0.773 against 0.755
    (docs/uav_camera.md). With session 48's coarser scan and single-window groups the set-up finds 164 against 160 here
    (tuning MOTA 0.786 against 0.777): the exemption still finds more, by less."""
    assert detector.config.containment_exempt_log_odds < NEVER_EXEMPT
    earlier = Detector(dataclasses.replace(detector.config, **BEFORE_SPEED))
    for exempt in (earlier, detector):
        without = Detector(dataclasses.replace(exempt.config, containment_exempt_log_odds=NEVER_EXEMPT,
                                               suppression_iou=1.0))
        assert_side_by_side(counts_of, exempt, without, gain=0.04 if exempt is earlier else 0.0, slack=0.06)


def test_low_confidence_band_adds_flagged_groups_and_leaves_the_detections_unchanged(detector, held_out_frames):
    """Groups the verifier scores within the band below its threshold are published flagged (their score, the
    verifier's probability, below the threshold's); the detections proper are the same with or without the band."""
    band = 6.0        # wide: with the patch network the summed log odds seldom fall just below the threshold
    without = Detector(dataclasses.replace(detector.config, low_confidence_band=0.0))
    banded = Detector(dataclasses.replace(detector.config, low_confidence_band=band))
    threshold = detector.config.verifier_threshold
    flagged = 0
    for image, _ in held_out_frames[HELD_OUT[0]][::2]:                     # every 16th frame
        plain, table = without.detect(image), banded.detect(image)
        assert LOW_CONFIDENCE not in plain.dtype.names and LOW_CONFIDENCE in table.dtype.names
        low = table[LOW_CONFIDENCE] == 1
        high = table[~low][list(plain.dtype.names)]
        assert high.tolist() == plain.tolist()
        logit = np.log(table["score"] / (1 - table["score"]))
        assert (logit[low] < threshold + 1e-4).all() and (logit[low] >= threshold - band - 1e-4).all()
        flagged += int(low.sum())
    assert flagged > 0


def test_the_verified_detections_go_through_the_suppression_iou(detector, held_out_frames):
    """The set-up's verified path (colour verifier, patch network) applies ``suppression_iou`` too: at IoU 0 one row
    is left of a frame with several."""
    image = next(image for image, _ in held_out_frames[HELD_OUT[0]] if len(detector.detect(image)) >= 2)
    assert len(Detector(dataclasses.replace(detector.config, suppression_iou=0.0)).detect(image)) == 1


def test_the_verified_detections_exempt_the_confident_groups_from_containment(detector, held_out_frames):
    """``containment_exempt_log_odds`` reaches the verified path: at -50 every accepted group is exempt, which is
    containment 1 (off); at 50 (never) containment drops some of them."""
    images = [image for image, _ in held_out_frames[HELD_OUT[0]]][:6]
    every = Detector(dataclasses.replace(detector.config, containment_exempt_log_odds=-50.0))
    off = Detector(dataclasses.replace(detector.config, containment=1.0))
    never = Detector(dataclasses.replace(detector.config, containment_exempt_log_odds=NEVER_EXEMPT))
    assert detector.config.containment < 1.0
    more = 0
    for image in images:
        exempt, without = every.detect(image), off.detect(image)
        assert np.array_equal(exempt, without)
        more += len(exempt) - len(never.detect(image))
    assert more > 0


def test_the_patch_net_floor_rejects_only_groups_below_it_without_the_network(detector, held_out_frames):
    """``patch_net_floor``: a group whose verifier log odds lie below it is never shown to the patch network (it keeps
    the verifier's log odds and member-statistics box, so it is rejected); every other group gets what it gets without
    the floor. -50 (the default) shows the network every group."""
    cfg = dataclasses.replace(detector.config, low_confidence_band=0.0)
    trees = Detector(dataclasses.replace(cfg, patch_net="", patch_net_floor=EVERY_GROUP))
    every = Detector(dataclasses.replace(cfg, patch_net_floor=EVERY_GROUP))
    floor = 0.0                                       # between the set-up's -4 and its threshold: many on each side
    floored = Detector(dataclasses.replace(cfg, patch_net_floor=floor))
    below = above = 0
    for image, _ in held_out_frames[HELD_OUT[0]][:4]:
        windows = every.raw(image)
        (plain_boxes, plain), (all_boxes, summed), (boxes, logit) = (
            d.candidates(image, windows, cfg.window_margin) for d in (trees, every, floored))
        low = plain < floor
        assert np.array_equal(logit[low], plain[low]) and np.array_equal(boxes[low], plain_boxes[low])
        assert np.allclose(logit[~low], summed[~low], atol=1e-4) and np.allclose(boxes[~low], all_boxes[~low], atol=1e-3)
        assert (logit[low] < cfg.verifier_threshold).all()
        below, above = below + int(low.sum()), above + int((~low).sum())
    assert below > 0 and above > 0
    with pytest.raises(ConfigError, match="patch_net_floor"):
        validate(dataclasses.replace(cfg, patch_net_floor=cfg.verifier_threshold + 0.5))
    with pytest.raises(ConfigError, match="patch_net_floor"):
        validate(DetectorConfig(patch_net_floor=-5.0))


def test_low_confidence_band_needs_a_verifier():
    with pytest.raises(ConfigError):
        validate(DetectorConfig(low_confidence_band=1.0))
    with pytest.raises(ConfigError, match="containment_exempt_log_odds"):
        validate(DetectorConfig(containment_exempt_log_odds=5.0))


def test_training_tools_build_the_setups_cascade_alone():
    """tools/train_uav_verifier.py and train_uav_box_regressor.py scan with the set-up's cascade without its verifier
    (``cascade_detector``); the set-up's ``low_confidence_band`` needs a verifier, so the band is dropped with it
    (session 11's band broke both tools: ConfigError before any scan)."""
    import sys
    from pathlib import Path
    tools = str(Path(__file__).resolve().parent.parent / "tools")      # the checkout's tools (not installed)
    sys.path.insert(0, tools)
    try:
        from train_uav_verifier import cascade_detector
    finally:
        sys.path.remove(tools)
    assert load_yaml_parameters(SETUP, "detector")["low_confidence_band"] > 0
    det = cascade_detector({"box_scale": 1.0})
    assert det.verifier is None and det.box_regressor is None and det.config.low_confidence_band == 0
    assert det.config.border == load_yaml_parameters(SETUP, "detector")["border"]
    # and scan as when the shipped verifier and box regressor were trained: before the colour blobs' views
    assert not det.config.blob_views and det.config.turned_crop == 0
    assert det.config.scale_factor == BEFORE_BLOBS["scale_factor"]


def test_training_tools_take_overrides_of_the_setup():
    """``--set KEY=JSON`` reaches every scan of the training tools, after the tool's own settings (so another cascade's
    second stages can be trained without editing config/uav_camera.yaml); malformed items stop with a clear message."""
    import sys
    from pathlib import Path
    tools = str(Path(__file__).resolve().parent.parent / "tools")
    sys.path.insert(0, tools)
    try:
        from train_uav_verifier import cascade_detector, parse_overrides, setup_detector, setup_verifier
    finally:
        sys.path.remove(tools)
    overrides = parse_overrides(['model="uav_vehicles_heading.json"', "group_shape=\"turned\"", "min_neighbors=5"])
    assert overrides == {"model": "uav_vehicles_heading.json", "group_shape": "turned", "min_neighbors": 5}
    det = cascade_detector(overrides)
    assert Path(det.config.model).name == "uav_vehicles_heading.json" and det.verifier is None
    assert det.config.group_shape == "turned" and det.config.min_neighbors == 5   # the override wins over the tool's
    assert setup_detector(overrides).verifier is not None          # the whole set-up keeps its verifier
    # the set-up's tree verifier, or the logistic one named instead
    assert type(setup_verifier()).__name__ == "TreeVerifier"
    assert type(setup_verifier({"verifier": "uav_vehicles_verifier.json"})).__name__ == "Verifier"
    for bad in (["model"], ["min_neighbors=three"], ["min_neighbours=3"]):
        with pytest.raises(SystemExit, match="--set"):
            parse_overrides(bad)
