"""Multi-target association: seed 003 §3.2-3.3 (eqs. 7-13) around the Kalman filters (no ROS here).

One frame (:meth:`MultiTargetTracker.step`):

1. check the detections (NaN, inf, non-positive size are dropped and counted);
2. T from the time stamps; predict every target (eqs. 5-6, :mod:`kalman`);
3. the cost of eqs. 8-10: ``c_ij = θ_ij / max θ + r_ij / max r`` where r_ij is the distance from
   target i's predicted position to detection j and θ_ij the angle between target i's velocity
   and the vector from target i's (last estimated) position to detection j;
4. padding with zero rows or columns to a square matrix (eqs. 11-12) and the Hungarian algorithm
   (eq. 13, ``scipy.optimize.linear_sum_assignment``);
5. track management of §3.3: an assignment with ``c_ij > c_t`` counts as none (rule 2); a target
   without a detection is updated with its prediction and its missed counter grows (rule 1), and
   is deleted when the counter exceeds ``f_t``; an assigned target is updated with its detection
   and its counter reset (rule 3); a detection assigned to no target starts a tentative track
   that becomes a target when its length reaches ``l_t`` (rule 4) and is otherwise dropped as a
   false alarm. IDs are never reused.

Choices the seed leaves open (named here, in the config, and measured in ``bench/association.py``):

* *No velocity yet.* A target whose speed is below ``still_speed`` (a new target, or one standing
  still) gives no direction evidence, so its θ_ij is 0 for every detection: its cost is the
  distance term alone. Likewise θ = 0 when the detection sits exactly on the target.
* *Track length* (rule 4) is the number of frames with an assigned detection; a tentative track
  obeys rule 1 with its own limit ``tentative_max_misses`` (``f_t`` in the seed preset, as the seed
  does not distinguish).
* *Degenerate maxima.* Where max θ or max r over the matrix is 0, that term is 0.

Beyond the seed, each selectable (``bench/association.py`` measures each one):

* ``gate="mahalanobis"``: the acceptance test of rule 2 becomes the absolute test
  ``d² = (z − Hx̂)ᵀ S⁻¹ (z − Hx̂) ≤ mahalanobis_gate`` from the filter's innovation covariance S;
  pairs outside it are excluded before normalising, so one far clutter detection cannot rescale
  every cost. (With the seed's normalisation a lone target and a lone detection always cost
  1 + 1 = 2 > c_t and are never associated; the absolute gate removes that.)
* ``iou_weight``: adds ``w (1 − IoU)`` between the predicted box and the detection to the cost.
* ``second_pass``: ByteTrack's idea (Zhang et al., ECCV 2022): detections with score below
  ``high_score`` are kept out of the first association and offered in a second one to the
  targets left without a detection; they never start tracks. ``low_confidence``: so do the detections a
  detector flags ``low_confidence`` (groups its verifier scored below its threshold, ``low_confidence_band``),
  whatever their score; off, flagged detections are dropped. ``second_pass_iou``: the second pass also
  needs this IoU of predicted box and detection (ByteTrack gates its low-score boxes by IoU).
* ``reacquire_frames``: a target deleted by rule 1 is kept as *lost* this many frames more; a new
  detection near its prediction (within ``reacquire_radius`` box diagonals) re-confirms it with
  its old ID instead of starting a tentative track.
* Output policy (issue 13). A missed target is *published* (state 2, coasting) only while its
  prediction is trusted: at most ``coast_output_frames`` misses and a position std
  ``sqrt(P_xx)`` of at most ``coast_output_std`` box heights. Past that it coasts unpublished
  (state 4): still predicted and associated, so it comes back with its ID, but not output, so a
  drifting prediction is not a false positive. On a frame the detector skipped
  (:meth:`MultiTargetTracker.predicted`) a target detected on its last frame has its own limit,
  ``fill_output_std``: nobody looked for it there, so a wider uncertainty is no evidence that it
  has gone. Every state stays in :class:`Tracks` (and the node's ``tracks`` table);
  :meth:`Tracks.visible` is what is published (states 1 and 2).
* Growing gates (issue 13, ``kalman.missed_update="none"``): a missed target is only predicted,
  so its covariance and with it the Mahalanobis gate grow with every missed frame, and a target
  reappearing after a long hide off its constant-velocity path is still inside its own gate. The
  seed's rule 1 (update with the prediction itself) shrinks the covariance instead: after 10
  misses the gate is tighter than after one detection, and the target is re-found only if it
  comes back exactly where predicted.
* ``cascade``: the first pass in two stages, recently seen targets first, targets coasting
  unpublished on what they left (DeepSORT's matching cascade, two levels).
* ``confirm_first_frame``: detections of the first frame of a stream (or after a reset) start
  confirmed targets (ByteTrack's first-frame activation), so a sequence's first frame is not lost.
* ``score_scale``: scores are divided by it first (100 for a detector that reports percent); the
  thresholds ``min_score`` and ``high_score`` are fractions.

Defaults. :func:`seed_config` is seed 003 as written (c_t gate, l_t = 15, no improvement;
``config/association_seed.yaml``). With the seed's gate every sequence of the benchmark scored
MOTA near 0 (the matrix-normalised cost of a true pair rarely stays below c_t = 0.3 once
detections jitter). The dataclass defaults were chosen by leave-one-sequence-out over TUD-Campus,
airport-2 and three synthetic UAV scenes (``bench/association.py``, held-out scores in
``bench/results/association.md``): the Mahalanobis gate, l_t = 2 with first-frame activation,
the IoU term, the second pass, coasting published at most 2 frames, growing gates, f_t = 40.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from aircraft_docking_tracker.config import param, validate
from aircraft_docking_tracker.geometry import box_iou
from multi_target_tracker.kalman import KalmanBank, KalmanConfig

TENTATIVE, CONFIRMED, COASTING, LOST, PREDICTED = 0, 1, 2, 3, 4
#: What each state means (the ``state`` field of the node's ``tracks`` table).
STATE_NAMES = {TENTATIVE: "tentative (rule 4, not yet a target)", CONFIRMED: "confirmed (detected this frame)",
               COASTING: "coasting, published (missed, prediction still trusted)",
               LOST: "lost (past f_t, kept only for re-acquisition)",
               PREDICTED: "coasting, not published (missed, prediction no longer trusted; still associated)"}
#: Cost of a pair that a gate excludes; larger than any real cost so the Hungarian avoids it.
EXCLUDED = 1e6


class AssociationError(ValueError):
    """Input the association core cannot use (wrong array shapes)."""


@dataclass
class AssociationConfig:
    """§3.3 thresholds (seed §4.1 values) and the selectable improvements."""

    max_misses: int = param(40, "f_t: a target is deleted when its missed-frame counter exceeds this (§3.3 rule 1)",
                            low=0, high=100000)
    cost_gate: float = param(0.3, "c_t: an assignment costing more counts as no detection (§3.3 rule 2)",
                             low=0.0, high=10.0)
    confirm_length: int = param(2, "l_t: a tentative track becomes a target at this many detections (§3.3 rule 4)",
                                low=1, high=100000)
    tentative_max_misses: int = param(1, "a tentative track is dropped when its missed counter exceeds this",
                                      low=0, high=100000)
    angle_weight: float = param(1.0, "weight of the direction term θ/max θ in the cost (eq. 10: 1)",
                                low=0.0, high=100.0)
    still_speed: float = param(1.0, "below this speed [px/s] a target has no direction: θ = 0 for it",
                               low=0.0, high=1e6)
    score_scale: float = param(1.0, "detection scores are divided by this first: 1 for scores in [0, 1], 100 for "
                               "percent; min_score and high_score are fractions", low=1e-9, high=1e9)
    min_score: float = param(0.0, "detections scoring below this fraction are ignored", low=0.0, high=1.0)
    max_frame_gap: float = param(5.0, "a stamp jumping forward more than this [s] (or backwards) resets all tracks",
                                 low=0.0, high=1e9)
    default_frame_interval: float = param(1.0 / 30.0, "T [s] used when stamps do not advance", low=1e-6, high=10.0)
    gate: str = param("mahalanobis", "acceptance: 'cost' is c_ij <= c_t (seed rule 2); 'mahalanobis' is "
                      "d² <= mahalanobis_gate with normalisation over the gated pairs only",
                      choices=("cost", "mahalanobis"))
    mahalanobis_gate: float = param(13.8, "χ² threshold of the Mahalanobis gate (2 dof; 9.21: 99 per cent, 13.8: "
                                    "99.9 per cent of true pairs pass)",
                                    low=0.0, high=1e6)
    iou_weight: float = param(3.0, "weight of (1 - IoU) of predicted box and detection added to the cost",
                              low=0.0, high=100.0)
    second_pass: bool = param(True, "ByteTrack: associate detections scoring below high_score in a second pass")
    high_score: float = param(0.6, "score (a fraction) splitting first-pass from second-pass detections",
                              low=0.0, high=1.0)
    low_confidence: bool = param(False, "detections the detector flags low_confidence (verifier log odds under its "
                                 "threshold; the detector's low_confidence_band) join the second pass: they only "
                                 "extend confirmed or coasting targets left without a detection, never start a "
                                 "track; false: they are dropped (ByteTrack's two thresholds)")
    second_pass_iou: float = param(0.0, "a second-pass pair also needs at least this IoU of the target's predicted "
                                   "box and the detection (ByteTrack's IoU gate for its low-score boxes); 0: the "
                                   "first pass's gate only", low=0.0, high=1.0)
    second_pass_min_hits: int = param(0, "only targets with at least this many assigned detections (rule 4's "
                                      "track length) take part in the second pass; 0: every confirmed or coasting "
                                      "target", low=0, high=100000)
    reacquire_frames: int = param(0, "frames a deleted target is kept as lost for re-confirmation (0: seed, off)",
                                  low=0, high=100000)
    reacquire_radius: float = param(1.0, "re-confirmation radius around a lost target's prediction [box diagonals]",
                                    low=0.0, high=100.0)
    coast_output_frames: int = param(2, "a missed target is published (state 2) at most this many frames after "
                                     "its last detection; then it coasts unpublished (state 4)", low=0, high=100000)
    coast_output_std: float = param(0.1, "... and only while its position std sqrt(P_xx) is at most this many box "
                                    "heights (needs kalman.missed_update='none': otherwise P shrinks while coasting)",
                                    low=0.0, high=1e6)
    fill_output_std: float = param(0.1, "on a frame the detector skipped (predicted(), the node's "
                                   "output.fill_skipped_frames) a target detected on its last frame is published while "
                                   "its position std is at most this many box heights (a missed one: coast_output_std)",
                                   low=0.0, high=1e6)
    cascade: bool = param(False, "first pass in two stages: targets seen recently first, then those coasting "
                          "unpublished (state 4) on the detections left (DeepSORT's matching cascade, two levels)")
    confirm_first_frame: bool = param(True, "detections of the first frame (or the first after a reset) start "
                                      "confirmed targets (ByteTrack's first-frame activation)")
    history_length: int = param(30, "positions kept per track (trails; tentative history for offline backfill)",
                                low=1, high=100000)
    frame_width: int = param(0, "image width [px]: published boxes are cut to the image (a target leaving it "
                             "keeps its visible part, as a detector and the ground truth box it; one wholly "
                             "outside is not published, state 4); 0: boxes not cut", low=0, high=100000)
    frame_height: int = param(0, "image height [px] for the cut (with frame_width; 0: not cut)", low=0, high=100000)


def seed_config(**overrides) -> AssociationConfig:
    """Seed 003 §3 as written: c_t gate on the matrix-normalised cost, l_t = 15, f_t = 10, nothing added."""
    values = dict(gate="cost", cost_gate=0.3, confirm_length=15, max_misses=10, tentative_max_misses=10,
                  angle_weight=1.0, iou_weight=0.0, second_pass=False, reacquire_frames=0, cascade=False,
                  confirm_first_frame=False, coast_output_frames=100000, coast_output_std=1e6,
                  fill_output_std=1e6)
    values.update(overrides)
    return validate(AssociationConfig(**values))


@dataclass
class Tracks:
    """The targets after one frame, one entry per track (all states), in the filter bank's order."""

    ids: np.ndarray          # int
    boxes: np.ndarray        # (N, 4) x, y, w, h [px], top-left corner
    velocities: np.ndarray   # (N, 2) [px/s]
    scores: np.ndarray       # score of the last assigned detection
    class_ids: np.ndarray
    ages: np.ndarray         # frames since the track started
    hits: np.ndarray         # frames with an assigned detection (track length of rule 4)
    misses: np.ndarray       # missed-frame counter of rule 1
    states: np.ndarray       # TENTATIVE, CONFIRMED, COASTING, LOST

    def __len__(self) -> int:
        return len(self.ids)

    def select(self, mask: np.ndarray) -> "Tracks":
        return Tracks(**{k: v[mask] for k, v in self.__dict__.items()})

    def visible(self, include_tentative: bool = False, include_coasting: bool = True) -> "Tracks":
        """Tracks to publish: confirmed, optionally trusted coasting and tentative ones; never state 3 or 4."""
        mask = self.states == CONFIRMED
        if include_coasting:
            mask |= self.states == COASTING
        if include_tentative:
            mask |= self.states == TENTATIVE
        return self.select(mask)


