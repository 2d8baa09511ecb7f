"""Static-camera foreground and the extent correction of the docking filter (issue 11)."""
import numpy as np
import pytest

from aircraft_docking_tracker.docking import affine_group as ag
from aircraft_docking_tracker.docking.tracker import DockingConfig, DockingTracker
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
from aircraft_docking_tracker.docking.static_background import (StaticBackground, foreground_extent, row_offsets,
                                                               state_mask, target_motion)

SIZE = (240, 320)


def stand(rng):
    """A static, textured empty stand (grey, 320x240)."""
    import cv2  # noqa: PLC0415

    noise = cv2.GaussianBlur(rng.normal(size=SIZE).astype(np.float32), (0, 0), 3.0)
    return cv2.normalize(noise, None, 60, 180, cv2.NORM_MINMAX)


def with_target(background, box, value=240.0, rng=None, gain=1.0):
    x, y, w, h = box
    frame = background * gain
    frame[y:y + h, x:x + w] = value
    if rng is not None:
        frame = frame + rng.normal(0, 2, frame.shape)
    return np.clip(frame, 0, 255).astype(np.uint8)


def test_foreground_is_the_moving_target_not_the_stand_nor_a_global_light_change():
    rng = np.random.default_rng(0)
    empty = stand(rng)
    model = StaticBackground()
    box = (40, 60, 40, 20)
    model.start(with_target(empty, box, rng=rng), ag.from_box(*box))
    for i in range(1, 12):
        box = (40 + 8 * i, 60 + 2 * i, 40, 20)
        state = ag.from_box(40 + 8 * (i - 1), 60 + 2 * (i - 1), 40, 20)
        fg = model.observe(with_target(empty, box, rng=rng, gain=1.2 if i == 11 else 1.0), state)
    assert model.trusted and fg is not None
    s = model.scale
    x, y, w, h = (int(round(v * s)) for v in box)
    inside = fg[y + 1:y + h - 1, x + 1:x + w - 1].mean()
    away = np.ones(fg.shape, bool)                         # never under the target (its trail is absorbed
    for i in range(12):                                    # only background_step grey levels per frame)
        bx, by = (int(round(v * s)) for v in (40 + 8 * i, 60 + 2 * i))
        away[max(by - 4, 0):by + 10 + 4, max(bx - 4, 0):bx + 20 + 4] = False
    assert inside > 0.8                                   # the target
    assert (fg[away] > 0.5).mean() < 0.05                 # not the stand (noise tails), not a 20 % brighter light


def test_a_moving_camera_gives_no_foreground():
    rng = np.random.default_rng(1)
    wide = stand(np.random.default_rng(2))
    wide = np.hstack([wide, wide[:, ::-1]])                # a panorama to pan over
    model = StaticBackground()
    state = ag.from_box(100, 100, 40, 20)
    model.start(np.clip(wide[:, :320], 0, 255).astype(np.uint8), state)
    trusted = []
    for i in range(1, 10):
        frame = np.clip(wide[:, 12 * i:12 * i + 320] + rng.normal(0, 2, SIZE), 0, 255).astype(np.uint8)
        model.observe(frame, state)
        trusted.append(model.trusted)
    assert not any(trusted[2:])


@pytest.mark.parametrize("factor", [0.8, 1.0, 1.25])
def test_extent_measures_the_silhouette_in_the_estimates_frame(factor):
    fg = np.zeros((240, 320), np.float32)
    fg[100:140, 100:180] = 1.0                            # the silhouette: 80 x 40 px
    truth = ag.from_box(100, 100, 80, 40)
    estimate = truth @ ag.exp_coords(np.array([np.log(factor), 0, 0, 0, 0, 0]))
    extent = foreground_extent(fg, estimate, 1.0)
    assert extent is not None
    cell = 1.6 / 64
    assert extent.width == pytest.approx(1 / factor, abs=2 * cell)
    assert extent.height == pytest.approx(1 / factor, abs=2 * cell)
    assert abs(extent.centre_u) < 2 * cell and abs(extent.centre_v) < 2 * cell
    corrected = estimate @ extent.correction()
    assert np.allclose(ag.to_quad(corrected), ag.to_quad(truth), atol=3.0)


def test_extent_keeps_a_silhouettes_piece_outside_a_too_narrow_estimate(monkeypatch):
    """Rain breaks the aircraft's silhouette into pieces (fuselage, engines, wing roots). X̂ covers two of them; a
    third, cut off by a gap, lies mostly outside X̂: the silhouette takes it (width 1.23x X̂'s; with the pieces
    overlapping X̂'s own rectangle only, 0.88x, and X̂ would be pulled narrower still). A rain speck is left out."""
    from aircraft_docking_tracker.docking import static_background  # noqa: PLC0415

    fg = np.zeros((240, 320), np.float32)
    for x0, x1 in ((100, 120), (150, 170), (184, 198)):   # three pieces, the last beyond X̂'s right side (180)
        fg[110:130, x0:x1] = 1.0
    fg[90:92, 80:82] = 1.0                                # a speck
    estimate = ag.from_box(100, 100, 80, 40)
    extent = foreground_extent(fg, estimate, 1.0)
    assert extent is not None
    assert extent.width == pytest.approx(98 / 80, abs=0.05)
    assert extent.height == pytest.approx(0.5, abs=0.05)
    monkeypatch.setattr(static_background, "PIECES_WITHIN", 0.5)
    narrow = foreground_extent(fg, estimate, 1.0)
    assert narrow.width == pytest.approx(70 / 80, abs=0.05)


def test_a_small_piece_holds_the_extent_inside_the_estimate_and_never_widens_it():
    """A fin fading into a low sun's glare is a small piece apart from the fuselage (4-10 % of it): dropped, the
    extent is the fuselage alone, half X̂'s height, and pulls X̂ down to it. With ``small_share`` its cells inside X̂
    count (height 0.97); a speck of the same share beside X̂ does not widen it (width 1.0, not 1.23)."""
    fg = np.zeros((240, 320), np.float32)
    fg[110:140, 100:220] = 1.0          # the fuselage and wings: the lower half of X̂ (800 grid cells)
    fg[82:100, 155:165] = 1.0           # the fin, cut off by a gap: 36 cells, 0.045 of the largest piece
    fg[112:130, 232:244] = 1.0          # a speck beside X̂ (right side at 220): 48 cells, 0.06
    estimate = ag.from_box(100, 80, 120, 60)
    dropped = foreground_extent(fg, estimate, 1.0)
    held = foreground_extent(fg, estimate, 1.0, small_share=0.03)
    assert dropped.height == pytest.approx(0.5, abs=0.05) and dropped.width == pytest.approx(1.0, abs=0.05)
    assert held.height == pytest.approx(58 / 60, abs=0.05) and held.width == pytest.approx(1.0, abs=0.05)
    assert held.centre_v < dropped.centre_v - 0.2                   # the rectangle reaches up to the fin


