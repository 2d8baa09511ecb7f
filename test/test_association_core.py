"""Association core: eqs. 8-12 by hand, each rule of seed 003 §3.3 on a scripted scene, the options."""
from __future__ import annotations

import numpy as np
import pytest

from multi_target_tracker.association import (COASTING, CONFIRMED, LOST, PREDICTED, TENTATIVE, AssociationConfig,
                                              AssociationError, MultiTargetTracker, all_pairs, angles, gated_pairs,
                                              hungarian, mahalanobis_squared, normalise_by_max, pad_square,
                                              seed_config, seed_cost)
from multi_target_tracker.kalman import KalmanConfig

FPS = 10.0
KALMAN = KalmanConfig(acceleration_noise=50.0, measurement_noise=1.0, initial_velocity_std=100.0)


def box(cx, cy, w=10.0, h=10.0):
    return [cx - w / 2, cy - h / 2, w, h]


def run(tracker, frames):
    """frames: list of lists of boxes; returns the FrameResult of every frame."""
    return [tracker.step(k / FPS, np.array(b, dtype=float).reshape(-1, 4)) for k, b in enumerate(frames)]


def state_of(result, track_id):
    t = result.tracks
    return int(t.states[t.ids == track_id][0]) if (t.ids == track_id).any() else None


# -- eqs. 8-12 --------------------------------------------------------------------------------
def test_angle_and_normalised_cost_by_hand():
    positions = np.array([[0.0, 0.0], [10.0, 0.0]])
    velocities = np.array([[1.0, 0.0], [0.0, 0.0]])           # second target: no velocity yet
    points = np.array([[1.0, 1.0], [-2.0, 0.0]])
    i, j = all_pairs(2, 2)
    assert i.tolist() == [0, 0, 1, 1] and j.tolist() == [0, 1, 0, 1]
    theta = angles(positions[i], velocities[i], points[j], still_speed=0.5)
    np.testing.assert_allclose(theta, [np.pi / 4, np.pi, 0.0, 0.0])   # documented: θ = 0 without velocity
    predicted = positions + [[1.0, 0.0], [0.0, 0.0]]
    cost = seed_cost(positions[i], predicted[i], velocities[i], points[j], 0.5)
    r = np.array([1.0, 3.0, np.hypot(9, 1), 12.0])
    np.testing.assert_allclose(cost, theta / np.pi + r / 12.0)
    assert normalise_by_max(np.zeros(4)).max() == 0.0
    no_angle = seed_cost(positions[i], predicted[i], velocities[i], points[j], 0.5, angle_weight=0.0)
    np.testing.assert_allclose(no_angle, r / 12.0)
    half = seed_cost(positions[i], predicted[i], velocities[i], points[j], 0.5, angle_weight=0.5)
    np.testing.assert_allclose(half, 0.5 * theta / np.pi + r / 12.0)


def test_mahalanobis_pairs_by_hand_and_kdtree_agrees_with_brute_force():
    d2 = mahalanobis_squared(np.zeros((1, 2)), np.array([4.0]), np.array([[2.0, 1.0]]))
    assert d2[0] == pytest.approx(5.0 / 4.0)                    # (2² + 1²) / s with S = s I
    rng = np.random.default_rng(1)
    predicted = rng.uniform(0, 500, (80, 2))
    points = predicted[rng.permutation(80)[:70]] + rng.normal(0, 3, (70, 2))
    s = rng.uniform(2.0, 30.0, 80)
    brute = gated_pairs(predicted, s, points, 9.21, brute_force_below=10 ** 9)
    tree = gated_pairs(predicted, s, points, 9.21, brute_force_below=0)
    assert sorted(zip(*brute)) == sorted(zip(*tree)) and len(brute[0]) >= 50


def test_padding_shapes_and_zero_dummies():
    wide = np.arange(6, dtype=float).reshape(2, 3) + 1
    tall = np.arange(6, dtype=float).reshape(3, 2) + 1
    assert pad_square(wide).shape == (3, 3) and pad_square(tall).shape == (3, 3)
    np.testing.assert_array_equal(pad_square(wide)[2], 0)     # eq. 12: n - m dummy targets
    np.testing.assert_array_equal(pad_square(tall)[:, 2], 0)  # eq. 11: m - n dummy detections
    np.testing.assert_array_equal(pad_square(wide)[:2], wide)
    t, d = hungarian(np.array([[5.0, 1.0, 9.0], [1.0, 9.0, 9.0]]))
    assert sorted(zip(t.tolist(), d.tolist())) == [(0, 1), (1, 0)]
    t, d = hungarian(np.zeros((0, 3)))
    assert len(t) == 0


