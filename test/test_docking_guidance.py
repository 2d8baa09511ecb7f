"""Stand calibration and docking guidance cores (issue 15): geometry against the synthetic stand's exact
truth, the fusion of the two ranges, the display states, and clear errors for bad stand files."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from aircraft_docking_tracker.config import ConfigError
from aircraft_docking_tracker.docking.guidance import (LOST, NO_AIRCRAFT, OVERSHOOT, SLOW_DOWN, STOP, TRACKING,
                                                       DockingGuidance, GuidanceConfig, along_line, locate_nose,
                                                       template_point)
from aircraft_docking_tracker.docking.nose_gear import NOSE_GEAR_DTYPE
from aircraft_docking_tracker.docking.stand import focal_from_homography, load_stand, parse_stand
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig, apply_affine, template_corners
from aircraft_docking_tracker.scenarios.render import frame_stamp_ns

NS = 1_000_000_000


@pytest.fixture(scope="module")
def scene():
    """600 frames at 14 Hz: about 3 m/s 15 m out, as an aircraft closes (80 frames would be 30 m/s)."""
    return DockingScene(DockingSceneConfig(frames=600, lateral_offset_m=1.0, camera_height_m=8.0,
                                           camera_distance_m=50.0), seed=7)


@pytest.fixture(scope="module")
def frames(scene):
    """(true quadrilateral, true guidance, stamp, nose on the apron) per frame, from the scene's poses (the
    images are not needed)."""
    truth = scene.guidance_truth()
    out = []
    for i in range(scene.config.frames):
        affine, nose_ground, _ = scene.pose(i)
        out.append((apply_affine(affine, template_corners()), truth[i], frame_stamp_ns(i, scene.config.fps),
                    nose_ground))
    return out


def test_calibration_recovers_the_camera_from_clicked_marks(scene):
    stand = parse_stand(scene.stand_calibration(click_sigma_px=0.5))
    truth = scene.camera.position
    assert np.linalg.norm(stand.camera.centre - truth) < 0.5          # 6 marks clicked to 0.5 px, 50 m away
    assert stand.reprojection_px < 1.5
    exact = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
    assert np.linalg.norm(exact.camera.centre - truth) < 0.01          # the marks are written to 0.01 px
    assert exact.camera.project([[3.0, 20.0, 1.0]]) == pytest.approx(scene.camera.project([[3.0, 20.0, 1.0]]),
                                                                     abs=0.02)


def test_focal_length_estimated_from_the_marks_when_not_given(scene):
    data = scene.stand_calibration(click_sigma_px=0.0)
    data["camera"]["focal_px"] = 0
    assert parse_stand(data).camera.focal_px == pytest.approx(scene.camera.f, rel=0.01)
    # a camera square onto the stand's axes (no pitch, no yaw) leaves the focal length free
    assert np.isnan(focal_from_homography(np.diag([500.0, 500.0, 1.0]), (0.0, 0.0)))


def test_survey_error_at_the_stop_is_the_spread_of_clicked_surveys(scene):
    """The clicking error the marks' residuals imply, and the stop mark's error propagated from it, against the
    spread of 200 surveys of the same stand clicked with 0.5 px of error (measured: 0.495 px; predicted 0.95-1.07
    of the realised spread along the line on three stands)."""
    exact = scene.stand_calibration(click_sigma_px=0.0)
    exact_stand = parse_stand(exact)
    stop_pixel = exact_stand.camera.project([[0.0, 0.0, 0.0]])
    rng = np.random.default_rng(0)
    clicked, stops = [], []
    for _ in range(200):
        data = copy.deepcopy(exact)
        for mark in data["camera"]["points"]:
            mark["image"] = (np.array(mark["image"]) + rng.normal(0.0, 0.5, 2)).tolist()
        stand = parse_stand(data)
        clicked.append(stand.click_sigma_px)
        depth = stand.camera.depth_on_plane(stop_pixel, 0.0)
        stops.append(stand.camera.point_at_depth(stop_pixel, depth)[0, :2])
    assert np.mean(clicked) == pytest.approx(0.5, rel=0.1)
    predicted = np.sqrt(np.diag(exact_stand.marks.covariance([0.0, 0.0], 0.5)))
    realised = np.std(stops, axis=0)
    assert predicted[1] == pytest.approx(realised[1], rel=0.3)      # along the line (y): tenths of a metre
    assert predicted[1] > 3 * predicted[0]                          # the camera faces the approach: depth is weak
    assert exact_stand.click_sigma_px < 0.02                        # marks written to 0.01 px
    assert np.sqrt(exact_stand.survey_covariance([0.0, 0.0])[1, 1]) < 0.01


def test_start_up_note_warns_of_a_survey_too_coarse_for_the_stop(scene):
    """The note at start-up: the survey's 95 % error at the stop along and across the line; a warning once it
    takes more than half of the +-0.5 m."""
    import logging  # noqa: PLC0415

    from aircraft_docking_tracker.docking.guidance import SURVEY_WARN_M, survey_note  # noqa: PLC0415

    good = DockingGuidance(parse_stand(scene.stand_calibration(click_sigma_px=0.1)))
    level, text = survey_note(good)
    assert level == logging.INFO and 2 * good.survey_sigma_m[0] < SURVEY_WARN_M
    assert "along the lead-in line" in text and "px a click" in text
    coarse = DockingGuidance(parse_stand(scene.stand_calibration(click_sigma_px=2.0)))
    level, text = survey_note(coarse)
    assert level == logging.WARNING and 2 * coarse.survey_sigma_m[0] > SURVEY_WARN_M
    assert "Add marks near the stop" in text


def test_pilot_sees_positive_lateral_to_his_right():
    line = np.array([[0.0, 50.0], [0.0, 0.0], [0.0, -10.0]])   # driving towards -y, the camera's way
    arc, lateral = along_line(line, [-0.4, 20.0])                # the camera's left is the pilot's right
    assert arc == pytest.approx(30.0) and lateral == pytest.approx(0.4)
    arc, lateral = along_line(line, [0.2, -15.0])                # past the end: the last segment extended
    assert arc == pytest.approx(65.0) and lateral == pytest.approx(-0.2)


def test_true_quadrilaterals_give_the_true_guidance(scene, frames):
    """Fed the exact quadrilaterals (and told their size is good to 1 %), the geometry alone errs by what the
    0.5 px clicks leave (0.17 m here)."""
    guidance = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(size_sigma=0.01))
    errors = []
    for quad, truth, _, nose_ground in frames:
        result, sigma, lateral_sigma = guidance.measure(quad)
        assert sigma > 0 and lateral_sigma > 0
        if truth[0] <= 15.0:
            errors.append([result.distance_m - truth[0], result.lateral_m - truth[1]])
            assert result.nose_stand[:2] == pytest.approx(nose_ground, abs=0.25)
    errors = np.abs(np.array(errors))
    assert len(errors) > 15
    assert errors[:, 0].max() < 0.25 and errors[:, 1].max() < 0.1


def test_fusion_leans_on_the_range_that_holds(scene, frames):
    """A 10 % size error at 50 m moves the size range by metres; the fused depth follows the ground plane
    more when the pixel error is small, and the size more when the pixels are not trusted."""
    stand = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
    aircraft = stand.aircraft_type("synthetic_a320")
    quad = frames[-1][0]
    centre = template_point(quad, aircraft.nose_in_template)
    shrunk = centre + (quad - centre) / 1.1                       # the same nose, a template 10 % too small
    _, _, ground, size, _ = locate_nose(stand, aircraft, shrunk, 1.0, 0.03)
    true_depth = scene.camera.depth([[*frames[-1][3], aircraft.nose_height_m]])[0]
    assert ground == pytest.approx(true_depth, rel=0.01) and size == pytest.approx(1.1 * true_depth, rel=0.01)
    trust_pixels = locate_nose(stand, aircraft, shrunk, 0.2, 0.03)[1]
    trust_size = locate_nose(stand, aircraft, shrunk, 20.0, 0.03)[1]
    depth = lambda p: float(stand.camera.R[2] @ (p - stand.camera.centre))   # noqa: E731
    assert abs(depth(trust_pixels) - true_depth) < 0.3 * abs(depth(trust_size) - true_depth)


def test_states_through_an_approach(scene, frames):
    guidance = DockingGuidance(parse_stand(scene.stand_calibration()))
    assert guidance.update(None, False, False, 0).state == NO_AIRCRAFT
    states, firsts = [], {}
    for i, (quad, truth, stamp, _) in enumerate(frames):
        r = guidance.update(quad, True, False, stamp)
        states.append(r.state)
        firsts.setdefault(r.state, truth[0])
        assert np.isfinite([r.distance_m, r.lateral_m, r.speed_mps]).all()
    assert states[0] == TRACKING and states[-1] == STOP
    assert 14.5 <= firsts[SLOW_DOWN] <= 16.0                        # slow down shown at 15 m (the smoothing's lag)
    assert -0.5 <= firsts[STOP] <= 0.5                              # STOP neither late nor early
    assert OVERSHOOT not in states                                  # braking to the mark is not "too far"
    # order on the way in: tracking, slow down, STOP; never back out to tracking
    assert np.all(np.diff([{TRACKING: 0, SLOW_DOWN: 1, STOP: 2}[s] for s in states]) >= 0)


def test_speed_is_the_closing_speed(scene, frames):
    guidance = DockingGuidance(parse_stand(scene.stand_calibration(click_sigma_px=0.0)))
    speeds = [(guidance.update(q, True, False, s).speed_mps, t[2]) for q, t, s, _ in frames]
    measured, truth = np.array(speeds[5:]).T
    assert np.median(np.abs(measured - truth)) < 0.05 * truth.max()
    assert abs(measured[-1]) < 0.1                                  # standing at the stop


def test_overshoot_lost_and_time_jump(scene, frames):
    stand = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
    guidance = DockingGuidance(stand)
    quad = frames[-1][0]
    past = quad + np.array([0.0, 0.0]) + (quad - quad.mean(axis=0)) * 0.08      # 8 % larger: metres nearer
    for k in range(20):                                           # standing there from the start: no approach
        assert guidance.update(past, True, False, k * NS // 14).state == SLOW_DOWN
    guidance.reset()
    for quad_k, _, stamp, _ in frames[400:]:                      # an approach, then 8 % larger
        guidance.update(quad_k, True, False, stamp)
    for k in range(20):
        state = guidance.update(past, True, False, frames[-1][2] + (k + 1) * NS // 14).state
    assert state == OVERSHOOT
    lost = guidance.update(past, False, True, frames[-1][2] + 21 * NS // 14)
    assert lost.state == LOST and np.isnan(lost.distance_m)
    guidance.update(quad, True, False, 22 * NS // 14)
    guidance.update(quad, True, False, 10 * NS)                  # a 9 s gap: the smoothing restarts
    guidance.update(quad, True, False, 5 * NS)                   # a stamp going back: again
    assert guidance.restarts == 2


def test_broken_stand_files_say_what_is_wrong(scene, tmp_path):
    good = scene.stand_calibration()
    cases = [
        (lambda d: d["camera"].update(points=d["camera"]["points"][:3]), "at least 4 apron marks"),
        (lambda d: d["camera"]["points"][1].update(stand=[float("nan"), 0.0]), "camera.points[1].stand"),
        (lambda d: [p.update(stand=[0.0, float(i)]) for i, p in enumerate(d["camera"]["points"])], "on one line"),
        (lambda d: d.update(lead_in=[[0.0, 1.0]]), "lead_in"),
        (lambda d: d["aircraft"]["synthetic_a320"].update(height_m=-3), "aircraft.synthetic_a320.height_m"),
        (lambda d: d["aircraft"]["synthetic_a320"].update(nose_in_template=[0.5, 1.5]), "nose_in_template"),
        (lambda d: d["camera"].update(focal_px="wide"), "camera.focal_px"),
        (lambda d: d["aircraft"]["synthetic_a320"].update(nose_gear_setback_m=-1), "nose_gear_setback_m"),
    ]
    for breaks, message in cases:
        data = copy.deepcopy(good)
        breaks(data)
        with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
            parse_stand(data)
    with pytest.raises(ConfigError, match="no aircraft type 'B777'"):
        DockingGuidance(parse_stand(good), GuidanceConfig(aircraft_type="B777"))
    with pytest.raises(ConfigError, match="not YAML"):
        (tmp_path / "bad.yaml").write_text("camera: [unclosed\n")
        load_stand(tmp_path / "bad.yaml")
    with pytest.raises(ConfigError, match="No such file"):
        load_stand(tmp_path / "missing.yaml")


def test_shipped_stand_file_loads():
    stand = load_stand("demo_stand.yaml")
    assert stand.reprojection_px < 1.5 and "synthetic_a320" in stand.aircraft


# --------------------------------------------------------------------------- the nose wheel's ground contact
def _perturbed(quad: np.ndarray, shift: float, angle_deg: float, scale: float) -> np.ndarray:
    """The quadrilateral moved sideways by ``shift`` of its height, turned and scaled about its centre: the
    errors a tracked quadrilateral carries late in an approach (measured: 0.35 of the height sideways, 20 deg)."""
    centre = quad.mean(axis=0)
    a = np.radians(angle_deg)
    turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    height = np.linalg.norm(quad[3] - quad[0])
    return centre + (quad - centre) @ turn.T * scale + (shift * height, 0.0)


@pytest.fixture(scope="module")
def stop_frames():
    """Frames near the stop of three stands (clear, rain, low sun; 60 frames each, rendered)."""
    out = []
    for seed, weather in ((21, "clear"), (22, "rain"), (23, "low_sun")):
        scene = DockingScene(DockingSceneConfig(frames=60, weather=weather, occluder="none", lateral_offset_m=1.0,
                                                camera_height_m=6.0, camera_distance_m=45.0), seed=seed)
        stand = parse_stand(scene.stand_calibration())
        out += [(scene, stand, f) for f in scene.frames() if f.index in (45, 52, 59)]
    return out


def test_nose_wheel_found_despite_a_quadrilateral_off_by_a_third(stop_frames):
    """The symmetry axis and the tyre's edge are measured to a pixel from quadrilaterals a third of their
    height to the side, turned 12 degrees and 6 % too large; the guidance from them errs by a fraction of what
    the quadrilateral alone gives."""
    with_gear, quad_only = [], []
    for k, (scene, stand, frame) in enumerate(stop_frames):
        guidance = DockingGuidance(stand)
        quad = _perturbed(frame.quad, (-1) ** k * 0.33, (-1) ** (k // 2) * 12.0, 1.06)
        gear = guidance.measure_gear(frame.image, quad)
        contact = scene.camera.project([[*frame.nose_ground, 0.0]])[0]
        assert gear["symmetry"][0] > 0.8
        assert abs(gear["axis_x"][0] - frame.nose[0]) < 1.0
        assert np.hypot(gear["ground_x"][0] - contact[0], gear["ground_y"][0] - contact[1]) < 1.5
        result = guidance.measure(quad, gear)[0]
        assert result.gear_measured
        with_gear.append([result.distance_m - frame.guidance[0], result.lateral_m - frame.guidance[1]])
        alone = guidance.measure(quad)[0]
        quad_only.append([alone.distance_m - frame.guidance[0], alone.lateral_m - frame.guidance[1]])
    with_gear, quad_only = np.abs(with_gear), np.abs(quad_only)
    assert with_gear[:, 1].max() < 0.15 and quad_only[:, 1].min() > 1.0
    assert with_gear[:, 0].max() < 0.8 and np.median(quad_only[:, 0]) > 2 * np.median(with_gear[:, 0])


def test_an_engine_as_symmetric_as_the_nose_gives_way_to_the_axis_with_the_tyre():
    """Held-out approach 209's stand (clear, a vehicle and the jet bridge, the camera 5.3 m high and 49 m out), its
    quadrilateral 0.3 of its height to the side, as the tracker had it in the last 15 m: the search's most
    symmetric axis is then an engine's (140-170 px off, a step of 10-18 grey levels under it), and with it the
    lateral offset was metres off. Looking at the next symmetric axes too (``gear_axes``), the first with a tyre's
    step (``gear_axis_contrast``) is the nose's, within a pixel; where the most symmetric axis is the nose's,
    nothing changes."""
    scene = DockingScene(DockingSceneConfig(frames=60, weather="clear", occluder="both", growth=5.33, turn_deg=25.7,
                                            difficulty=2, camera_height_m=5.3, camera_distance_m=49.1,
                                            lateral_offset_m=1.0), seed=209)
    stand = parse_stand(scene.stand_calibration())
    alone = DockingGuidance(stand, GuidanceConfig(gear_axes=1))
    axes = DockingGuidance(stand, GuidanceConfig(gear_axes=3))
    engine = 0
    for frame in scene.frames():
        if frame.index < 46 or frame.index % 2:
            continue
        quad = _perturbed(frame.quad, -0.3, 0.0, 1.0)
        first, looked = alone.measure_gear(frame.image, quad), axes.measure_gear(frame.image, quad)
        assert abs(looked["axis_x"][0] - frame.nose[0]) < 1.0 and looked["contrast"][0] > 60
        engine += abs(first["axis_x"][0] - frame.nose[0]) > 50
        centred = _perturbed(frame.quad, 0.2, 0.0, 1.0)
        assert alone.measure_gear(frame.image, centred).tolist() == axes.measure_gear(frame.image, centred).tolist()
    assert engine >= 5                                 # measured: 7 of 7 frames on the engine


def test_a_quadrilateral_a_fifth_too_small_still_finds_the_tyre_not_the_step_above_it():
    """Tuning approach 114's stand (low sun, the camera 8.8 m high and 48.6 m out), its quadrilateral 0.78 of its size
    and a third of its height to the side, as the tracker had it all the way in (0.78-0.81): the template then puts the tyre's
    row a window too high, and the old search (0.12 template heights, the largest step) took a strong step 30-40 px
    above the tyre on every frame (the guidance read 53-55 m there). The contact's search is wider
    (``gear_contact_window``) and takes the lowest step near the largest (``gear_lowest_step``): the tyre's, within
    a pixel; on the true quadrilateral nothing moves."""
    scene = DockingScene(DockingSceneConfig(frames=60, weather="low_sun", occluder="none", growth=5.18, turn_deg=22.2,
                                            difficulty=2, camera_height_m=8.8, camera_distance_m=48.6,
                                            lateral_offset_m=1.0), seed=114)
    stand = parse_stand(scene.stand_calibration())
    before = DockingGuidance(stand, GuidanceConfig(gear_contact_window=0.12, gear_lowest_step=0.0))
    now = DockingGuidance(stand)
    above, found = 0, 0
    for frame in scene.frames():
        if frame.index < 36 or frame.index % 2:
            continue
        contact = scene.camera.project([[*frame.nose_ground, 0.0]])[0]
        quad = _perturbed(frame.quad, -0.33, 0.0, 0.78)
        old, new = before.measure_gear(frame.image, quad), now.measure_gear(frame.image, quad)
        above += old["ground_y"][0] < contact[1] - 15.0
        found += abs(new["ground_y"][0] - contact[1]) < 1.5
        assert abs(now.measure_gear(frame.image, frame.quad)["ground_y"][0] - contact[1]) < 1.5
    assert above >= 10 and found >= 9                  # of 12 frames (measured: 12 and 11)


def test_ground_contact_is_the_tyres_edge_with_a_joint_line_right_under_it():
    """A grey profile down the axis as measured on a bench stand (415, 12.3 m to go): the tyre (44) ends after
    row 7, a slab joint (114, 118) runs right under it, then the apron (140-150). The step's bands smear the edge
    over two rows and their best row lies under the joint; the contact is the tyre's edge, the larger jump."""
    from aircraft_docking_tracker.docking.nose_gear import ground_contact, tyre_steps

    joint = np.array([108, 52, 44, 44, 45, 45, 45, 44, 114, 118, 140, 150, 150, 149, 144, 121, 150, 150, 150], float)
    assert int(np.argmax(tyre_steps(joint, 5, 2)[2:15])) + 2 == 9          # the step alone: two rows low
    contact, step = ground_contact(joint, 2, 14, 5, 2)
    assert abs(contact - 7.5) < 0.2 and step > 60
    clean = np.where(np.arange(len(joint)) < 8, joint, 150.0)
    assert abs(ground_contact(clean, 2, 14, 5, 2)[0] - 7.5) < 0.1
    stop_bar = clean.copy()
    stop_bar[8:11] = 230.0                             # a painted stop bar under the tyre: the edge stays the tyre's
    assert abs(ground_contact(stop_bar, 2, 14, 5, 2)[0] - 7.5) < 0.2
    # a stronger step above the tyre (a dark band with lit skin under it): the largest step takes it, the lowest
    # peak of at least 0.75 of it is the tyre's
    above_it = np.array([150, 40, 40, 40, 40, 40, 150, 150, 150, 150, 150, 50, 50, 50, 50, 50, 140, 140, 140, 140, 140,
                         140], float)
    assert abs(ground_contact(above_it, 3, 18, 4, 2)[0] - 5.5) < 0.3
    assert abs(ground_contact(above_it, 3, 18, 4, 2, lowest=0.75)[0] - 15.5) < 0.3