def test_the_start_region_is_learnt_once_the_target_has_left_it():
    """No inpainting guess: the start region is unknown (no foreground) until its pixels are still."""
    rng = np.random.default_rng(3)
    empty = stand(rng)
    model = StaticBackground()
    model.start(with_target(empty, (40, 60, 40, 20), rng=rng), ag.from_box(40, 60, 40, 20))
    s = model.scale
    region = (slice(int(60 * s), int(80 * s)), slice(int(40 * s), int(80 * s)))
    assert not model.known[region].any()
    for i in range(1, 15):                                  # the target jumps away and stays away
        model.observe(with_target(empty, (200, 150, 40, 20), rng=rng), ag.from_box(200, 150, 40, 20))
    assert model.known[region].all()
    assert np.abs(model.background[region] - cv2_level(empty, s)[region]).mean() < 3.0


@pytest.mark.parametrize("freeze", [0.0, 1.3])
def test_a_standing_target_stays_foreground_only_with_the_background_frozen_under_it(freeze):
    """background_freeze: a target that arrives and then stands still for 60 frames (contrast 60 grey levels,
    the running median's step 2 a frame) is absorbed into B without the freeze (its foreground gone), and stays
    foreground with B frozen inside its grown rectangle; outside it B still learns (a light step is followed)."""
    rng = np.random.default_rng(5)
    empty = stand(rng)
    box = (120, 100, 60, 30)
    state = ag.from_box(*box)
    model = StaticBackground(freeze=freeze)
    model.start(with_target(empty, (10, 10, 60, 30), rng=rng), ag.from_box(10, 10, 60, 30))
    for _ in range(10):                                      # the start region is learnt, the target elsewhere
        model.observe(with_target(empty, (200, 180, 60, 30), rng=rng), ag.from_box(200, 180, 60, 30))
    target = np.clip(cv2_level(empty, 1.0)[100:130, 120:180].mean() + 60, 0, 255)
    for _ in range(60):                                       # it arrives and stands
        model.observe(with_target(empty + 5.0, box, value=float(target), rng=rng), state)
    s = model.scale
    inside = model.foreground[int(105 * s):int(125 * s), int(125 * s):int(175 * s)]
    covered = float((inside > 0.5).mean())
    if freeze > 0:
        assert covered > 0.9, covered
    else:
        assert covered < 0.1, covered
    corner = (slice(0, int(40 * s)), slice(int(250 * s), int(320 * s)))      # outside: the +5 step is learnt
    assert np.abs(model.background[corner] - (cv2_level(empty, s)[corner] + 5.0)).mean() < 1.5


def cv2_level(image, scale):
    import cv2  # noqa: PLC0415

    return cv2.resize(image.astype(np.float32), None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def test_extent_is_not_measured_when_the_silhouette_runs_off_the_search_region_or_is_absent():
    fg = np.zeros((240, 320), np.float32)
    assert foreground_extent(fg, ag.from_box(100, 100, 80, 40), 1.0) is None
    fg[100:140, 0:320] = 1.0                               # a wall of foreground across the frame
    assert foreground_extent(fg, ag.from_box(100, 100, 80, 40), 1.0) is None


# the clear 4x approach, 20 deg turned, that several tests below track (with scene seed 100: a tuning scene)
APPROACH = DockingSceneConfig(width=640, height=480, frames=150, weather="clear", occluder="none",
                              growth=4.0, turn_deg=20.0, difficulty=1)
_RENDERED: dict = {}      # (config, scene seed, count) -> (frames, quads): several tests track the same scene
_TRACKED: dict = {}       # (scene key, tracker config) -> X̂ of every frame after the start


@pytest.fixture(autouse=True, scope="module")
def _forget_the_scenes():
    """Keep the rendered scenes and tracks for this module's tests only (about 50 MB a full scene)."""
    yield
    _RENDERED.clear()
    _TRACKED.clear()


def scene_frames(config, seed, count=None):
    """A docking scene's grey frames and true quadrilaterals (N, 4, 2) (a DockingFrame carries float masks);
    ``count``: only the first so many. Rendered once per module (the frames are read-only): the scene generator
    is deterministic, and the first ``count`` frames of a whole scene are those of a ``count``-frame rendering."""
    import itertools  # noqa: PLC0415

    import cv2  # noqa: PLC0415

    whole = _RENDERED.get((repr(config), seed, None))
    if whole is not None:
        return whole[0][:count], whole[1][:count]
    key = (repr(config), seed, count)
    if key not in _RENDERED:
        frames, quads = [], []
        for f in itertools.islice(DockingScene(config, seed=seed).frames(), count):
            frames.append(cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY))
            frames[-1].setflags(write=False)
            quads.append(f.quad)
        _RENDERED[key] = (frames, np.array(quads))
    return _RENDERED[key]


def tracked_from_the_polygon(config, scene_seed, tracker_config) -> np.ndarray:
    """X̂ (N - 1, 3, 3) of every frame after the first of a track of the scene started on its first polygon;
    computed once per module for each (scene, tracker configuration)."""
    key = (repr(config), scene_seed, repr(tracker_config))
    if key not in _TRACKED:
        frames, quads = scene_frames(config, scene_seed)
        tracker = DockingTracker(tracker_config)
        tracker.start(frames[0], quads[0])
        _TRACKED[key] = np.array([tracker.step(frame).matrix for frame in frames[1:]])
    return _TRACKED[key]


def stop_scale_ratio(config, scene_seed, extent_gain, seed):
    # the shipped defaults otherwise (the target motion on): the extent is skipped while no corner under X̂
    # moves (extent_still), which needs the motion measured. With the motion off, the running background
    # absorbs the stopped aircraft and the extent grew the scale to 1.47-1.53x the truth in the last 10
    # frames for 3 of 5 tracker seeds on an AVX BLAS (OPENBLAS_CORETYPE=Sandybridge; 0 of 5 on Haswell)
    matrices = tracked_from_the_polygon(config, scene_seed, DockingConfig(extent_gain=extent_gain, seed=seed))
    _, quads = scene_frames(config, scene_seed)
    return ag.to_params(matrices[-1])[2] / ag.to_params(ag.from_quad(quads[-1]))[2]


def test_extent_correction_keeps_the_scale_up_with_a_growing_aircraft():
    """A 4x approach from the first polygon: without the foreground the estimate lags (0.74-0.83 of the
    true scale at the stop on this scene), with it the lag is gone (medians 1.00-1.05 under the Haswell,
    Sandybridge, Prescott and SkylakeX BLAS kernels). Medians over 5 tracker seeds."""
    config = APPROACH
    without = np.median([stop_scale_ratio(config, 100, 0.0, s) for s in range(5)])
    with_fg = np.median([stop_scale_ratio(config, 100, 0.3, s) for s in range(5)])
    assert with_fg > without + 0.1
    assert 0.85 < with_fg < 1.15