# -- §3.3 rules ---------------------------------------------------------------------------------
def three_targets(k, dx=2.0):
    """Three targets far apart moving right, so the seed's matrix-normalised cost has a scale."""
    return [box(20 + dx * k, 20), box(20 + dx * k, 200), box(300 + dx * k, 100)]


def test_tentative_confirmed_at_lt_and_clutter_dropped():
    cfg = seed_config(confirm_length=4, tentative_max_misses=1)
    tracker = MultiTargetTracker(cfg, KALMAN)
    frames = [three_targets(k) for k in range(8)]
    frames[0] = frames[0] + [box(150, 300)]                    # one clutter detection, frame 0 only
    results = run(tracker, frames)
    clutter_id = 4
    assert state_of(results[0], clutter_id) == TENTATIVE
    assert state_of(results[2], clutter_id) is None             # dropped after more than 1 miss
    assert state_of(results[2], 1) == TENTATIVE                 # 3 detections so far
    assert results[3].confirmed_now == [1, 2, 3]                # rule 4: length reaches l_t = 4
    assert all(state_of(results[3], i) == CONFIRMED for i in (1, 2, 3))
    assert len(results[7].tracks.visible()) == 3
    assert len(results[2].tracks.visible()) == 0                # tentative tracks are never shown
    assert 4 not in np.concatenate([r.tracks.visible().ids for r in results])


def test_miss_coasts_then_resets_and_deletion_after_ft():
    cfg = seed_config(confirm_length=2, max_misses=3)
    tracker = MultiTargetTracker(cfg, KALMAN)
    frames = [three_targets(k) for k in range(12)]
    for k in (4, 5):
        frames[k] = frames[k][1:]                               # target 1 missed twice
    for k in range(7, 12):
        frames[k] = frames[k][1:]                               # then gone for good
    results = run(tracker, frames)
    assert state_of(results[4], 1) == COASTING and results[4].tracks.misses[0] == 1
    assert results[5].tracks.misses[0] == 2
    # coasting on prediction: the box kept moving right at ~20 px/s
    assert results[5].tracks.boxes[0, 0] > results[3].tracks.boxes[0, 0] + 2.0
    assert state_of(results[6], 1) == CONFIRMED and results[6].tracks.misses[0] == 0   # counter reset
    assert state_of(results[9], 1) == COASTING                                       # 3 misses: kept
    assert state_of(results[10], 1) is None                                          # 4 > f_t: deleted
    assert {2, 3} <= set(results[11].tracks.ids.tolist())
    assert tracker.next_id == 4                                                      # no new tracks


def test_assignment_above_ct_counts_as_miss():
    tracker = MultiTargetTracker(seed_config(confirm_length=2), KALMAN)
    frames = [three_targets(k) for k in range(4)]
    # target 1's detection jumps far against its motion: the Hungarian still pairs it (one
    # detection per target), but its cost exceeds c_t = 0.3 (rule 2)
    frames.append([box(-100, 20)] + three_targets(4)[1:])
    results = run(tracker, frames)
    last = results[-1]
    assert state_of(last, 1) == COASTING and last.tracks.misses[0] == 1
    assert state_of(last, 4) == TENTATIVE                       # the far detection starts a new track
    assert state_of(last, 2) == CONFIRMED and state_of(last, 3) == CONFIRMED


def test_crossing_targets_keep_their_ids():
    # Four targets in two crossing pairs (seed §4.1: crossing within frames 613-715 keeps the IDs).
    tracker = MultiTargetTracker(seed_config(confirm_length=3), KALMAN)
    frames = []
    for k in range(40):
        frames.append([box(100 + 4 * k, 100 + 2 * k), box(260 - 4 * k, 100 + 2 * k),
                       box(100 + 4 * k, 300 - 2 * k), box(260 - 4 * k, 300 - 2 * k)])
    results = run(tracker, frames)
    final = results[-1].tracks.visible()
    assert sorted(final.ids.tolist()) == [1, 2, 3, 4]
    order = np.argsort(final.ids)
    centres = final.boxes[order, :2] + final.boxes[order, 2:] / 2
    np.testing.assert_allclose(centres, [[256, 178], [104, 178], [256, 222], [104, 222]], atol=2.0)
    np.testing.assert_allclose(final.velocities[order], [[40, 20], [-40, 20], [40, -20], [-40, -20]], atol=3.0)


