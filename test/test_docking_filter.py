"""ISPF and the plain PF lock onto a synthetic textured target that moves, grows and turns."""
import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.docking import affine_group as ag
from aircraft_docking_tracker.docking.appearance import (AppearanceConfig, AppearanceError, IncrementalSubspace,
                                                 ObservationModel, normalize)
from aircraft_docking_tracker.evaluation.sot_metrics import polygon_iou
from aircraft_docking_tracker.docking.ispf import ISPF, AffineParticleFilter, FilterConfig, FrameError, make_filter


def textured(shape, rng, blur=2.0):
    noise = rng.normal(size=shape).astype(np.float32)
    img = cv2.GaussianBlur(noise, (0, 0), blur)
    return cv2.normalize(img, None, 20, 235, cv2.NORM_MINMAX)


def moving_target_scene(frames=40, size=(320, 240), seed=0, visible=lambda i: True, change=None):
    """Grey frames with a textured 48x32 target whose true state moves, grows x1.5 and turns 20 deg.

    Yields (frame uint8, true 3x3 state); ``visible(i)`` False hides the target in frame i; ``change`` (frame, mix):
    from that frame on, the target's texture is (1 - mix) of its own and mix of another (a lasting change of
    appearance: light, a pose change).
    """
    rng = np.random.default_rng(seed)
    w, h = size
    background = textured((h, w), rng, 3.0)
    sprite = textured((64, 96), rng, 4.0)                 # the target's texture, 96 x 64 sprite pixels
    if change is not None:
        changed = (1 - change[1]) * sprite + change[1] * textured((64, 96), rng, 4.0)
    for i in range(frames):
        t = i / max(frames - 1, 1)
        X = ag.from_params([80 + 140 * t, 90 + 50 * t, np.sqrt(48 * 32) * (1 + 0.5 * t), 1.5,
                            np.deg2rad(20) * t, 0.0])
        frame = background.copy()
        if visible(i):
            # sprite pixel (c, r) -> template (u, v) = ((c + .5)/96 - .5, (r + .5)/64 - .5) -> image
            to_template = np.array([[1 / 96, 0, 0.5 / 96 - 0.5], [0, 1 / 64, 0.5 / 64 - 0.5], [0, 0, 1]])
            M = (X @ to_template)[:2] - np.array([[0, 0, 0.5], [0, 0, 0.5]])
            texture = changed if change is not None and i >= change[0] else sprite
            warped = cv2.warpAffine(texture, M, (w, h), flags=cv2.INTER_LINEAR, borderValue=-1)
            inside = cv2.warpAffine(np.ones_like(sprite), M, (w, h), flags=cv2.INTER_LINEAR)
            frame = np.where(inside > 0.5, warped, frame)
        frame = frame + rng.normal(0, 3, frame.shape)
        yield np.clip(frame, 0, 255).astype(np.uint8), X


def run_filter(config, frames=40):
    scene = list(moving_target_scene(frames))
    flt = make_filter(config)
    flt.start(scene[0][0], scene[0][1])
    ious, particles = [], []
    for frame, truth in scene[1:]:
        r = flt.step(frame)
        ious.append(polygon_iou(ag.to_quad(r.state)[None], ag.to_quad(truth)[None])[0])
        particles.append(r.particles)
    return np.array(ious), np.array(particles), flt


SEEDS = range(5)


def test_ispf_locks_onto_a_moving_growing_turning_target():
    """Medians over tracker seeds (one draw may be unlucky on some CPU's rounding; the median is not)."""
    runs = [run_filter(FilterConfig(method="ispf", seed=s)) for s in SEEDS]
    assert np.median([ious.mean() for ious, _, _ in runs]) > 0.8, [ious.mean().round(2) for ious, _, _ in runs]
    assert np.median([ious[-10:].min() for ious, _, _ in runs]) > 0.7
    assert all(p.min() >= 20 and p.max() <= 300 for _, p, _ in runs)
    params = np.array([ag.to_params(flt.estimate) for _, _, flt in runs])
    assert abs(np.median(params[:, 2]) / (np.sqrt(48 * 32) * 1.5) - 1) < 0.15      # scale
    assert abs(np.rad2deg(np.median(params[:, 4])) - 20) < 8                         # rotation
    assert abs(np.median(params[:, 3]) / 1.5 - 1) < 0.15                             # aspect kept
    assert np.rad2deg(np.abs(params[:, 5])).max() < 3                                # no shear