@pytest.mark.parametrize("degrees", [-25.0, -10.0, 0.0, 15.0])
def test_extent_reports_the_silhouettes_principal_axis_against_the_estimates(degrees):
    """extent_rotation's measurement: a 2:1 silhouette turned by ``degrees`` seen from a level estimate."""
    import cv2  # noqa: PLC0415

    fg = np.zeros((240, 320), np.float32)
    truth = ag.from_params(np.array([[160.0, 120.0, np.sqrt(80 * 40), 2.0, np.deg2rad(degrees), 0.0]]))[0]
    cv2.fillConvexPoly(fg, np.round(ag.to_quad(truth)).astype(np.int32), 1.0)
    level = ag.from_box(115, 95, 90, 50)                   # level, and large enough to hold it turned
    extent = foreground_extent(fg, level, 1.0)
    assert extent is not None
    assert np.rad2deg(extent.axis_angle) == pytest.approx(degrees, abs=2.0)
    assert extent.elongation > 1.5


@pytest.mark.parametrize("error_deg", [-10.0, -5.0, 5.0, 10.0])
def test_extent_along_the_silhouettes_axes_does_not_grow_with_the_estimates_rotation_error(error_deg):
    """extent_axes: a 2:1 silhouette turned 20 deg, seen from an estimate of the right size, place and aspect but
    turned ``error_deg`` more. Along the estimate's own axes the bounding rectangle is the turned one's bounding
    box (at 10 deg: 1.35x too high); along the silhouette's principal axes its sides stay within a few grid
    cells of the truth (what the pixels' rasterisation adds at 0 deg), the centre unmoved."""
    import cv2  # noqa: PLC0415

    def turned(deg):
        return ag.from_params(np.array([[160.0, 120.0, np.sqrt(120 * 60), 2.0, np.deg2rad(deg), 0.0]]))[0]

    fg = np.zeros((240, 320), np.float32)
    cv2.fillConvexPoly(fg, np.round(ag.to_quad(turned(20.0))).astype(np.int32), 1.0)
    estimate = turned(20.0 + error_deg)
    own = foreground_extent(fg, estimate, 1.0)
    along = foreground_extent(fg, estimate, 1.0, axes="silhouette")
    assert own is not None and along is not None
    cell = 1.6 / 64
    assert own.width * own.height > 1.12                   # the bias: the turned rectangle's bounding box
    assert along.width == pytest.approx(1.0, abs=3 * cell) and along.height == pytest.approx(1.0, abs=4 * cell)
    assert abs(along.centre_u) < 2 * cell and abs(along.centre_v) < 2 * cell
    assert along.width * along.height < own.width * own.height - 0.08


def test_flicker_threshold_learns_a_flickering_edge_outside_the_target():
    """flicker_gain: a pixel that keeps changing outside the target (a shimmering edge) stops being
    foreground; with it off the edge stays foreground. The target itself stays foreground either way."""
    rng = np.random.default_rng(5)
    empty = stand(rng)
    box = (40, 60, 40, 20)
    results = {}
    for gain in (0.0, 2.0):
        model = StaticBackground(flicker_gain=gain)
        model.start(with_target(empty, box, rng=rng), ag.from_box(*box))
        for i in range(1, 40):
            frame = with_target(empty, box, rng=rng).astype(np.float32)
            frame[180:200, 200:300] += 40.0 if i % 2 else -40.0     # the flickering band
            fg = model.observe(np.clip(frame, 0, 255).astype(np.uint8), ag.from_box(*box))
        s = model.scale
        band = fg[int(185 * s):int(195 * s), int(210 * s):int(290 * s)]
        results[gain] = float((band > 0.5).mean())
    assert results[0.0] > 0.5
    assert results[2.0] < 0.1


# ------------------------------------------------------------------------------------------------
# The target's own motion (motion_gain)
# ------------------------------------------------------------------------------------------------
def textured_target(rng, shape=(30, 60)):
    """A textured 60 x 30 patch (the target), darker than the stand."""
    import cv2  # noqa: PLC0415

    noise = cv2.GaussianBlur(rng.normal(size=shape).astype(np.float32), (0, 0), 1.5)
    return cv2.normalize(noise, None, 0, 90, cv2.NORM_MINMAX)


def paste(background, patch, centre, scale=1.0, dx=0.0):
    """The stand with ``patch`` scaled about its centre and put at ``centre`` (sub-pixel, warpAffine);
    the stand itself shifted by ``dx`` px (a camera that pans)."""
    import cv2  # noqa: PLC0415

    h, w = patch.shape
    frame = cv2.warpAffine(background, np.float32([[1, 0, dx], [0, 1, 0]]), background.shape[::-1],
                           borderMode=cv2.BORDER_REFLECT)
    m = np.float32([[scale, 0, centre[0] - scale * w / 2], [0, scale, centre[1] - scale * h / 2]])
    warped = cv2.warpAffine(patch, m, frame.shape[::-1])
    inside = cv2.warpAffine(np.ones_like(patch), m, frame.shape[::-1])
    return frame * (1 - inside) + warped * inside


@pytest.mark.parametrize("shift,growth", [((6.0, -2.0), 1.0), ((-9.0, 1.5), 1.03), ((3.0, 0.0), 0.98)])
def test_target_motion_is_the_targets_shift_and_growth(shift, growth):
    """A textured target moved (and grown) on a still, textured stand: M maps the previous estimate's
    centre to the new centre within 0.5 px and its scale within 1 %."""
    rng = np.random.default_rng(7)
    empty, patch = stand(rng), textured_target(rng)
    centre = np.array([150.0, 120.0])
    before = paste(empty, patch, centre)
    after = paste(empty, patch, centre + shift, growth)
    motion = target_motion(before, after, ag.from_box(120, 105, 60, 30), 1.0)
    assert motion is not None
    assert np.allclose((motion @ np.r_[centre, 1])[:2], centre + shift, atol=0.5)
    assert np.sqrt(abs(np.linalg.det(motion[:2, :2]))) == pytest.approx(growth, abs=0.01)


def test_target_motion_is_none_for_a_still_target_or_a_camera_that_follows_it():
    """No measurement when nothing moved, nor when the stand moves past a target that stays put in the
    image (a camera following the target: the ring around it moves the way the fit says)."""
    rng = np.random.default_rng(8)
    empty, patch = stand(rng), textured_target(rng)
    centre, state = np.array([150.0, 120.0]), ag.from_box(120, 105, 60, 30)
    before = paste(empty, patch, centre)
    assert target_motion(before, paste(empty, patch, centre), state, 1.0) is None
    assert target_motion(before, paste(empty, patch, centre, dx=4.0), state, 1.0) is None