def test_ids_never_reused_after_reset_on_backward_stamp():
    tracker = MultiTargetTracker(AssociationConfig(confirm_length=1, gate="mahalanobis"), KALMAN)
    tracker.step(1.0, [box(10, 10)])
    r = tracker.step(1.1, [box(11, 10)])
    assert r.tracks.ids.tolist() == [1] and not r.reset
    r = tracker.step(0.2, [box(11, 10)])                        # looped bag: stamps went backwards
    assert r.reset and r.tracks.ids.tolist() == [2]
    r = tracker.step(100.0, [box(11, 10)])                      # jump beyond max_frame_gap
    assert r.reset and r.tracks.ids.tolist() == [3]
    r = tracker.step(100.0, [box(12, 10)])                      # repeated stamp: default interval
    assert not r.reset and r.tracks.ids.tolist() == [3]


# -- bad input --------------------------------------------------------------------------------
def test_nan_inf_and_negative_size_rejected_and_counted():
    tracker = MultiTargetTracker(seed_config(confirm_length=1), KALMAN)
    boxes = np.array([box(10, 10), [np.nan, 0, 5, 5], [0, np.inf, 5, 5], [0, 0, -5, 5], [0, 0, 5, 0]])
    r = tracker.step(0.0, boxes, scores=[0.9, 0.9, 0.9, 0.9, 0.9])
    assert r.rejected == 4
    assert len(r.tracks) == 1
    r = tracker.step(0.1, [box(10, 10)], scores=[np.nan])
    assert r.rejected == 1
    with pytest.raises(AssociationError):
        tracker.step(0.2, np.zeros((3, 5)))
    with pytest.raises(AssociationError):
        tracker.step(0.2, np.zeros((2, 4)), scores=[1.0])
    with pytest.raises(AssociationError):
        tracker.step(float("nan"), np.zeros((0, 4)))


# -- beyond the seed --------------------------------------------------------------------------
def test_defaults_are_the_measured_improvements_and_seed_preset_is_the_seed():
    seed, default = seed_config(), AssociationConfig()
    assert (seed.gate, seed.cost_gate, seed.confirm_length, seed.max_misses) == ("cost", 0.3, 15, 10)
    assert not seed.second_pass and seed.iou_weight == 0 and seed.reacquire_frames == 0
    assert not (seed.cascade or seed.confirm_first_frame) and seed.coast_output_frames > seed.max_misses
    assert default.gate == "mahalanobis" and default.max_misses == 40 and default.coast_output_frames == 2
    assert KalmanConfig().missed_update == "none"               # growing gates (issue 13)


def test_lone_target_needs_absolute_gate():
    # Seed normalisation: with one target and one detection c = θ/maxθ + r/maxr = 0 + 1 > c_t.
    frames = [[box(50 + 2 * k, 50)] for k in range(6)]
    seed = run(MultiTargetTracker(seed_config(confirm_length=2), KALMAN), frames)
    assert seed[1].tracks.ids.tolist() == [1, 2]                 # the pair of frames 0-1 is refused
    gated = run(MultiTargetTracker(AssociationConfig(confirm_length=2, gate="mahalanobis"), KALMAN), frames)
    assert gated[-1].tracks.ids.tolist() == [1] and state_of(gated[-1], 1) == CONFIRMED


def test_far_clutter_does_not_rescale_with_mahalanobis_gate():
    cfg = AssociationConfig(confirm_length=2, gate="mahalanobis")
    tracker = MultiTargetTracker(cfg, KALMAN)
    frames = [three_targets(k) for k in range(5)] + [three_targets(5) + [box(5000, 5000)]]
    results = run(tracker, frames)
    assert all(state_of(results[-1], i) == CONFIRMED for i in (1, 2, 3))
    assert state_of(results[-1], 4) == TENTATIVE