def test_nose_wheel_measured_alike_in_colour_and_in_grey(stop_frames):
    """Only the strip's pixels of a colour frame are turned grey: the measurement is the whole grey frame's."""
    import cv2

    for k, (_, stand, frame) in enumerate(stop_frames):
        guidance = DockingGuidance(stand)
        quad = _perturbed(frame.quad, (-1) ** k * 0.2, 5.0, 1.03)
        colour = guidance.measure_gear(frame.image, quad)
        grey = guidance.measure_gear(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), quad)
        assert np.isfinite(colour["ground_y"]).all()
        assert np.allclose(colour.tolist(), grey.tolist(), rtol=0.0, atol=1e-9)


def test_nose_wheel_not_measured_where_it_cannot_be(stop_frames):
    scene, stand, frame = stop_frames[-1]
    guidance = DockingGuidance(stand)
    small = frame.quad.mean(axis=0) + (frame.quad - frame.quad.mean(axis=0)) * 0.2     # under 80 px tall
    assert np.isnan(guidance.measure_gear(frame.image, small)["ground_y"]).all()
    off_image = frame.quad + (600.0, 0.0)
    assert np.isnan(guidance.measure_gear(frame.image, off_image)["ground_y"]).all()
    flat = np.full_like(frame.image, 128)                                              # nothing to see
    assert np.isnan(guidance.measure_gear(flat, frame.quad)["ground_y"]).all()
    never = DockingGuidance(stand, GuidanceConfig(gear_min_height_px=0.0))
    assert np.isnan(never.measure_gear(frame.image, frame.quad)["ground_y"]).all()
    assert not never.measure(frame.quad, never.measure_gear(frame.image, frame.quad))[0].gear_measured