def captioned_pan(wide, speed: float, n: int, rng, dress):
    """``n`` frames of a camera panning ``speed`` px a frame over ``wide``, each ``dress``-ed (frame -> frame), with
    a caption burnt in that does not move (as TinyTLP CarChase2's)."""
    import cv2  # noqa: PLC0415

    caption = np.where(rng.random((14, 90)) < 0.5, 30, 230).astype(np.uint8)
    frames = []
    for i in range(n):
        frame = dress(cv2.warpAffine(wide, np.float32([[1, 0, -speed * i], [0, 1, 0]]), SIZE[::-1]))
        frame[8:22, 220:310] = caption
        frames.append(frame)
    return frames


def panning_clip(speed: float, n: int = 30, seed: int = 3):
    """A camera panning ``speed`` px a frame over a textured stand, a target that moves with it (as a chase
    camera keeps it) and a caption burnt into the picture that does not move (as TinyTLP CarChase2's)."""
    rng = np.random.default_rng(seed)
    wide = np.hstack([stand(np.random.default_rng(seed + 1)), stand(np.random.default_rng(seed + 2))])
    box = (140, 100, 40, 20)
    return captioned_pan(wide, speed, n, rng, lambda frame: with_target(frame, box, rng=rng)), ag.from_box(*box)


def test_a_slow_pan_that_passes_the_shift_test_is_judged_moving_and_a_rainy_stand_still():
    """The stale-background test (``camera_moving``): a pan of 1 px a frame with a fixed caption passes the
    per-frame shift test (phase correlation median < max_shift / 2) but its stale ratio ends above 1.3x
    max_stale and the camera counts as moving from frame 10 on, nothing trusted; rainy synthetic stands
    are never judged moving, their ratio (once the window is full) below max_stale / 1.3."""
    from aircraft_docking_tracker.docking.static_background import _level_image  # noqa: PLC0415

    frames, state = panning_clip(1.0)
    model = StaticBackground(motion=True)
    model.start(frames[0], state)
    shifts, moving, trusted = [], [], []
    for frame in frames[1:]:
        image = _level_image(frame, model.level)
        shifts.append(model.camera_shift(image, state_mask(state, model.guard, image.shape, model.scale) == 0))
        model.observe(frame, state)
        moving.append(model.camera_moving)
        trusted.append(model.trusted or model.motion is not None)
    assert np.median(shifts) < model.max_shift / 2          # what the shift test alone let through
    assert all(moving[9:]) and not any(trusted[9:])
    assert model.stale_ratio > 1.3 * model.max_stale
    for seed in (0, 1):
        frames, quads = scene_frames(DockingSceneConfig(width=320, height=240, frames=40, weather="rain"), seed)
        model = StaticBackground()
        model.start(frames[0], ag.from_quad(quads[0]))
        ratios = []
        for frame, quad in zip(frames[1:], quads[:-1]):
            model.observe(frame, ag.from_quad(quad))
            assert not model.camera_moving
            ratios.append(model.stale_ratio)
        assert max(ratios[model.stale_window:]) < model.max_stale / 1.3


def road_pan(speed: float, mark: float, n: int = 40, seed: int = 3):
    """A chase camera sliding ``speed`` px a frame over a grey road with sparse lane marks ``mark`` levels
    brighter, a caption burnt in that does not move (TinyTLP CarChase2 at low contrast: most pixels of the
    road change by less than a grey level from one frame to the next)."""
    rng = np.random.default_rng(seed)
    h, w = SIZE
    road = np.full((h, 2 * w), 70.0, np.float32)
    for x0 in range(0, 2 * w, 37):
        for y0 in range(0, h, 29):
            road[y0:y0 + 3, x0:x0 + 14] += mark
    noisy = lambda frame: np.clip(frame + rng.normal(0, 0.4, frame.shape), 0, 255).round().astype(np.uint8)  # noqa: E731
    return captioned_pan(road, speed, n, rng, noisy), ag.from_box(140, 100, 40, 20)


def test_a_pan_over_a_road_that_changes_less_than_a_grey_level_a_frame_is_judged_moving():
    """The stale ratio divides by the frame-to-frame change, floored at ``NOISE_FLOOR``: here that change is
    about 0.5 level (CarChase2 at 0.4x contrast: 0.56 in the median), under the floor of 1 level used until
    session 24, which held the ratio near 0.8 and took the chase camera for a stand. With the change itself
    the ratio ends above 1.2x max_stale and the camera counts as moving from frame 10 on."""
    from aircraft_docking_tracker.docking.static_background import NOISE_FLOOR, _level_image  # noqa: PLC0415

    frames, state = road_pan(1.0, 16.0)
    model = StaticBackground(motion=True)
    model.start(frames[0], state)
    changes, moving = [], []
    for frame in frames[1:]:
        image = _level_image(frame, model.level)
        changes.append(float(np.abs(image - model._previous).mean()))
        model.observe(frame, state)
        moving.append(model.camera_moving)
    assert NOISE_FLOOR < np.median(changes) < 0.75            # under the old floor, above the new one
    assert all(moving[9:])
    assert model.stale_ratio > 1.2 * model.max_stale


def test_a_moving_camera_gives_no_motion_until_it_has_been_still_again():
    """The motion is measured on a still camera from the first frame; once a frame's phase-correlation
    shift says the camera moved, not again before ``still_frames`` still frames."""
    rng = np.random.default_rng(9)
    empty, patch = stand(rng), textured_target(rng)
    model = StaticBackground(motion=True)
    x = 100.0
    model.start(np.clip(paste(empty, patch, (x, 120)), 0, 255).astype(np.uint8), ag.from_box(x - 30, 105, 60, 30))
    measured = []
    for i in range(1, 16):
        pan = 6.0 * min(max(i - 3, 0), 3)                  # the camera pans 6 px a frame in frames 4-6
        frame = paste(empty, patch, (x + 8, 120), dx=pan)
        model.observe(np.clip(frame, 0, 255).astype(np.uint8), ag.from_box(x - 30, 105, 60, 30))
        measured.append(model.motion is not None)
        x += 8
    assert model.still_frames == 5
    assert all(measured[:3])                # frames 1-3: still camera, moving target: measured
    assert not any(measured[3:11])          # frames 4-6 pan, then 7-11: not yet 5 still frames in a row
    assert all(measured[11:])               # frames 12-15


def loose_box_ious(frames, quads, motion_gain, seed):
    """Per frame, the polygon IoU of a track started from the first polygon's axis-aligned box."""
    from aircraft_docking_tracker.evaluation.sot_metrics import region_iou  # noqa: PLC0415
    from aircraft_docking_tracker.sot_track import track  # noqa: PLC0415

    lo, hi = quads[0].min(axis=0), quads[0].max(axis=0)
    run = track(iter(frames), np.r_[lo, hi - lo], DockingConfig(motion_gain=motion_gain, seed=seed), len(frames),
                progress=False)
    return region_iou(np.asarray(run.quads, np.float64), quads)