def test_second_pass_keeps_track_on_low_score_detection():
    frames = [three_targets(k) for k in range(6)]
    scores = [[0.9, 0.9, 0.9]] * 5 + [[0.2, 0.9, 0.9]]         # target 1 weakly detected in the last frame

    def go(second_pass):
        tracker = MultiTargetTracker(AssociationConfig(confirm_length=2, gate="mahalanobis",
                                                       second_pass=second_pass, high_score=0.5), KALMAN)
        return [tracker.step(k / FPS, np.array(b), scores=s) for k, (b, s) in enumerate(zip(frames, scores))][-1]

    with_pass, without = go(True), go(False)
    assert state_of(with_pass, 1) == CONFIRMED and with_pass.tracks.misses[0] == 0
    assert with_pass.tracks.ids.max() == 3                       # low-score detections start no track
    assert state_of(without, 1) == CONFIRMED                     # without: an ordinary detection


def test_reacquire_lost_track_keeps_id():
    frames = [three_targets(k, dx=0.0) for k in range(4)] + [three_targets(0, dx=0.0)[1:]] * 4 \
        + [three_targets(0, dx=0.0)] * 2

    def go(reacquire):
        cfg = AssociationConfig(confirm_length=2, max_misses=2, gate="mahalanobis", reacquire_frames=reacquire)
        return run(MultiTargetTracker(cfg, KALMAN), frames)

    seed = go(0)
    assert state_of(seed[8], 1) is None and state_of(seed[8], 4) == TENTATIVE   # a new ID
    kept = go(10)
    assert state_of(kept[7], 1) == LOST and len(kept[7].tracks.visible()) == 2
    assert state_of(kept[8], 1) == CONFIRMED and kept[-1].tracks.ids.max() == 3


def test_iou_term_decides_between_equally_near_detections():
    # Two detections equally far from the prediction's centre: one the size of the target, one
    # twice as large. Without the IoU term the distance/angle cost cannot tell them apart.
    def go(weight):
        cfg = AssociationConfig(confirm_length=1, iou_weight=weight, second_pass=False)
        tracker = MultiTargetTracker(cfg, KalmanConfig(measurement_noise=5.0, size_gain=1.0))
        for k in range(4):
            tracker.step(k / FPS, [box(100, 100, 20, 20)])
        big, same = box(100, 104, 40, 40), box(100, 96, 20, 20)
        r = tracker.step(4 / FPS, [big, same])
        return r.tracks.boxes[r.tracks.ids == 1][0]
    assert go(3.0)[2] == pytest.approx(20.0, abs=0.5)           # stayed with the same-size box
    assert go(0.0)[2] == pytest.approx(40.0, abs=0.5)           # order decides: the first, larger one


def test_trail_records_history():
    cfg = AssociationConfig(confirm_length=1, history_length=3, tentative_max_misses=0, gate="mahalanobis")
    tracker = MultiTargetTracker(cfg, KALMAN)
    run(tracker, [[box(10 + k, 10)] for k in range(5)])
    trail = tracker.trail(1)
    assert len(trail) == 3                                      # max(history_length, l_t + misses + 1)
    np.testing.assert_allclose(trail[:, 0], [3, 4, 5])
    assert trail[-1, 0] == 5 and trail[-1, 5] == 1.0
    assert len(tracker.trail(99)) == 0


def test_empty_frames_coast_then_delete():
    tracker = MultiTargetTracker(seed_config(confirm_length=2, max_misses=2), KALMAN)
    run(tracker, [three_targets(k) for k in range(3)])
    states = [tracker.step((3 + k) / FPS, np.zeros((0, 4))).tracks.states.tolist() for k in range(3)]
    assert states[0] == [COASTING] * 3 and states[1] == [COASTING] * 3
    assert states[2] == []                                      # 3 misses > f_t = 2: all deleted


# -- output policy, growing gates, score scale (issue 13) -------------------------------------
def _walker(frames_seen, hide, frames_after, speed=40.0, y=100.0):
    """One target moving right at ``speed`` px/s, detected, hidden ``hide`` frames, detected again."""
    seq = [[box(20 + speed * k / FPS, y)] for k in range(frames_seen)]
    seq += [[] for _ in range(hide)]
    k0 = frames_seen + hide
    seq += [[box(20 + speed * (k0 + k) / FPS, y)] for k in range(frames_after)]
    return seq