@dataclass
class FrameResult:
    tracks: Tracks
    rejected: int = 0                 # detections dropped as invalid (NaN, inf, size <= 0)
    reset: bool = False               # stamps went backwards or jumped: every track was dropped
    confirmed_now: list = field(default_factory=list)  # ids that became targets in this frame (rule 4)
    frame_index: int = 0              # how many frames the core has seen, this one included


# --------------------------------------------------------------------------------------------
# Eqs. 8-12: the cost matrix and its padding
# --------------------------------------------------------------------------------------------
# The cost is computed for a list of (target i, detection j) pairs: every pair for the seed, the
# pairs inside the Mahalanobis gate otherwise, so that a frame of a thousand targets stays sparse.
def all_pairs(m: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every (i, j) of an m x n matrix, row by row."""
    i, j = np.divmod(np.arange(m * n), n)
    return i, j


def angles(origins: np.ndarray, velocities: np.ndarray, points: np.ndarray, still_speed: float) -> np.ndarray:
    """θ_ij of eq. 8 per pair: angle [rad] between the target's velocity and the vector from the
    target (``origins``) to the detection (``points``).

    θ = 0 for a target slower than ``still_speed`` (no direction yet) and for a point on the target.
    """
    u = points - origins
    speed = np.hypot(velocities[:, 0], velocities[:, 1])
    norms = np.hypot(u[:, 0], u[:, 1]) * speed
    dot = u[:, 0] * velocities[:, 0] + u[:, 1] * velocities[:, 1]
    cos = dot / np.where(norms > 0, norms, 1.0)        # dot is 0 where a norm is 0: θ = π/2 there ...
    cos[norms == 0] = 1.0                              # ... so set θ = 0 explicitly
    theta = np.arccos(np.clip(cos, -1.0, 1.0, out=cos))
    theta[speed < still_speed] = 0.0
    return theta


def distances(predicted: np.ndarray, points: np.ndarray) -> np.ndarray:
    """r_ij of eq. 9 per pair: distance from the target's predicted position to the detection."""
    return np.hypot(points[:, 0] - predicted[:, 0], points[:, 1] - predicted[:, 1])


def normalise_by_max(values: np.ndarray) -> np.ndarray:
    """Eqs. 8-9: divide by the maximum over the matrix (the pairs given); 0 where the maximum is 0."""
    top = float(values.max()) if values.size else 0.0
    return values / top if top > 0 else np.zeros_like(values)


def seed_cost(origins, predicted, velocities, points, still_speed, angle_weight: float = 1.0) -> np.ndarray:
    """Eq. 10 per pair: ``c_ij = θ_ij / max θ + r_ij / max r``, maxima over the pairs given.

    ``angle_weight`` scales the direction term (1 in the seed).
    """
    r = distances(predicted, points)
    if angle_weight == 0:
        return normalise_by_max(r)
    theta = angles(origins, velocities, points, still_speed)
    return angle_weight * normalise_by_max(theta) + normalise_by_max(r)


def mahalanobis_squared(predicted: np.ndarray, s: np.ndarray, points: np.ndarray) -> np.ndarray:
    """d² = (z − Hx̂)ᵀ S⁻¹ (z − Hx̂) per pair, with S = s I the pair's innovation covariance."""
    dx, dy = points[:, 0] - predicted[:, 0], points[:, 1] - predicted[:, 1]
    return (dx * dx + dy * dy) / s


def gated_pairs(predicted: np.ndarray, s: np.ndarray, points: np.ndarray, gate: float,
                brute_force_below: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """The (i, j) pairs with d²_ij <= ``gate`` (``s``: innovation variances of the targets).

    Candidates come from every pair for small matrices, else from a KD-tree around each predicted
    position with the gate's radius ``sqrt(gate · s_i)``; the exact test follows.
    """
    m, n = len(predicted), len(points)
    if m * n <= brute_force_below:
        i, j = all_pairs(m, n)
    else:
        near = cKDTree(points).query_ball_point(predicted, r=np.sqrt(gate * s) * (1 + 1e-9))
        i = np.repeat(np.arange(m), [len(c) for c in near])
        j = np.fromiter((k for c in near for k in c), dtype=np.intp, count=len(i))
    d2 = mahalanobis_squared(predicted[i], s[i], points[j])
    keep = d2 <= gate
    return i[keep], j[keep]


def pad_square(cost: np.ndarray) -> np.ndarray:
    """Eqs. 11-12: append zero-cost dummy detections (m > n) or dummy targets (m < n)."""
    m, n = cost.shape
    k = max(m, n)
    padded = np.zeros((k, k), dtype=cost.dtype)
    padded[:m, :n] = cost
    return padded


def hungarian(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 13 on the padded matrix; returns the (target, detection) pairs between real rows and columns."""
    m, n = cost.shape
    if m == 0 or n == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    rows, cols = linear_sum_assignment(pad_square(cost))
    real = (rows < m) & (cols < n)
    return rows[real], cols[real]


# --------------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------------
def clip_to_frame(boxes: np.ndarray, width: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """x, y, w, h boxes cut to the ``width`` x ``height`` image, and whether anything of each is left in it
    (a box wholly outside is returned as it was: nothing of it can be cut to the image)."""
    x0, y0 = np.clip(boxes[:, 0], 0.0, width), np.clip(boxes[:, 1], 0.0, height)
    x1 = np.clip(boxes[:, 0] + boxes[:, 2], 0.0, width)
    y1 = np.clip(boxes[:, 1] + boxes[:, 3], 0.0, height)
    inside = (x1 > x0) & (y1 > y0)
    out = np.column_stack([x0, y0, x1 - x0, y1 - y0])
    out[~inside] = boxes[~inside]
    return out, inside


def valid_detections(boxes: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Mask of usable detections: finite numbers and positive width and height."""
    finite = np.isfinite(boxes).all(axis=1) & np.isfinite(scores)
    return finite & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)


def _without(indices: np.ndarray, remove: np.ndarray, size: int) -> np.ndarray:
    """``indices`` (all below ``size``) less those in ``remove``, order kept."""
    keep = np.ones(size, dtype=bool)
    keep[remove] = False
    return indices[keep[indices]]


def _as_inputs(boxes, scores, class_ids, low=None):
    boxes = np.asarray(boxes, dtype=np.float64)
    if boxes.size == 0:
        boxes = boxes.reshape(0, 4)
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise AssociationError(f"detection boxes must be (N, 4) x, y, w, h, got shape {boxes.shape}")
    n = len(boxes)
    scores = np.ones(n) if scores is None else np.asarray(scores, dtype=np.float64).reshape(-1)
    class_ids = np.zeros(n, dtype=np.int64) if class_ids is None else np.asarray(class_ids).reshape(-1)
    low = np.zeros(n, dtype=bool) if low is None else np.asarray(low).reshape(-1).astype(bool)
    if len(scores) != n or len(class_ids) != n or len(low) != n:
        raise AssociationError(f"{n} boxes but {len(scores)} scores, {len(class_ids)} class ids and {len(low)} "
                               "low-confidence flags")
    return boxes, scores, class_ids, low


# --------------------------------------------------------------------------------------------
# The tracker
# --------------------------------------------------------------------------------------------
class MultiTargetTracker:
    """Kalman filters + Hungarian association + §3.3 track management, one :meth:`step` per frame."""

    def __init__(self, config: AssociationConfig | None = None, kalman: KalmanConfig | None = None):
        self.config = validate(config or AssociationConfig())
        self.kalman_config = validate(kalman or KalmanConfig())
        self.next_id = 1
        self.frame_index = 0
        self.last_stamp: float | None = None
        self.first_frame = False
        self._clear()

    def configure(self, config: AssociationConfig | None = None, kalman: KalmanConfig | None = None) -> None:
        """Apply new settings from the next frame on, keeping the tracks (runtime parameter change)."""
        if config is not None:
            self.config = validate(config)
        if kalman is not None:
            self.kalman_config = self.bank.config = validate(kalman)

    def _clear(self) -> None:
        self.bank = KalmanBank(self.kalman_config)
        self.ids = np.zeros(0, dtype=np.int64)
        self.states = np.zeros(0, dtype=np.int64)
        self.hits = np.zeros(0, dtype=np.int64)
        self.misses = np.zeros(0, dtype=np.int64)
        self.ages = np.zeros(0, dtype=np.int64)
        self.scores = np.zeros(0)
        self.class_ids = np.zeros(0, dtype=np.int64)
        self.history: list[deque] = []   # per track: (frame_index, x, y, w, h, matched)

    def reset(self) -> None:
        """Drop every track (IDs keep counting up: never reused)."""
        self._clear()
        self.last_stamp = None

    # -- one frame ----------------------------------------------------------------------------
    def step(self, stamp: float, boxes, scores=None, class_ids=None, low=None) -> FrameResult:
        """Process the detections (x, y, w, h boxes, scores, class ids) of the frame at ``stamp`` [s]; ``low``
        flags the low-confidence ones (second pass only with ``low_confidence``, else dropped)."""
        cfg = self.config
        boxes, scores, class_ids, low = _as_inputs(boxes, scores, class_ids, low)
        if cfg.score_scale != 1.0:
            scores = scores / cfg.score_scale
        ok = valid_detections(boxes, scores)
        rejected = int((~ok).sum())
        ok &= scores >= cfg.min_score
        if not cfg.low_confidence:
            ok &= ~low
        boxes, scores, class_ids, low = boxes[ok], scores[ok], class_ids[ok], low[ok]

        starting = self.last_stamp is None
        T, was_reset = self._frame_interval(stamp)
        self.first_frame = starting or was_reset
        self.frame_index += 1
        previous = self.bank.positions.copy()          # last estimates: origin of θ's vectors (Fig. 1)
        if len(self.bank) and T > 0:
            self.bank.predict(T)
        self.ages += 1

        centres = boxes[:, :2] + boxes[:, 2:] / 2.0
        active = np.flatnonzero(self.states != LOST)
        high = ~low & (scores >= cfg.high_score) if cfg.second_pass else ~low
        first, second = np.flatnonzero(high), np.flatnonzero(~high)

        # First association: every active target against the (high-score) detections; with the
        # cascade, targets coasting unpublished (wide, growing gates) only get what the others left.
        if cfg.cascade:
            recent = active[self.states[active] != PREDICTED]
            t1, d1 = self._associate(recent, first, previous, centres, boxes)
            matched_t, matched_d = [recent[t1]], [first[d1]]
            old = active[self.states[active] == PREDICTED]
            rest = _without(first, first[d1], len(boxes))
            t1, d1 = self._associate(old, rest, previous, centres, boxes)
            matched_t.append(old[t1])
            matched_d.append(rest[d1])
            matched_t, matched_d = [np.concatenate(matched_t)], [np.concatenate(matched_d)]
        else:
            t1, d1 = self._associate(active, first, previous, centres, boxes)
            matched_t, matched_d = [active[t1]], [first[d1]]
        # Second association (ByteTrack): targets left over against the low-score detections.
        if len(second):
            left = _without(active, matched_t[0], len(self.bank))
            left = left[(self.states[left] != TENTATIVE) & (self.hits[left] >= cfg.second_pass_min_hits)]
            t2, d2 = self._associate(left, second, previous, centres, boxes, cfg.second_pass_iou)
            matched_t.append(left[t2])
            matched_d.append(second[d2])
        # Unmatched first-pass detections may re-confirm lost targets, else start tentative tracks.
        unmatched = _without(first, np.concatenate(matched_d), len(boxes))
        if cfg.reacquire_frames > 0 and len(unmatched):
            t3, d3 = self._reacquire(unmatched, centres)
            matched_t.append(t3)
            matched_d.append(d3)
            unmatched = _without(unmatched, d3, len(boxes))
        rows = np.concatenate(matched_t).astype(np.intp)
        dets = np.concatenate(matched_d).astype(np.intp)

        # Rule 3: assigned targets are updated with their detections; the counter is reset.
        # Rule 1 (and rule 2's refused assignments): the others are updated with their prediction
        # and count a miss. Both filter updates run as one batch.
        missed = _without(np.arange(len(self.bank)), rows, len(self.bank))
        self.bank.update_frame(rows, centres[dets], boxes[dets, 2:], missed)
        self.hits[rows] += 1
        self.misses[rows] = 0
        self.scores[rows] = scores[dets]
        self.class_ids[rows] = class_ids[dets]
        self.misses[missed] += 1
        confirmed_now = self._update_states(rows, missed)
        self._record(rows)
        self._delete()
        self._start(boxes[unmatched], scores[unmatched], class_ids[unmatched])
        return FrameResult(self.tracks(), rejected, was_reset, confirmed_now, self.frame_index)

    def _frame_interval(self, stamp: float) -> tuple[float, bool]:
        """T of eq. 6 from the stamps; a stamp going backwards or jumping resets the tracker."""
        if stamp != stamp or stamp in (float("inf"), float("-inf")):
            raise AssociationError(f"stamp {stamp} is not a finite number of seconds")
        cfg = self.config
        was_reset = False
        if self.last_stamp is None:
            T = 0.0
        else:
            T = stamp - self.last_stamp
            if T < 0 or T > cfg.max_frame_gap:
                self.reset()
                was_reset, T = True, 0.0
            elif T == 0:
                T = cfg.default_frame_interval
        self.last_stamp = stamp
        return T, was_reset

    def _associate(self, targets: np.ndarray, detections: np.ndarray, previous: np.ndarray,
                   centres: np.ndarray, boxes: np.ndarray, min_iou: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Cost (eqs. 8-10, options), padding and Hungarian (eqs. 11-13), gate (rule 2); with ``min_iou`` > 0 a
        pair whose predicted box and detection overlap less is excluded as well (the second pass's IoU gate).

        Returns indices into ``targets`` and ``detections`` of the accepted pairs.
        """
        cfg = self.config
        if len(targets) == 0 or len(detections) == 0:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        points = centres[detections]
        predicted = self.bank.positions[targets]
        if cfg.gate == "mahalanobis":
            i, j = gated_pairs(predicted, self.bank.innovation_variance(targets), points, cfg.mahalanobis_gate)
        else:
            i, j = all_pairs(len(targets), len(detections))
        if min_iou > 0:
            inside = box_iou(self.bank.boxes(targets[i]), boxes[detections[j]]) >= min_iou
            i, j = i[inside], j[inside]
        ti = targets[i]
        # θ from the last estimate (every target existed before this frame's births), r from the prediction
        pair_cost = seed_cost(previous[ti], predicted[i], self.bank.velocities[ti], points[j],
                              cfg.still_speed, cfg.angle_weight)
        if cfg.iou_weight > 0:
            pair_cost += cfg.iou_weight * (1.0 - box_iou(self.bank.boxes(ti), boxes[detections[j]]))
        cost = np.full((len(targets), len(detections)), EXCLUDED)
        cost[i, j] = pair_cost
        t, d = hungarian(cost)
        accept = cost[t, d] <= cfg.cost_gate if cfg.gate == "cost" else cost[t, d] < EXCLUDED
        return t[accept], d[accept]

    def _reacquire(self, detections: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lost targets against unmatched detections: distance in box diagonals, Hungarian, radius gate."""
        lost = np.flatnonzero(self.states == LOST)
        if len(lost) == 0:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        diagonal = np.linalg.norm(self.bank.size[lost], axis=1)
        dist = np.linalg.norm(centres[detections][None] - self.bank.positions[lost][:, None], axis=2)
        dist = dist / np.maximum(diagonal, 1e-9)[:, None]
        t, d = hungarian(dist)
        accept = dist[t, d] <= self.config.reacquire_radius
        return lost[t[accept]], detections[d[accept]]

    def _update_states(self, rows: np.ndarray, missed: np.ndarray) -> list:
        """Rule 4 (tentative → confirmed at l_t hits), coasting on misses, lost after f_t.

        A missed target is published as coasting (2) while its prediction is trusted: at most
        ``coast_output_frames`` misses and position std at most ``coast_output_std`` box heights;
        past that it coasts unpublished (4), still associated, until rule 1 makes it lost (3).
        """
        cfg = self.config
        tentative = rows[self.states[rows] == TENTATIVE]
        promoted = tentative[self.hits[tentative] >= cfg.confirm_length]
        self.states[rows[self.states[rows] != TENTATIVE]] = CONFIRMED   # coasting / lost ones re-confirmed
        self.states[promoted] = CONFIRMED
        coasting = missed[np.isin(self.states[missed], (CONFIRMED, COASTING, PREDICTED))]
        std = np.sqrt(self.bank.cov[coasting, 0])
        trusted = (self.misses[coasting] <= cfg.coast_output_frames) & \
            (std <= cfg.coast_output_std * self.bank.size[coasting, 1])
        self.states[coasting] = np.where(trusted, COASTING, PREDICTED)
        gone = coasting[self.misses[coasting] > cfg.max_misses]
        self.states[gone] = LOST
        return self.ids[promoted].tolist()

    def _record(self, rows: np.ndarray) -> None:
        """Append this frame's box of every track to its history (trails, offline backfill)."""
        matched = np.zeros(len(self.bank), dtype=bool)
        matched[rows] = True
        k = self.frame_index
        for h, (x, y, w, hh), m in zip(self.history, self.bank.boxes().tolist(), matched.tolist()):
            h.append((k, x, y, w, hh, m))

    def _delete(self) -> None:
        """Rule 1 / rule 4 deletions: tentative tracks past their limit, lost ones past re-acquisition."""
        cfg = self.config
        drop = (self.states == TENTATIVE) & (self.misses > cfg.tentative_max_misses)
        drop |= (self.states == LOST) & (self.misses > cfg.max_misses + cfg.reacquire_frames)
        if drop.any():
            keep = ~drop
            self.bank.keep(keep)
            for name in ("ids", "states", "hits", "misses", "ages", "scores", "class_ids"):
                setattr(self, name, getattr(self, name)[keep])
            self.history = [h for h, k in zip(self.history, keep) if k]

    def _start(self, boxes: np.ndarray, scores: np.ndarray, class_ids: np.ndarray) -> None:
        """Rule 4: every unassigned detection starts a tentative track with a fresh ID."""
        k = len(boxes)
        if k == 0:
            return
        self.bank.add(boxes)
        self.ids = np.concatenate([self.ids, np.arange(self.next_id, self.next_id + k)])
        self.next_id += k
        confirmed = self.config.confirm_length <= 1 or (self.config.confirm_first_frame and self.first_frame)
        self.states = np.concatenate([self.states, np.full(k, CONFIRMED if confirmed else TENTATIVE)])
        self.hits = np.concatenate([self.hits, np.ones(k, dtype=np.int64)])
        self.misses = np.concatenate([self.misses, np.zeros(k, dtype=np.int64)])
        self.ages = np.concatenate([self.ages, np.ones(k, dtype=np.int64)])
        self.scores = np.concatenate([self.scores, scores])
        self.class_ids = np.concatenate([self.class_ids, class_ids.astype(np.int64)])
        maxlen = max(self.config.history_length, self.config.confirm_length + self.config.tentative_max_misses + 1)
        for b in boxes:
            self.history.append(deque([(self.frame_index, *b, True)], maxlen=maxlen))

    # -- read-out -----------------------------------------------------------------------------
    def tracks(self) -> Tracks:
        """Every track's box and state; with ``frame_width`` and ``frame_height`` the boxes cut to the image
        (the filters keep the whole predicted box) and published targets wholly outside it unpublished (4)."""
        return self._read_out(self.bank, self.states.copy())

    def predicted(self, stamp: float) -> Tracks | None:
        """The tracks at ``stamp``, a frame after the last :meth:`step` that has no detections of its own (the
        detector skipped it), without changing anything: every filter predicted over ``T = stamp - last stamp``
        (eq. 6). A published target is coasting (2) there while its predicted position is trusted (its position
        std at most ``fill_output_std`` box heights if it was detected on the last frame, ``coast_output_std`` if it
        was missed there), else unpublished (4); its missed counter stays (nobody looked at that frame).
        None when no frame was stepped yet or :meth:`step` at ``stamp`` would reset (stamp not after the last
        one, or more than ``max_frame_gap`` after it)."""
        if stamp != stamp or stamp in (float("inf"), float("-inf")):
            raise AssociationError(f"stamp {stamp} is not a finite number of seconds")
        if self.last_stamp is None or not 0 < stamp - self.last_stamp <= self.config.max_frame_gap:
            return None
        bank = self.bank.copy()
        bank.predict(stamp - self.last_stamp)
        states = self.states.copy()
        published = np.isin(states, (CONFIRMED, COASTING))
        limit = np.where(self.misses == 0, self.config.fill_output_std, self.config.coast_output_std)
        trusted = np.sqrt(bank.cov[:, 0]) <= limit * bank.size[:, 1]
        states[published] = np.where(trusted[published], COASTING, PREDICTED)
        return self._read_out(bank, states)

    def _read_out(self, bank: KalmanBank, states: np.ndarray) -> Tracks:
        """:class:`Tracks` of ``bank``'s filters (this tracker's or a predicted copy) with ``states``."""
        boxes = bank.boxes()
        cfg = self.config
        if cfg.frame_width > 0 and cfg.frame_height > 0 and len(boxes):
            boxes, inside = clip_to_frame(boxes, cfg.frame_width, cfg.frame_height)
            states[~inside & np.isin(states, (CONFIRMED, COASTING))] = PREDICTED
        return Tracks(self.ids.copy(), boxes, bank.velocities.copy(), self.scores.copy(),
                      self.class_ids.copy(), self.ages.copy(), self.hits.copy(), self.misses.copy(), states)

    def trail(self, track_id: int) -> np.ndarray:
        """The recorded ``(frame_index, x, y, w, h, matched)`` rows of one track (oldest first)."""
        where = np.flatnonzero(self.ids == track_id)
        if len(where) == 0:
            return np.zeros((0, 6))
        return np.array(self.history[where[0]], dtype=np.float64).reshape(-1, 6)