def test_target_motion_keeps_a_fast_approach_from_a_loose_box():
    """A 60-frame approach (5x growth, 40 deg turn, rain, a vehicle; the aircraft moves ~7 px, a tenth
    of its width, a frame at the start) from the first polygon's axis-aligned box, half of it background:
    without the motion the track stays on the start's background, with it the track follows the aircraft through
    its first 20 frames (mean IoU there 0.47-0.55 on every tracker seed, against 0.21-0.25 without). Later, in the
    rain behind the crossing vehicle, the aircraft is lost on some seeds: the whole run's AUC is bimodal by seed
    (0.64-0.66 or 0.17-0.30; 2 of 5 seeds good before session 28 redrew the scene by a fraction of a pixel, 0 of 5
    since), so the assertion is on the first 20 frames, where it holds on every seed."""
    config = DockingSceneConfig(width=640, height=480, frames=60, weather="rain", occluder="vehicle",
                                growth=5.24, turn_deg=39.6, difficulty=1)
    frames, quads = scene_frames(config, 152)
    without = np.array([loose_box_ious(frames, quads, 0.0, s) for s in range(5)])
    with_motion = np.array([loose_box_ious(frames, quads, 0.6, s) for s in range(5)])
    assert without.mean() < 0.2
    assert with_motion[:, :20].mean(axis=1).min() > without[:, :20].mean(axis=1).max() + 0.15


SESSION6_SHAPE = {"shape_prior": "start", "rotation_pull": 0.0, "extent_still": "measure"}


def worst_scale_error(motion_pull: str, seed: int, **overrides) -> float:
    """Largest |scale / true scale - 1| over a 30-frame track of the textured target (x1.5 growth)."""
    from test_docking_filter import moving_target_scene

    scene = list(moving_target_scene(30))
    tracker = DockingTracker(DockingConfig(motion_pull=motion_pull, seed=seed, **overrides))
    tracker.start(scene[0][0], scene[0][1])
    return max(abs(tracker.step(frame).params[2] / ag.to_params(truth)[2] - 1) for frame, truth in scene[1:])


def test_the_motion_pulls_the_centre_and_leaves_the_scale_to_the_appearance():
    """The default pull (translation) moves X̂'s centre only: pulling the whole similarity carried the
    previous estimate's scale error forward, with nothing to bring it back (worst scale error over the
    track, median of 5 tracker seeds, 0.12 against 0.05; on an AVX-512 BLAS one track ran off, was
    declared lost and restarted elsewhere). Compared with session 6's shape rules in both arms: the
    silhouette's shape prior (the default since) also holds the similarity pull's scale (0.08 against 0.05)."""
    translation = np.median([worst_scale_error("translation", s, **SESSION6_SHAPE) for s in range(5)])
    similarity = np.median([worst_scale_error("similarity", s, **SESSION6_SHAPE) for s in range(5)])
    # medians measured (translation, similarity): Haswell 0.050 / 0.120, SkylakeX 0.047 / 0.120, Prescott
    # 0.052 / 0.076 (the same on the commit before the shape prior: the old margin 0.03 failed there)
    assert translation < 0.09 and translation < similarity - 0.015, (translation, similarity)
    defaults = np.median([worst_scale_error("translation", s) for s in range(5)])
    assert defaults < 0.09, defaults


def late_aspect_error(frames, quads, seed, **overrides):
    """Median |aspect / true aspect - 1| over the last 10 frames, tracked from the first polygon's axis-aligned box."""
    lo, hi = quads[0].min(axis=0), quads[0].max(axis=0)
    tracker = DockingTracker(DockingConfig(seed=seed, **overrides))
    tracker.start(frames[0], np.r_[lo, hi - lo])
    errors = [abs(ag.to_params(tracker.step(frame).matrix)[3] / ag.to_params(ag.from_quad(quad))[3] - 1)
              for frame, quad in zip(frames[1:], quads[1:])]
    return float(np.median(errors[-10:]))


def test_the_loose_box_aspect_is_not_held_to_the_stop():
    """From the loose box (the first polygon's axis-aligned box: aspect 1.36 against the truth's 1.98 on this
    20 deg turned approach), pulled toward the start's aspect without the start re-fit the track holds the
    wrong aspect to the stop; with the defaults (the start re-fit, the silhouette's shape prior) it does not.
    Medians over 3 tracker seeds of the error over the last 10 frames, on the scene as session 28 redrew it, with
    OPENBLAS_CORETYPE Haswell / Prescott: defaults 0.075 / 0.014, held 0.151 / 0.148 (before the redraw, over
    Haswell / Prescott / Sandybridge / SkylakeX: defaults 0.110-0.130, held 0.208-0.249). (Session 8's form of this
    test, the silhouette prior without the re-fit at the single stop frame, was a knife edge: 0.09-0.19 by kernel;
    that prior overshoots the aspect late, +0.11-0.23.)"""
    config = APPROACH
    frames, quads = scene_frames(config, 100)
    # rotation_gain 0 (the default): with the turn at 0.3 the late aspect error here is 0.21 (unset kernel, this
    # machine), as large as the held one: docs/docking_tracker.md's session-11 section says so
    defaults = np.median([late_aspect_error(frames, quads, s, rotation_gain=0.0) for s in range(3)])
    held = np.median([late_aspect_error(frames, quads, s, shape_prior="start", start_refit=0, rotation_gain=0.0)
                      for s in range(3)])
    assert held > 0.12, held                                   # the loose box's aspect, held
    assert defaults < 0.12 and defaults < held - 0.05, (defaults, held)


def test_row_offsets_remove_a_row_wise_offset_outside_the_target_only():
    rng = np.random.default_rng(3)
    offsets = rng.uniform(-1.5, 1.5, 40).astype(np.float32)
    signed = offsets[:, None] + rng.normal(0, 0.2, (40, 60)).astype(np.float32)
    outside = np.ones((40, 60), bool)
    outside[10:30, 5:55] = False                        # the target: rows 10-29 keep 10 pixels outside
    signed[10:30, 5:55] += 50.0                         # ... and do not move the rows' medians
    found = row_offsets(signed, outside, min_count=8)
    assert np.abs(found - offsets).max() < 0.3
    assert (row_offsets(signed, outside, min_count=12)[10:30] == 0).all()   # too few pixels outside: no offset
    signed[35, :40] += 30.0                             # a vehicle fills two thirds of row 35: not a band
    assert row_offsets(signed, outside, min_count=8)[35] == 0.0


def _measured_late(frames, quads, rows):
    """Frames of the moving part late in the approach (40-85 % of it) whose foreground extent is measured at
    the true state, and the measured rectangles' median width (true = 1)."""
    model = StaticBackground(row_offset=rows)
    widths, n = [], len(frames)
    for i, (frame, quad) in enumerate(zip(frames, quads)):
        state = ag.from_quad(quad)
        if i == 0:
            model.start(frame, state)
            continue
        fg = model.observe(frame, state)
        if fg is not None and 0.4 < i / n < 0.85:
            extent = foreground_extent(fg, state, model.scale)
            if extent is not None:
                widths.append(extent.width)
    return len(widths), float(np.median(widths)) if widths else np.nan