def test_coasting_is_published_only_while_trusted_and_every_state_is_kept():
    cfg = AssociationConfig(coast_output_frames=2, coast_output_std=1e6, max_misses=30)
    results = run(MultiTargetTracker(cfg, KalmanConfig(missed_update="none")), _walker(6, 5, 3))
    assert [state_of(r, 1) for r in results[6:11]] == [COASTING, COASTING, PREDICTED, PREDICTED, PREDICTED]
    assert [len(r.tracks.visible()) for r in results[6:11]] == [1, 1, 0, 0, 0]   # published: states 1, 2
    assert len(results[9].tracks) == 1                                           # but still held
    assert state_of(results[11], 1) == CONFIRMED and len(results[11].tracks.visible()) == 1   # same id back
    # the uncertainty test alone: a tight std bound stops publication before the frame limit
    tight = AssociationConfig(coast_output_frames=100, coast_output_std=0.01, max_misses=30)
    results = run(MultiTargetTracker(tight, KalmanConfig(missed_update="none")), _walker(6, 3, 0))
    assert state_of(results[6], 1) == PREDICTED


def test_coasting_gate_grows_without_collapsing():
    # kalman.missed_update='none': the innovation variance grows with every missed frame; the seed's
    # update with its own prediction makes it shrink (the gate that shut out reappearing targets).
    for mode, grows in (("none", True), ("prediction", False)):
        tracker = MultiTargetTracker(AssociationConfig(max_misses=50), KalmanConfig(missed_update=mode))
        run(tracker, _walker(8, 0, 0))
        s = []
        for k in range(10):
            tracker.step((8 + k) / FPS, np.zeros((0, 4)))
            s.append(float(tracker.bank.innovation_variance()[0]))
        assert (np.diff(s) > 0).all() == grows
        assert (s[-1] > 4 * s[0]) == grows


@pytest.mark.parametrize("seed", range(5))
def test_reacquired_after_long_hide_with_a_speed_change(seed):
    # A target hidden 40 frames (4 s) reappears 30-45 px off its constant-velocity prediction:
    # with growing gates it gets its old id back; with the collapsed covariance it is a new target.
    rng = np.random.default_rng(seed)
    offset = rng.uniform(30.0, 45.0)
    seen = [[box(20 + 40.0 * k / FPS, 100)] for k in range(10)]
    after = [[box(20 + 40.0 * (50 + k) / FPS + offset, 100 + rng.normal(0, 0.5))] for k in range(5)]
    frames = seen + [[] for _ in range(40)] + after
    ids = {}
    for mode in ("none", "prediction"):
        results = run(MultiTargetTracker(AssociationConfig(max_misses=80), KalmanConfig(missed_update=mode)), frames)
        ids[mode] = results[-1].tracks.visible().ids.tolist()
    assert ids["none"] == [1]
    assert ids["prediction"] != [1]


def test_percent_scores_with_score_scale_match_fractions():
    rng = np.random.default_rng(3)
    frames = [np.array([box(20 + 4 * k, 50), box(200, 80 + 2 * k)]) for k in range(12)]
    scores = [rng.uniform(0.3, 0.95, 2) for _ in range(12)]
    cfg = dict(min_score=0.4, high_score=0.6)
    fraction = MultiTargetTracker(AssociationConfig(**cfg))
    percent = MultiTargetTracker(AssociationConfig(**cfg, score_scale=100.0))
    raw = MultiTargetTracker(AssociationConfig(**cfg))                       # percent read as fractions
    for k, (b, s) in enumerate(zip(frames, scores)):
        a = fraction.step(k / FPS, b, s).tracks
        p = percent.step(k / FPS, b, 100 * s).tracks
        r = raw.step(k / FPS, b, 100 * s).tracks
        assert a.ids.tolist() == p.ids.tolist() and np.allclose(a.boxes, p.boxes) and np.allclose(a.scores, p.scores)
    assert len(a.visible()) and (r.scores > 1).all()                         # thresholds defeated without it


def test_first_frame_detections_start_confirmed():
    frames = [[box(20, 50), box(200, 50)], [box(24, 50), box(204, 50)], [box(28, 50), box(208, 50), box(400, 90)]]
    on = run(MultiTargetTracker(AssociationConfig(confirm_first_frame=True, confirm_length=3)), frames)
    off = run(MultiTargetTracker(AssociationConfig(confirm_first_frame=False, confirm_length=3)), frames)
    assert len(on[0].tracks.visible()) == 2 and len(off[0].tracks.visible()) == 0
    assert state_of(on[2], 3) == TENTATIVE                      # later newcomers still need l_t detections