def _contact(stand, nose_ground) -> np.ndarray:
    """A nose-wheel row measured exactly where ``nose_ground`` (on the apron) projects."""
    gear = np.full(1, np.nan, NOSE_GEAR_DTYPE)
    gear["axis_x"], gear["axis_y"] = gear["ground_x"], gear["ground_y"] = stand.camera.project([[*nose_ground, 0.0]])[0]
    return gear


def test_nose_gear_setback_puts_the_nose_ahead_of_the_wheel(scene, frames):
    """A wheel measured where a nose 2 m ahead of it would put it: the nose is 2 m nearer the mark."""
    data = scene.stand_calibration(click_sigma_px=0.0)
    stand = parse_stand(data)
    data["aircraft"]["synthetic_a320"]["nose_gear_setback_m"] = 2.0
    setback = parse_stand(data)
    quad, truth, _, nose_ground = frames[300]
    gear = _contact(stand, nose_ground)
    exact = DockingGuidance(stand, GuidanceConfig(size_sigma=1.0)).measure(quad, gear)[0]
    ahead = DockingGuidance(setback, GuidanceConfig(size_sigma=1.0)).measure(quad, gear)[0]
    assert exact.distance_m == pytest.approx(truth[0], abs=0.1)
    assert ahead.distance_m == pytest.approx(truth[0] - 2.0, abs=0.15)