def test_row_offsets_keep_a_smooth_skys_bands_out_of_the_late_silhouette():
    """Late in a clear approach the aircraft reaches into the sky, a smooth gradient whose rounding to grey
    levels under the drifting light leaves row-wise bands of about a grey level, above the threshold of a
    low-noise frame (the 5x5 blur averages the pixel noise, not a band). One gain and offset keep them: they
    merge with the fin and the wing tips and the silhouette runs off the search grid, so the extent is not
    measured on most late frames (tuning scenes 100, 103, 106: 23-30 of 67), and is 1.15-1.3 times too wide
    when it is. With the rows' offsets removed: 53-65 of 67, width 1.05-1.10."""
    config = APPROACH
    frames, quads = scene_frames(config, 100)
    n_off, width_off = _measured_late(frames, quads, False)
    n_on, width_on = _measured_late(frames, quads, True)
    assert n_on >= 1.5 * n_off
    assert 0.95 < width_on < 1.2
    assert width_on < width_off


@pytest.mark.parametrize("width_factor", [0.5, 0.6])
def test_a_lagging_estimates_own_target_is_measured_on_the_wide_grid(width_factor):
    """An estimate 0.5-0.6 of its target's width: the silhouette runs off the 1.6x grid, so the extent is not
    measured (as before, ``extent_wide`` 0) exactly when the estimate most needs it; the filter measures it
    again on the ``extent_wide`` grid (2.4x), and the correction gives the true rectangle."""
    from aircraft_docking_tracker.docking.ispf import FilterConfig, make_filter  # noqa: PLC0415

    fg = np.zeros((240, 320), np.float32)
    fg[100:140, 100:180] = 1.0                            # the silhouette: 80 x 40 px
    truth = ag.from_box(100, 100, 80, 40)
    estimate = truth @ ag.exp_coords(np.array([0.0, np.log(width_factor) / 2, 0, 0, 0, 0])
                                     + np.array([np.log(width_factor) / 2, 0, 0, 0, 0, 0]))
    assert foreground_extent(fg, estimate, 1.0) is None
    wide = make_filter(FilterConfig(extent_wide=2.4))
    wide.background.scale = 1.0
    extent = wide._silhouette(fg, estimate)
    assert extent is not None
    assert extent.width == pytest.approx(1 / width_factor, abs=2 * 2.4 / 64)
    assert np.allclose(ag.to_quad(estimate @ extent.correction()), ag.to_quad(truth), atol=4.0)
    off = make_filter(FilterConfig(extent_wide=0.0))
    off.background.scale = 1.0
    assert off._silhouette(fg, estimate) is None


def late_rotation_error(config, scene_seed, rotation_gain, seed, **overrides):
    """Median |rotation error| [deg] over the last 40 % of a track started on the first polygon."""
    matrices = tracked_from_the_polygon(config, scene_seed,
                                        DockingConfig(rotation_gain=rotation_gain, seed=seed, **overrides))
    _, quads = scene_frames(config, scene_seed)
    errors = []
    for k, matrix in enumerate(matrices, 1):
        if k >= 0.6 * len(quads):
            turn = ag.to_params(matrix)[4] - ag.to_params(ag.from_quad(quads[k]))[4]
            errors.append(abs((turn + np.pi / 2) % np.pi - np.pi / 2))
    return float(np.rad2deg(np.median(errors)))


def test_the_estimate_turns_with_the_aircraft_to_the_silhouettes_axis():
    """Started on the first polygon of a 20 deg turned approach, the aircraft levels out from frame ~50;
    the particles' rotation_pull toward the running prior alone leaves X̂ turned (about 10 deg to the
    stop: the appearance learnt on the turned aircraft keeps choosing the turned particles), while X̂
    turned part of the way to each measured frame's silhouette axis (rotation_gain) follows it to within
    about 1 deg. Medians over 3 tracker seeds."""
    config = APPROACH
    off = np.median([late_rotation_error(config, 100, 0.0, s, learn_rotation="estimate") for s in range(3)])
    on = np.median([late_rotation_error(config, 100, 0.3, s, learn_rotation="estimate") for s in range(3)])
    assert on < 4.0 and on < off - 4.0, (off, on)


def test_the_model_learnt_at_the_silhouettes_rotation_turns_the_estimate_with_the_aircraft():
    """The same approach: the appearance model learns X̂'s own patch, so once X̂ lags the levelling aircraft the
    model has learnt the lag (probe, tracker seed 0: late, X̂'s patch scores 0.99, X̂ turned to the truth's
    rotation 0.75) and X̂ stays about 10 deg turned. Learnt at the silhouette's axis instead (learn_rotation
    silhouette; X̂ itself not turned), the model prefers the aircraft's rotation and the particles follow it
    (probe: 0.5-1 deg late). Medians over 3 tracker seeds."""
    config = APPROACH
    off = np.median([late_rotation_error(config, 100, 0.0, s, learn_rotation="estimate") for s in range(3)])
    on = np.median([late_rotation_error(config, 100, 0.0, s, learn_rotation="silhouette") for s in range(3)])
    assert on < 4.0 and on < off - 4.0, (off, on)
    defaults = np.median([late_rotation_error(config, 100, 0.0, s) for s in range(3)])
    assert defaults < 4.0, defaults       # the default (shaped) learns so on a polygon start


def track_then_restart(tracker, frames, quads, at, grow=1.0):
    """Start ``tracker`` on the first polygon, step it to frame ``at`` - 1, and request a restart on the aircraft's
    bounding box at frame ``at``, ``grow`` times as large about its centre (what the detector gives a lost track)."""
    tracker.start(frames[0], quads[0])
    for frame in frames[1:at]:
        tracker.step(frame)
    lo, hi = quads[at].min(axis=0), quads[at].max(axis=0)
    sides = (hi - lo) * grow
    tracker.request_start(np.r_[lo - (sides - (hi - lo)) / 2, sides])


def restart_mid_approach(frames, quads, restart_background, seed, at=34, after=20):
    """Track from the first polygon, restart at frame ``at`` on the aircraft's bounding box (what the detector
    gives a lost track), then ``after`` frames: the fraction of them with the extent measured, and the median
    fraction of the aircraft's true rectangle that is foreground."""
    # rotation_gain 0 (the default): with the turn at 0.3 the new background's extent is measured on 0.65 of the
    # frames, no longer under 0.5
    tracker = DockingTracker(DockingConfig(restart_background=restart_background, seed=seed, rotation_gain=0.0))
    track_then_restart(tracker, frames, quads, at)
    tracker.step(frames[at])
    cover = []
    for i in range(at + 1, at + 1 + after):
        tracker.step(frames[i])
        model = tracker.filter.background
        inside = state_mask(ag.from_quad(quads[i]), 1.0, model.known.shape, model.scale) > 0
        cover.append(0.0 if model.foreground is None else float((model.foreground[inside] > 0.5).mean()))
    return tracker.filter.extent_counts["measured"] / after, float(np.median(cover))