def test_plain_pf_with_the_same_model_also_tracks():
    runs = [run_filter(FilterConfig(method="pf", pf_particles=300, seed=s)) for s in SEEDS]
    assert all((p == 300).all() for _, p, _ in runs)
    assert np.median([ious.mean() for ious, _, _ in runs]) > 0.7


def test_the_seeds_choices_stay_selectable_and_track():
    """The seed's unit-square chart, AR on all six, argmax estimate and update rule (config/docking_tracker_seed.yaml)."""
    cfg = dict(chart="unit", ar_dims="all", estimate="best", update_rule="background", tune_min_gain=0.0,
               skew_pull=0.0, aspect_pull=0.0)
    runs = [run_filter(FilterConfig(seed=s, **cfg)) for s in SEEDS]
    assert np.median([ious.mean() for ious, _, _ in runs]) > 0.6


def test_metric_chart_rotation_noise_is_an_image_rotation_without_shear():
    """On a 4:1 target, σ_θ alone turns the quadrilateral and leaves aspect and skew untouched (metric
    chart); on the unit-square chart the same step shears it (the seed's, the issue's finding)."""
    frame, _ = next(moving_target_scene(1))
    X = ag.from_params([160, 120, 40, 4.0, 0.3, 0.0])
    zero = dict(sigma_scale=0, sigma_aspect=0, sigma_skew=0, sigma_x=0, sigma_y=0, sigma_rotation=0.05,
                skew_pull=0.0, aspect_pull=0.0)
    skews = {}
    for chart in ("metric", "unit"):
        flt = AffineParticleFilter(FilterConfig(chart=chart, **zero))
        flt.start(frame, X)
        p = ag.to_params(flt._perturb(np.repeat(X[None], 200, axis=0)))
        skews[chart] = np.abs(p[:, 5]).mean()
        if chart == "metric":
            assert np.allclose(p[:, 2:4], [40, 4.0]) and p[:, 4].std() > 0.03
    assert skews["metric"] < 1e-9 < 0.01 < skews["unit"]


def test_weighted_estimate_moves_little_when_one_score_moves_a_rounding_step():
    frame, X = next(moving_target_scene(1))
    flt = AffineParticleFilter(FilterConfig(seed=0))
    flt.start(frame, X)
    states = flt._perturb(np.repeat(X[None], 50, axis=0))
    scores, patches = flt._score(states)
    order = np.argsort(-scores)
    scores[order[1]] = scores[order[0]] + 1e-7                      # the argmax flips to another particle
    a = flt._estimate(states, scores, patches)[0]
    scores[order[1]] = scores[order[0]] - 1e-7
    b = flt._estimate(states, scores, patches)[0]
    assert np.abs(ag.to_quad(a) - ag.to_quad(b)).max() < 0.05      # pixels


def test_scale_check_moves_a_too_small_estimate_toward_the_true_scale_and_keeps_a_right_one():
    """The multi-scale check of X̂ (``scale_check``): one step of exp(±s) toward the better-scoring scale,
    none at the true state (a margin of tune_min_gain, so rounding does not decide)."""
    frame, X = next(moving_target_scene(1))
    flt = AffineParticleFilter(FilterConfig(seed=0, scale_check=0.03))
    flt.start(frame, X)
    small = X @ ag.exp_coords(np.array([-0.12, 0, 0, 0, 0, 0]))
    score, patch = flt._score(small[None])
    moved, moved_score, _ = flt._check_scale(small, float(score[0]), patch[0])
    ratio = np.sqrt(np.linalg.det(moved[:2, :2]) / np.linalg.det(small[:2, :2]))
    assert np.isclose(ratio, np.exp(0.03)) and moved_score > score[0] + 1e-3
    score, patch = flt._score(X[None])
    kept, kept_score, _ = flt._check_scale(X, float(score[0]), patch[0])
    assert np.array_equal(kept, X) and kept_score == score[0]