def test_a_contact_far_from_the_size_range_is_refused(scene, frames):
    """A tyre-to-apron step found on the apron 25 px above the wheel lies tens of metres from the size's range
    (about 6 sigmas of it 25 m out): with ``gear_agree_sigma`` it is refused and counted, and the figures fall
    back on the quadrilateral; the true contact is taken even under a quadrilateral 10 % too large."""
    stand = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
    i = int(np.argmin([abs(truth[0] - 25.0) for _, truth, _, _ in frames]))
    quad, truth, _, nose_ground = frames[i]
    gear = _contact(stand, nose_ground)
    on_apron = gear.copy()
    on_apron["ground_y"] -= 25.0
    agree = DockingGuidance(stand, GuidanceConfig(gear_agree_sigma=4.0))
    taken = agree.measure(quad, gear)[0]
    assert taken.gear_measured and not taken.gear_refused and taken.distance_m == pytest.approx(truth[0], abs=0.3)
    large = quad.mean(axis=0) + (quad - quad.mean(axis=0)) * 1.1
    assert agree.measure(large, gear)[0].gear_measured
    refused = agree.measure(quad, on_apron)[0]
    assert refused.gear_refused and not refused.gear_measured
    assert refused.distance_m == pytest.approx(truth[0], abs=3.0)        # the quadrilateral's figure
    blind = DockingGuidance(stand, GuidanceConfig(gear_agree_sigma=0.0)).measure(quad, on_apron)[0]   # all taken
    assert blind.gear_measured and blind.distance_m - truth[0] > 20.0
    agree.update(quad, True, False, 0, on_apron)
    assert agree.gear_refused == 1 and agree.gear_measured == 0