def test_a_restart_mid_approach_keeps_what_the_stand_background_knows():
    """Tuning scene 115 (clear, a vehicle, x5.55, 29.5 deg), restarted at frame 34 on the aircraft's box as a
    lost track is. A new static background makes the start region unknown until its pixels are still for 5
    frames: mid-approach the aircraft's uniform skin is still from frame to frame, so it is learnt as background
    and the silhouette has holes (27 % of the aircraft foreground; the extent measured on 6-7 of the next 20
    frames, on 14 since session 20's extent_small_share lets the holey silhouette's small pieces inside X̂ hold
    it, 22 % foreground). Kept (``restart_background`` keep), the stand is known: 16-19 of 20, 59 % (19, 55 %).
    Medians over 3 tracker seeds (Haswell, Prescott, Sandybridge, SkylakeX alike)."""
    config = DockingSceneConfig(width=640, height=480, frames=150, weather="clear", occluder="vehicle",
                                growth=5.55, turn_deg=29.5, difficulty=1)
    frames, quads = scene_frames(config, 115, count=55)
    new = np.median([restart_mid_approach(frames, quads, "new", s) for s in range(3)], axis=0)
    kept = np.median([restart_mid_approach(frames, quads, "keep", s) for s in range(3)], axis=0)
    assert kept[0] >= 0.7 and kept[0] > new[0] + 0.15
    assert kept[1] > new[1] + 0.15


def test_relight_keeps_a_bright_sky_out_of_the_foreground_under_a_fast_light_ramp():
    """background_relight: the light rises 1.5 % a frame (no pixel saturates), so a sky at 170 grey levels
    brightens 2.6 levels a frame, more than the background's step (2), the ground (36-108) less: a background that
    follows the frame as seen lags on the sky only, and one gain and offset cannot explain sky and ground at once
    (measured: 17 % of the sky is foreground); kept under its own light, the background is the stand itself."""
    rng = np.random.default_rng(3)
    empty = stand(rng) * 0.6                                  # ground 36-108
    empty[:80] = 170.0 - np.arange(80, dtype=np.float32)[:, None] * 70 / 80     # a smooth bright sky band on top
    box = (120, 140, 60, 30)
    state = ag.from_box(*box)
    outcome = {}
    for relight in (False, True):
        model = StaticBackground(relight=relight)
        model.start(with_target(empty, box, value=250.0, rng=np.random.default_rng(4)), state)
        sky_foreground, trusted = [], []
        frame_rng = np.random.default_rng(5)
        for i in range(1, 25):
            frame = with_target(empty, box, value=250.0, rng=frame_rng, gain=1.0 + 0.015 * i)
            fg = model.observe(frame, state)
            trusted.append(fg is not None)
            if fg is not None:
                sky_foreground.append(float((fg[: int(70 * model.scale)] > 0.5).mean()))
        outcome[relight] = (np.mean(trusted[10:]), max(sky_foreground[10:], default=1.0))
    assert outcome[True][0] == 1.0 and outcome[True][1] < 0.02      # kept under its own light: the sky is still sky
    assert outcome[False][0] < 1.0 or outcome[False][1] > 0.08       # followed as seen: the sky lags (the contrast)


def test_two_frame_foreground_drops_one_frame_streaks_and_keeps_the_moving_target():
    """foreground_frames 2: bright streaks that fall anew each frame (rain) are foreground on one frame only; the
    minimum of two trusted frames' foregrounds drops them and keeps a target that moves 4 px a frame."""
    rng = np.random.default_rng(6)
    empty = stand(rng)
    outcome = {}
    for persist in (1, 2):
        model = StaticBackground(persist=persist)
        frame_rng = np.random.default_rng(7)
        box = (40, 80, 60, 30)
        model.start(with_target(empty, box, rng=frame_rng), ag.from_box(*box))
        streaks, target = [], []
        for i in range(1, 30):
            box = (40 + 4 * i, 80, 60, 30)
            frame = with_target(empty, box, rng=frame_rng).astype(np.float32)
            for x, y in zip(frame_rng.integers(0, 314, 60), frame_rng.integers(0, 226, 60)):
                frame[y:y + 12, x:x + 2] = 235.0              # 60 streaks of 2 x 12 px, new every frame
            fg = model.observe(frame.astype(np.uint8), ag.from_box(40 + 4 * (i - 1), 80, 60, 30))
            if fg is None or i < 10:
                continue
            s = model.scale
            x, y, w, h = (int(round(v * s)) for v in box)
            inner = np.zeros(fg.shape, bool)
            inner[y + 2:y + h - 2, x + 3:x + w - 2] = True       # the target less its leading and trailing edges
            away = np.ones(fg.shape, bool)                  # not the target's path (its trail fades only
            away[max(y - 6, 0):y + h + 6] = False             # background_step levels a frame)
            target.append(float((fg[inner] > 0.5).mean()))
            streaks.append(float((fg[away] > 0.5).mean()))
        outcome[persist] = (len(target), np.median(target), np.median(streaks))
    assert outcome[2][0] >= 15 and outcome[2][1] > 0.9              # the target stays foreground
    assert outcome[2][2] < 0.5 * outcome[1][2]                      # most streaks are gone (measured: 0.024 vs 0.083)
    assert outcome[1][2] > 0.04                                     # (the contrast: one frame keeps them)


def scale_after_loose_restart(frames, quads, seed, at=30, grow=1.7, after=40, **overrides):
    """Track from the first polygon, restart at frame ``at`` on a box ``grow`` times the aircraft's bounding box
    about its centre (1.7: a cascade box around the aircraft and the jet bridge; 0.55: one around the fuselage
    alone), then ``after`` frames: the median log scale error of X̂ over the last 10."""
    tracker = DockingTracker(DockingConfig(**overrides, seed=seed))
    track_then_restart(tracker, frames, quads, at, grow)
    errors = []
    for i in range(at, at + after):
        r = tracker.step(frames[i])
        errors.append(np.log(ag.to_params(r.matrix)[2] / ag.to_params(ag.from_quad(quads[i]))[2]))
    return float(np.median(errors[-10:]))


def test_a_restart_on_a_box_too_large_is_shrunk_to_the_silhouette():
    """Tuning scene 100 (clear, x4, 20 deg) restarted at frame 30 on a box 1.7x the aircraft's bounding box. The
    silhouette is then 0.5-0.6x X̂'s sides, outside the usual 0.6-1.5x, so at ``restart_extent_low`` 0.6 it is
    never measured and X̂ stays +0.5 log too large for 40 frames; at 0.4 (the default) the first measurements
    are taken and the scale is right within 0.06 log (medians over 3 tracker seeds; at 2x the box, 2 of 3)."""
    config = APPROACH
    frames, quads = scene_frames(config, 100, count=70)
    usual = np.median([scale_after_loose_restart(frames, quads, s, restart_extent_low=0.6) for s in range(3)])
    wide = np.median([scale_after_loose_restart(frames, quads, s, restart_extent_low=0.4) for s in range(3)])
    assert usual > 0.35
    assert abs(wide) < 0.2