def test_update_floor_is_lowered_only_under_a_lasting_low_score_on_a_moving_camera_and_never_below_update_low():
    """``update_relative``: min(update_min_score, μ_T - k σ_T), at least ``update_low``, on a frame the camera is judged
    moving; a still camera (its extent corrects the state) and off (0): the absolute floor."""
    frame, X = next(moving_target_scene(1))
    floors = {}
    for k in (0.0, 2.0):
        flt = AffineParticleFilter(FilterConfig(seed=0, update_relative=k))
        flt.start(frame, X)
        for moving in (False, True):
            flt.background.camera_moving = moving
            for name, (mean, std) in {"tracked": (0.95, 0.02), "lasting low": (0.66, 0.01),
                                      "hidden": (0.5, 0.05)}.items():
                flt.track_stats.mean, flt.track_stats.var = mean, std ** 2
                floors[k, moving, name] = flt._update_floor()
    assert {v for (k, moving, _), v in floors.items() if k == 0.0 or not moving} == {0.75}
    assert floors[2.0, True, "tracked"] == 0.75                   # a high-scoring track: the absolute floor
    assert abs(floors[2.0, True, "lasting low"] - 0.64) < 1e-9    # scores sat at 0.66: it learns again
    assert floors[2.0, True, "hidden"] == 0.6                     # never below update_low


def test_the_anchor_term_weighs_moving_anchor_weight_where_no_still_camera_checks_the_track():
    """The model's β is ``anchor_weight`` on a still camera's frames and ``moving_anchor_weight`` on the others: the
    static-camera model off, or the camera judged moving (a pan of 3 px a frame)."""
    scene = list(moving_target_scene(12))
    config = dict(seed=0, anchor_weight=0.1, moving_anchor_weight=0.4)
    weights = {}
    for name, extra, pan in (("still", {}, 0), ("no static model", {"extent_gain": 0.0, "motion_gain": 0.0}, 0),
                             ("moving", {}, 3)):
        flt = make_filter(FilterConfig(**config, **extra))
        flt.start(*scene[0])
        for i, (frame, _) in enumerate(scene[1:], 1):
            flt.step(np.roll(frame, pan * i, axis=1))
        weights[name] = (flt.model.anchor_weight, flt.background.camera_moving)
    assert weights == {"still": (0.1, False), "no static model": (0.4, False), "moving": (0.4, True)}


def test_a_lasting_change_of_appearance_is_learnt_with_update_relative():
    """Half of the target's texture replaced from frame 8 on, no static-camera model (what a moving camera leaves):
    the absolute floor never updates the model again (Ŝ about 0.5-0.65, the start's model to the end); the relative
    floor learns the new appearance (Ŝ back near 0.9) and keeps the target (medians of 3 seeds). Learning the new
    texture costs a little IoU here, by BLAS kernel 0.01-0.05 (late mean IoU, median of the seeds: native 0.875
    against 0.888, Sandybridge 0.851 against 0.904): the model also learns some of the state's error with it."""
    scene = list(moving_target_scene(40, change=(8, 0.5)))
    runs = {}
    for k in (0.0, 2.0):
        for seed in range(3):
            flt = make_filter(FilterConfig(seed=seed, update_relative=k, extent_gain=0.0, motion_gain=0.0))
            flt.start(scene[0][0], scene[0][1])
            results = [(flt.step(frame), truth) for frame, truth in scene[1:]]
            late = results[10:]
            iou = np.mean([polygon_iou(ag.to_quad(r.state)[None], ag.to_quad(t)[None])[0] for r, t in late])
            runs.setdefault(k, []).append((iou, sum(r.updated for r, _ in late), np.mean([r.score for r, _ in late])))
    med = {k: np.median(np.array(v), axis=0) for k, v in runs.items()}
    assert med[0.0][1] <= 3 and med[2.0][1] >= 20, runs          # updates on the 29 late frames
    assert med[2.0][2] > med[0.0][2] + 0.15, runs                  # the model has learnt the new texture
    assert med[2.0][0] > 0.8 and med[2.0][0] > med[0.0][0] - 0.1, runs