def test_gate_rejects_a_jump_and_restarts_after_a_gap(scene, frames):
    """A quadrilateral that jumps to the stop mark mid-approach is rejected and counted; the figure holds the
    prediction. Rejected for longer than gate_hold_s, the smoothing takes the new figures."""
    guidance = DockingGuidance(parse_stand(scene.stand_calibration()))
    for quad, truth, stamp, _ in frames[:200]:
        guidance.update(quad, True, False, stamp)
    jump = frames[-1][0]                                          # the aircraft "at the stop" 20+ m early
    quad, truth, stamp, _ = frames[200]
    result = guidance.update(jump, True, False, stamp)
    assert not result.measurement_taken and guidance.rejected == 1
    assert result.distance_m == pytest.approx(truth[0], abs=1.0) and result.state != STOP
    for quad, truth, stamp, _ in frames[201:230]:                 # 2 s of a wrong lock
        result = guidance.update(jump, True, False, stamp)
    assert abs(guidance.rejected - scene.config.fps * guidance.config.gate_hold_s) <= 1     # about 1 s of frames
    assert result.measurement_taken and result.distance_m < 1.0
    short = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(gate_hold_s=0.5))
    for quad, truth, stamp, _ in frames[:200]:
        short.update(quad, True, False, stamp)
    for quad, truth, stamp, _ in frames[200:230]:
        short.update(jump, True, False, stamp)
    assert abs(short.rejected - scene.config.fps * 0.5) <= 1 and short.restarts == 0     # not a time jump
    off = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(gate_sigma=0.0))
    for quad, truth, stamp, _ in frames[:200]:
        off.update(quad, True, False, stamp)
    assert off.update(jump, True, False, frames[200][2]).measurement_taken and off.rejected == 0