def test_a_restart_on_a_box_too_small_grows_to_the_silhouette():
    """The same scene restarted at frame 30 on a box 0.55x the aircraft's bounding box (the stand cascade's box of
    the fuselage when the pale wings are lost against a low sun: tuning scene 152). The silhouette is then about
    1.8x X̂'s sides: at ``restart_extent_high`` 1.5 never measured, X̂ stays too small; at 2.0 (the default) it
    grows to the aircraft (medians over 3 tracker seeds)."""
    config = APPROACH
    frames, quads = scene_frames(config, 100, count=70)
    usual = np.median([scale_after_loose_restart(frames, quads, s, grow=0.55, restart_extent_high=1.5)
                       for s in range(3)])
    wide = np.median([scale_after_loose_restart(frames, quads, s, grow=0.55, restart_extent_high=2.0)
                      for s in range(3)])
    assert usual < -0.25                   # measured -0.33 to -0.39 over tracker seeds 0-4 (the start: -0.6)
    assert abs(wide) < 0.15                # measured -0.04 to +0.03


def test_a_target_painted_at_the_stands_grey_level_is_foreground_only_in_colour():
    """``colour`` (``foreground_colour``): a target whose paint changes the stand's colour but not its grey level
    (an orange wing over a grey apron of the same brightness) is foreground from the channels' colour beyond the
    grey difference, and not from the grey difference alone; the stand itself stays background either way."""
    import cv2  # noqa: PLC0415

    rng = np.random.default_rng(3)
    empty = cv2.cvtColor(stand(rng), cv2.COLOR_GRAY2BGR).astype(np.float32)
    paint = np.array([-54.4, -20.0, 60.0], np.float32)   # B, G, R: 0.114 B + 0.587 G + 0.299 R = 0
    foregrounds = {}
    for colour in (False, True):
        model = StaticBackground(colour=colour)
        rng = np.random.default_rng(4)
        for i in range(12):
            x, y = 40 + 8 * i, 60 + 2 * i
            frame = empty.copy()
            frame[y:y + 20, x:x + 40] += paint
            frame = np.clip(frame + rng.normal(0, 2, frame.shape), 0, 255).astype(np.uint8)
            grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
            state = ag.from_box(40 + 8 * max(i - 1, 0), 60 + 2 * max(i - 1, 0), 40, 20)
            fg = model.start(grey, state, frame) if i == 0 else model.observe(grey, state, frame)
        assert model.trusted and fg is not None
        assert (model.colour_background is not None) == colour
        s = model.scale
        inside = fg[int((y + 2) * s):int((y + 18) * s), int((x + 2) * s):int((x + 38) * s)].mean()
        far = fg[int(160 * s):, :int(120 * s)]           # never under the target
        foregrounds[colour] = inside
        assert (far > 0.5).mean() < 0.05
    assert foregrounds[True] > 0.8 and foregrounds[False] < 0.2


def _late_width(config, seed, colour, narrow=0.6):
    """Late in the approach (40-85 % of it), the median width (true = 1) of the foreground's rectangle measured
    about the true state narrowed to ``narrow`` of its width (a track that has lost the wings), on the grid
    of 1.6 X̂ or, when the silhouette runs off it, of 2.4 X̂ (as ``ispf`` measures it)."""
    import cv2  # noqa: PLC0415

    model = StaticBackground(row_offset=True, relight=True, persist=2, colour=colour)
    frames = list(DockingScene(config, seed=seed).frames())
    widths = []
    for i, frame in enumerate(frames):
        state = ag.from_quad(frame.quad)
        grey = cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY)
        if i == 0:
            model.start(grey, state, frame.image)
            continue
        fg = model.observe(grey, state, frame.image)
        if fg is not None and 0.4 < i / len(frames) < 0.85:
            narrowed = state @ np.diag([narrow, 1.0, 1.0])
            extent = (foreground_extent(fg, narrowed, model.scale, small_share=0.03)
                      or foreground_extent(fg, narrowed, model.scale, small_share=0.03, extent=2.4))
            if extent is not None:
                widths.append(extent.width * narrow)
    return len(widths), float(np.median(widths))


def test_in_rain_the_colour_foreground_gives_a_too_narrow_track_back_its_wings():
    """Rain (bench approach 301): the thin grey wings at the apron's grey level break from the fuselage in the
    grey foreground, their pieces lie outside a track that has narrowed to 0.6 of the aircraft's width and are
    dropped, so the extent measures the track's own width (0.65 of the truth's) and cannot widen it again: late
    in held-out rain approaches the track's width fell to 0.55 of the truth's. The colour foreground keeps the
    painted wing joined to the fuselage: 0.99. In clear light both measure the aircraft (0.99 each)."""
    rain = DockingSceneConfig(width=640, height=480, frames=60, weather="rain", occluder="none",
                              growth=4.37, turn_deg=27.3, difficulty=1)
    n_grey, grey = _late_width(rain, 301, False)
    n_colour, colour = _late_width(rain, 301, True)
    assert n_grey >= 15 and n_colour >= 15
    assert grey < 0.8 and 0.9 < colour < 1.15
    clear = DockingSceneConfig(width=640, height=480, frames=60, weather="clear", occluder="none",
                               growth=4.0, turn_deg=20.0, difficulty=1)
    n_clear, width_clear = _late_width(clear, 300, True)
    assert n_clear >= 15 and 0.9 < width_clear < 1.15


@pytest.mark.parametrize("window", [0, 15])
def test_a_slow_target_is_moving_only_with_the_keyframe_window(window):
    """A textured target drifting 0.12 px a frame (a slow approach 50 m out) never moves half a pixel between
    two frames: without the window it is judged still on every frame; with it, moving on most frames once the
    drift against the keyframe passes half a pixel (the check that finds 0.48 px calls that frame still), and
    still again at most ``still_gap`` (4) frames after it stops, not a whole window later."""
    rng = np.random.default_rng(11)
    empty, patch = stand(rng), textured_target(rng)
    centre, state = np.array([150.0, 120.0]), ag.from_box(120, 105, 60, 30)
    model = StaticBackground(max_width=320, motion=True, still_window=window)
    model.start(paste(empty, patch, centre), state)
    still = []
    for k in range(1, 61):
        position = centre + (min(k, 24) * 0.12, 0.0)          # drifts for 24 frames, then stands
        model.observe(paste(empty, patch, position) + rng.normal(0, 0.5, SIZE), state)
        still.append(model.target_still)
    moving_part, standing_part = still[8:24], still[24 + 5:]
    if window == 0:
        assert all(still[6:])
    else:
        assert np.mean(moving_part) <= 0.3 and all(standing_part)