def test_published_boxes_cut_to_the_frame_as_a_target_leaves_it():
    """With frame_width / frame_height a target driving out of the image is published with its visible part
    (the box a detector and the ground truth give it), the filter keeps predicting the whole box, and once
    nothing of it is left in the image it is not published (state 4); without them boxes are not cut."""
    frames = [[box(60.0 + 10.0 * k, 50.0, 20.0, 10.0)] for k in range(5)] + [[]] * 5    # image 100 x 80
    settings = dict(coast_output_frames=5, coast_output_std=1e6)
    cut = run(MultiTargetTracker(AssociationConfig(frame_width=100, frame_height=80, **settings)), frames)
    whole = run(MultiTargetTracker(AssociationConfig(**settings)), frames)
    for a, b in zip(cut, whole):
        assert len(a.tracks) == len(b.tracks) == 1
        x, y, w, h = a.tracks.boxes[0]
        assert (x >= 0 and y >= 0 and x + w <= 100 + 1e-9 and y + h <= 80 + 1e-9) or a.tracks.states[0] == PREDICTED
        assert b.tracks.boxes[0][2] == pytest.approx(20.0, abs=2.0)      # the filter's box stays whole
    assert cut[4].tracks.boxes[0][2] == pytest.approx(10.0, abs=3.0)      # centre near 100: half of it left
    assert cut[4].tracks.states[0] == CONFIRMED
    assert cut[-1].tracks.states[0] == PREDICTED and whole[-1].tracks.states[0] == COASTING


# -- two thresholds (ByteTrack): low-confidence detections --------------------------------------
def _moving(k):
    return [box(50 + 4 * k, 60)]


def _two_stage(low_confidence, frames=30, hidden=range(10, 20), **extra):
    """One vehicle moving 4 px a frame; in ``hidden`` frames its detection comes only flagged low-confidence."""
    cfg = AssociationConfig(confirm_length=3, gate="mahalanobis", max_misses=3, coast_output_frames=2,
                            low_confidence=low_confidence, **extra)
    tracker = MultiTargetTracker(cfg, KALMAN)
    return [tracker.step(k / FPS, np.array(_moving(k)), scores=[0.9], low=[k in hidden]) for k in range(frames)]


def test_low_confidence_detections_keep_a_track_and_its_id_only_with_the_second_stage():
    with_stage, without = _two_stage(True), _two_stage(False)
    assert [sorted(r.tracks.visible().ids.tolist()) for r in with_stage[3:]] == [[1]] * 27
    assert all(state_of(r, 1) == CONFIRMED for r in with_stage[10:20])
    # without: the track coasts, is dropped after max_misses and the vehicle comes back under a new id
    assert state_of(without[12], 1) == PREDICTED and state_of(without[19], 1) in (LOST, None)
    assert 1 not in without[-1].tracks.visible().ids.tolist() and len(without[-1].tracks.visible()) == 1


def test_second_pass_min_hits_leaves_young_targets_out_of_the_second_pass():
    # frames 0-9 give the track 10 hits before its detections come flagged
    kept, young = _two_stage(True, second_pass_min_hits=10), _two_stage(True, second_pass_min_hits=11)
    assert all(state_of(r, 1) == CONFIRMED for r in kept[10:20])
    assert state_of(young[12], 1) == PREDICTED and 1 not in young[-1].tracks.visible().ids.tolist()


def test_a_low_confidence_detection_never_starts_a_track():
    tracker = MultiTargetTracker(AssociationConfig(low_confidence=True, confirm_length=1), KALMAN)
    for k in range(8):                            # confirm_length 1 and first-frame activation: none would wait
        result = tracker.step(k / FPS, np.array([box(300, 300), box(50 + 4 * k, 60)]), scores=[0.95, 0.99],
                              low=[True, True])
        assert len(result.tracks) == 0
    result = _two_stage(True, hidden=range(0, 30))[-1]      # the vehicle only ever flagged: no track either
    assert len(result.tracks) == 0


def test_second_pass_iou_gate_refuses_a_low_confidence_detection_off_the_track():
    def last(offset, min_iou):
        cfg = AssociationConfig(confirm_length=2, gate="mahalanobis", low_confidence=True, second_pass_iou=min_iou)
        tracker = MultiTargetTracker(cfg, KALMAN)
        for k in range(6):
            shifted = box(50 + 4 * k + (offset if k == 5 else 0), 60)
            result = tracker.step(k / FPS, np.array([shifted]), low=[k == 5])
        return result
    assert state_of(last(6.0, 0.0), 1) == CONFIRMED             # the Mahalanobis gate alone takes it
    assert last(6.0, 0.5).tracks.misses.tolist() == [1]        # 6 px off a 10-px box: IoU 0.25 < 0.5, a miss
    assert state_of(last(1.0, 0.5), 1) == CONFIRMED             # IoU 0.82