def test_stop_stays_on_when_the_track_breaks_up_at_the_mark(scene, frames):
    """STOP shown at the end of a followed approach stays on when the quadrilateral then jumps for seconds (the gate
    restarts the smoothing on it, but a restart at the mark follows no approach); losing the aircraft clears it.
    (The quadrilaterals are exact, so their size is trusted to 1 %: the gate then rejects a jump of a few metres.)"""
    guidance = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(size_sigma=0.01))
    for quad, _, stamp, _ in frames:
        state = guidance.update(quad, True, False, stamp).state
    assert state == STOP
    quad, _, stamp, _ = frames[-1]
    broken = quad.mean(axis=0) + (quad - quad.mean(axis=0)) * 0.7          # 30 % smaller: "20 m back"
    states = [guidance.update(broken, True, False, stamp + (k + 1) * NS // 14).state for k in range(40)]
    assert guidance.rejected >= 10 and set(states) == {STOP}
    assert guidance.update(broken, False, True, stamp + 41 * NS // 14).state == LOST
    assert guidance.update(broken, True, False, stamp + 42 * NS // 14).state != STOP


@pytest.mark.parametrize("wheel", [False, True])
def test_figures_hold_at_the_mark_when_the_track_breaks_up(scene, frames, wheel):
    """stop_holds: under STOP a quadrilateral that grows onto the jet bridge (1.6x: the size reads the aircraft
    tens of metres past its mark) or slides 4 m sideways is refused for as long as it lasts -- 5 s here, the gate
    never giving up -- and the figures stay where the aircraft stopped, at rest (speed 0); when the track comes back
    it is taken again. With the nose wheel measured, a frame without it is not taken even when the gate would let
    it through. With the rule off the figures follow the broken track once gate_hold_s is over."""
    def run(**cfg):
        stand = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
        guidance = DockingGuidance(stand, GuidanceConfig(size_sigma=0.01, **cfg))
        for quad, _, stamp, nose_ground in frames:
            result = guidance.update(quad, True, False, stamp, _contact(stand, nose_ground) if wheel else None)
        assert result.state == STOP and abs(result.distance_m) < 0.1
        quad, _, stamp, nose_ground = frames[-1]
        centre, spread = quad.mean(axis=0), quad - quad.mean(axis=0)
        grown = centre + spread * 1.6
        slid = quad + stand.camera.project([[4.0, 0.0, 0.0]])[0] - stand.camera.project([[0.0, 0.0, 0.0]])[0]
        broken = [grown] * 40 + [slid] * 30
        held = [guidance.update(q, True, False, stamp + (k + 1) * NS // 14) for k, q in enumerate(broken)]
        back = guidance.update(quad, True, False, stamp + 71 * NS // 14,
                               _contact(stand, nose_ground) if wheel else None)
        return guidance, held, back

    guidance, held, back = run()
    assert {r.state for r in held} == {STOP} and not any(r.measurement_taken for r in held)
    assert max(abs(r.distance_m) for r in held) < 0.1 and max(abs(r.lateral_m - held[0].lateral_m) for r in held) < 0.05
    assert max(abs(r.speed_mps) for r in held) == 0.0
    assert guidance.held_at_stop == len(held) and guidance.restarts == 0
    assert back.measurement_taken and abs(back.distance_m) < 0.1 and back.state == STOP
    _, loose, _ = run(stop_holds=False)
    assert max(abs(r.distance_m) for r in loose) > 10.0                       # the broken track's figures


def test_a_creep_past_the_mark_after_stop_is_shown_overshoot(scene, frames):
    """stop_holds leaves a slow creep on past the mark to be followed: an aircraft that rolls on at 0.3 m/s, with
    its nose wheel measured, is shown overshoot once it is overshoot_m past, and its figures follow it there."""
    stand = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
    guidance = DockingGuidance(stand, GuidanceConfig(size_sigma=0.01))
    for quad, _, stamp, nose_ground in frames:
        result = guidance.update(quad, True, False, stamp, _contact(stand, nose_ground))
    assert result.state == STOP
    quad, _, stamp, nose_ground = frames[-1]
    heading = np.array([0.0, -1.0])                                           # the line runs on towards -y
    states = []
    for k in range(1, 80):                                                    # 5.6 s at 0.3 m/s: 1.7 m on
        moved = np.asarray(nose_ground[:2], float) + heading * 0.3 * k / 14
        shift = stand.camera.project([[*moved, 0.0]])[0] - stand.camera.project([[*nose_ground[:2], 0.0]])[0]
        result = guidance.update(quad + shift, True, False, stamp + k * NS // 14, _contact(stand, moved))
        states.append(result.state)
    assert OVERSHOOT in states and result.distance_m == pytest.approx(-1.7, abs=0.3)


def test_no_stop_for_a_figure_that_comes_back_through_the_mark(scene, frames):
    """recede_mps: a followed approach shows STOP at the mark; a figure that then runs on past it (overshoot) and
    comes back through the mark at several m/s (a track that jumped onto something else: fresh approach 1009 showed
    STOP 108 m early so) does not show STOP on the way back, slow down stands for it; with the rule off
    (recede_mps 1000) it does. The quadrilaterals are exact and their size trusted to 1 %, as in the test above."""
    def run(**cfg):
        guidance = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(size_sigma=0.01, **cfg))
        for quad, _, stamp, _ in frames:
            state = guidance.update(quad, True, False, stamp).state
        assert state == STOP
        quad, _, stamp, _ = frames[-1]
        centre, spread = quad.mean(axis=0), quad - quad.mean(axis=0)
        scales = np.r_[np.linspace(1.0, 1.25, 30), np.linspace(1.25, 0.85, 30)]   # on past the mark, then back
        results = [guidance.update(centre + spread * k, True, False, stamp + (i + 1) * NS // 14)
                   for i, k in enumerate(scales)]
        back = [r for r in results[30:] if r.distance_m > -0.5]
        return [r.state for r in results], back

    states, back = run()
    assert OVERSHOOT in states[:30] and back and min(r.speed_mps for r in back) < -2.0
    assert STOP not in [r.state for r in back] and SLOW_DOWN in [r.state for r in back]
    states, back = run(recede_mps=1000.0)
    assert STOP in [r.state for r in back]


def test_an_aircraft_standing_at_its_mark_behind_a_long_figure_is_shown_stop(scene, frames):
    """halted_stop_m: a stand whose survey reads the last metres long -- here its stop mark moved on along the line,
    so that the aircraft stands ``long_m`` short of it (fresh approaches 1012 and 1018 read 0.3-0.45 m long from
    half-pixel clicks) -- shows STOP once the aircraft has stood still for halted_s, and not before it stands; with
    the rule off it never does, nor does a figure further from the mark than halted_stop_m."""
    stands = (truth[2] == 0.0 for _, truth, _, _ in frames)
    standing_from = next(i for i, still in enumerate(stands) if still)
    fps = int(scene.config.fps)

    def first_stop(long_m, **cfg):
        stand = scene.stand_calibration(click_sigma_px=0.0)
        stand["aircraft"]["synthetic_a320"]["stop_m"] = [0.0, -long_m]      # the line runs on towards -y
        guidance = DockingGuidance(parse_stand(stand), GuidanceConfig(size_sigma=0.01, **cfg))
        states = [guidance.update(quad, True, False, stamp) for quad, _, stamp, _ in frames]
        assert abs(states[-1].distance_m - long_m) < 0.1                    # the figure at the stand reads long
        first = next((i for i, r in enumerate(states) if r.state == STOP), None)
        assert guidance.halted_stops == (first is not None and long_m > guidance.config.stop_m)   # diagnostics
        return first

    assert first_stop(0.0) < standing_from                                  # a true figure: STOP while it closes
    for long_m in (0.35, 0.45):
        first = first_stop(long_m)
        assert first is not None and first <= standing_from + fps * 2.0
        assert abs(frames[first][1][0]) < 0.05 and abs(frames[first - fps][1][0] - frames[first][1][0]) < 0.1
    assert first_stop(0.35, halted_stop_m=0.0) is None
    assert first_stop(0.8) is None


def _replay(scene, frames, order, **cfg):
    """The guidance over the scene's true quadrilaterals in ``order`` (frame indices, repeats allowed), stamped at
    14 Hz one after another: the guidance and its results."""
    guidance = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(**cfg))
    return guidance, [guidance.update(frames[i][0], True, False, frames[0][2] + k * NS // 14)
                      for k, i in enumerate(order)]


def test_no_stop_for_a_figure_that_leaps_to_the_mark(scene, frames):
    """arrive_mps: a figure that runs the last 8 m to the mark at 5 m/s (a track on something else; fresh approach
    1004 showed STOP 171 m early so) shows no STOP while it closes that fast; STOP comes once it has slowed to
    arrive_mps, the aircraft then standing at the mark. With the rule off (arrive_mps 1000) STOP comes at over
    2 m/s. The quadrilaterals are exact and their size trusted to 1 %, as in the tests above."""
    distances = np.array([truth[0] for _, truth, _, _ in frames])
    start = int(np.argmax(distances < 8.0))
    standing = int(np.argmax(distances <= 0.0))
    leap = [int(np.argmin(np.abs(distances[:standing + 1] - d))) for d in np.arange(8.0, 0.0, -5.0 / 14)]
    order = list(range(start)) + leap + [standing] * 40                 # then 40 frames (3 s) at the mark

    def run(**cfg):
        guidance, results = _replay(scene, frames, order, size_sigma=0.01, **cfg)
        first = next(k for k, r in enumerate(results) if r.state == STOP)
        return first, results[first], guidance.stop_withheld

    first, result, withheld = run()
    assert first >= start + len(leap) and result.speed_mps <= 2.0 and withheld >= 1     # counted for the diagnostics
    first, result, withheld = run(arrive_mps=1000.0)
    assert result.speed_mps > 2.0 and withheld == 0


def test_no_stop_for_a_figure_beside_the_line(scene, frames):
    """stop_lateral_m: the whole approach seen 5 m to the side of the lead-in line (a track on something standing
    or moving beside it: two bench runs showed STOP 19 and 151 m early so, 5.9 and 9.8 m off the line) shows slow
    down at the mark, never STOP, and the withheld STOPs are counted; with the rule off it shows STOP there."""
    camera = scene.camera
    aside = []
    for quad, truth, stamp, nose in frames:
        at, beside = camera.project([[nose[0], nose[1], 0.0], [nose[0] + 5.0, nose[1], 0.0]])
        aside.append((quad + (beside - at), truth, stamp, nose))
    standing = int(np.argmax(np.array([t[0] for _, t, _, _ in frames]) <= 0.0))
    order = list(range(standing + 1)) + [standing] * 40

    guidance, results = _replay(scene, aside, order, size_sigma=0.01)
    assert abs(results[-1].lateral_m) > 4.0 and abs(results[-1].distance_m) < 0.5
    assert all(r.state != STOP for r in results) and results[-1].state == SLOW_DOWN
    assert guidance.stop_withheld >= 10
    guidance, results = _replay(scene, aside, order, size_sigma=0.01, stop_lateral_m=1000.0)
    assert results[-1].state == STOP and guidance.stop_withheld == 0


def test_a_figure_at_the_speed_clamp_follows_no_approach(scene, frames):
    """A figure whose rate reaches max_speed_mps is no aircraft (fresh approach 5019: a track re-acquired on a box
    three times the aircraft's size ran its figure down at the clamp, and STOP was shown 114 m early): the approach
    followed and the time in slow down count again from there. Here the figure leaps from 10 m to the mark (the gate
    off, so that the smoothing takes it) and stands there for 3 s: no STOP. With a clamp it does not reach
    (max_speed_mps 1000), STOP is shown once the figure has settled."""
    distances = np.array([truth[0] for _, truth, _, _ in frames])
    start = int(np.argmax(distances < 10.0))
    order = list(range(start)) + [len(frames) - 1] * 42

    def states(**cfg):
        return _replay(scene, frames, order, size_sigma=0.01, gate_sigma=0.0, **cfg)[1][start:]

    leapt = states()
    assert max(r.speed_mps for r in leapt) >= 12.0 and abs(leapt[-1].distance_m) < 0.3
    assert STOP not in [r.state for r in leapt] and OVERSHOOT not in [r.state for r in leapt]
    assert STOP in [r.state for r in states(max_speed_mps=1000.0)]