def test_ispf_uses_fewer_particles_than_its_maximum_when_the_target_is_easy():
    _, particles, _ = run_filter(FilterConfig(method="ispf", seed=2, n_total=600))
    assert particles.mean() < 0.5 * 600


def test_isp_and_pf_share_one_transition_and_update():
    assert issubclass(ISPF, AffineParticleFilter)
    for name in ("_transition", "_finish", "_resample", "_observe", "start"):
        assert name not in ISPF.__dict__


def test_self_tuning_moves_particles_toward_the_target():
    scene = moving_target_scene(3)
    frame0, X0 = next(scene)
    flt = ISPF(FilterConfig(seed=0))
    flt.start(frame0, X0)
    frame1, X1 = next(scene)
    flt._load(frame1, X0)
    offsets = np.zeros((30, 6))
    offsets[:, 4:] = np.random.default_rng(0).normal(0, 0.08, (30, 2))
    start = X1 @ ag.exp_coords(offsets)
    tuned, scores, _ = flt.self_tune(start)
    before = np.linalg.norm(ag.log_coords(ag.inverse(X1) @ start)[:, 4:], axis=1)
    after = np.linalg.norm(ag.log_coords(ag.inverse(X1) @ tuned)[:, 4:], axis=1)
    assert np.median(after) < 0.6 * np.median(before)
    assert (scores >= flt._score(start)[0] - 1e-6).all()         # tuning never lowers Sim


def test_bad_frames_are_refused():
    flt = make_filter(FilterConfig())
    with pytest.raises(FrameError):
        flt.step(np.zeros((10, 10), np.uint8))                   # before start
    frame, X = next(moving_target_scene(1))
    flt.start(frame, X)
    with pytest.raises(FrameError):
        flt.step(np.zeros((0, 5), np.uint8))
    with pytest.raises(FrameError):
        flt.step(np.zeros((4, 4, 3, 2), np.uint8))
    with pytest.raises(FrameError):
        flt.step(np.zeros((4, 4, 4), np.uint8))                  # BGRA: grey or BGR only
    flt.step(np.repeat(frame[..., None], 3, axis=2))             # BGR: tracked in its grey conversion


def test_incremental_subspace_learns_a_low_rank_set():
    rng = np.random.default_rng(0)
    basis = np.linalg.qr(rng.normal(size=(100, 3)))[0]
    data = rng.normal(size=(60, 3)) @ basis.T * 5 + 2.0
    sub = IncrementalSubspace(100, 8, 1.0)
    for k in range(0, 60, 5):
        sub.update(data[k:k + 5])
    assert np.allclose(sub.mean, data.mean(axis=0), atol=1e-4)
    assert np.abs(sub.residual(data)).max() < 1e-3                 # the 3-d set is explained
    assert np.abs(sub.residual(rng.normal(size=(5, 100)) * 5)).mean() > 1.0


def test_similarity_is_high_for_the_model_and_low_for_other_texture():
    rng = np.random.default_rng(0)
    model = ObservationModel(AppearanceConfig())
    patch = textured((32, 32), rng)
    model.start(patch[None])
    other = textured((32, 32), rng)
    sims = model.similarity(np.stack([patch, patch * 0.5 + 40, other]))
    assert sims[0] > 0.99 and sims[1] > 0.99 and sims[2] < 0.6     # brightness/contrast invariant
    with pytest.raises(AppearanceError):
        model.similarity(np.zeros((1, 16, 16)))
    assert np.allclose(normalize(patch[None]).std(), 1, atol=1e-2)