def test_low_confidence_flags_must_match_the_boxes():
    with pytest.raises(AssociationError):
        MultiTargetTracker().step(0.0, np.array([box(5, 5)]), low=[True, False])


def test_predicted_tracks_at_a_skipped_frame_change_nothing_and_follow_eq_6():
    """A frame the detector skipped: every filter predicted to its stamp, states published -> coasting, and the
    tracker exactly as before (the next step gives the same tracks as a tracker never asked)."""
    frames = [[box(50 + 4 * k, 50, 40, 40), box(150, 80 + 3 * k, 40, 40)] for k in range(6)]
    asked, plain = MultiTargetTracker(kalman=KALMAN), MultiTargetTracker(kalman=KALMAN)
    assert asked.predicted(0.0) is None                                   # nothing stepped yet
    run(asked, frames[:5])
    run(plain, frames[:5])
    now = asked.tracks()
    between = asked.predicted(4.5 / FPS)
    T = 0.5 / FPS
    np.testing.assert_allclose(between.boxes[:, :2], now.boxes[:, :2] + T * now.velocities)   # x <- x + T v
    np.testing.assert_allclose(between.boxes[:, 2:], now.boxes[:, 2:])
    assert (now.states == CONFIRMED).all() and (between.states == COASTING).all()
    assert (between.misses == now.misses).all() and (between.ids == now.ids).all()
    assert asked.predicted(4.0 / FPS) is None and asked.predicted(4.0 / FPS + 10.0) is None   # not after / a reset
    with pytest.raises(AssociationError):
        asked.predicted(float("nan"))
    after, expected = asked.step(5 / FPS, np.array(frames[5])), plain.step(5 / FPS, np.array(frames[5]))
    for name in ("ids", "boxes", "velocities", "states", "misses"):
        np.testing.assert_array_equal(getattr(after.tracks, name), getattr(expected.tracks, name))
    np.testing.assert_array_equal(asked.bank.cov, plain.bank.cov)


def test_predicted_tracks_unpublish_an_untrusted_prediction():
    """fill_output_std applies to the predicted position of a target detected on the last frame: one whose position
    std would exceed it at the skipped frame is not published there (state 4); tentative targets stay tentative."""
    cfg = AssociationConfig(fill_output_std=0.1, confirm_first_frame=False, confirm_length=2)
    tracker = MultiTargetTracker(cfg, KALMAN)
    run(tracker, [[box(50 + 4 * k, 50, 40, 40)] for k in range(3)] + [[box(62, 50, 40, 40), box(300, 300, 40, 40)]])
    near, far = tracker.predicted(3.2 / FPS), tracker.predicted(3 / FPS + 2.0)
    assert near.states.tolist() == [COASTING, TENTATIVE]
    assert far.states.tolist() == [PREDICTED, TENTATIVE]                  # 2 s on: std grew past 0.1 box heights


def test_a_skipped_frame_holds_a_detected_target_to_fill_output_std_and_a_missed_one_to_coast_output_std():
    """Half a second after the last frame (position std 0.49 box heights for the target detected there, 0.60 for the
    one missed there): fill_output_std 1 keeps the detected target published, 0.1 does not; the missed one is held to
    coast_output_std 0.3 either way. Nothing the frames with detections publish changes."""
    frames = [[box(50 + 4 * k, 50, 40, 40), box(300, 300 + 4 * k, 40, 40)] for k in range(3)] + [[box(62, 50, 40, 40)]]
    for fill, expected in ((1.0, [COASTING, PREDICTED]), (0.1, [PREDICTED, PREDICTED])):
        cfg = AssociationConfig(coast_output_std=0.3, fill_output_std=fill, coast_output_frames=5,
                                confirm_first_frame=False, confirm_length=2)
        tracker = MultiTargetTracker(cfg, KALMAN)
        run(tracker, frames)
        assert tracker.tracks().states.tolist() == [CONFIRMED, COASTING] and tracker.misses.tolist() == [0, 1]
        assert tracker.predicted(3 / FPS + 0.5).states.tolist() == expected, fill
