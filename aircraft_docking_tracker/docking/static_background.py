"""Static-camera foreground and the aircraft's extent measured from it (issue 11). Pure.

A stand camera does not move; the aircraft does. The appearance model of ISPF (``appearance.py``)
learns whatever its estimate covers, so once the estimate lags behind a growing aircraft it learns
the lag (measured: at frame 100 of a 4-6x approach the model scores the lagging state 0.94 and the
true one 0.57). The background, though, does not learn the aircraft: this module keeps a model of
the empty stand and measures, in the estimate's own template frame, where the foreground ends.

* **Background** ``B``: the frame at the working pyramid level (``cv2.pyrDown``). At the start the
  region around the start state (``guard`` times it) is *unknown*: it gives no foreground until each
  of its pixels has been still (3x3-blurred frame-to-frame change below ``still_level`` or three
  times the frame's median change, whichever is larger) for ``still_frames``
  frames, i.e. until the aircraft has left it; the pixel is then learnt at its value. (Filling the
  region in from its surroundings, ``cv2.inpaint``, was measured first: the guess stays foreground
  for tens of frames and holds a track that sits on the static stand; held-out loose-box starts with
  it: 70 % of runs at AUC >= 0.5, with this rule 85 %.) Every frame moves each known pixel of ``B``
  toward the frame by at most ``step`` grey levels (a running median, "sigma-delta": an aircraft that
  stands still is absorbed only after contrast/step frames).
* **Foreground** ``F ∈ [0, 1]``: ``|I - (a B + c)|`` (gain ``a`` and offset ``c`` fitted by least
  squares outside the target, so a global light change is not foreground), zero on unknown pixels,
  then box-blurred 5x5 (rain streaks are thin; zeroing first keeps the unknown region's difference
  from leaking a ring of foreground round it), then ``clip((d - median - k σ) / (k σ), 0, 1)`` with the median and
  ``σ = 1.4826 MAD`` of ``d`` outside the target (the frame's own noise level).
* **Relight** (``relight``, ``background_relight`` in ``ispf.py``, off): on a still camera's frame ``B`` first
  takes the frame's light, ``B <- a B + c`` with the gain and offset fitted above, then steps toward the frame
  by at most ``step``. Stepping toward ``I`` alone, ``B`` follows a light that changes more than ``step`` levels
  a frame only on the dark pixels: the bright sky lags, and no one gain explains sky and ground at once. At the
  true state on tuning scenes 150, 153 (clear, 60 frames: the light's period is 36-90 frames) the silhouette's
  width came out +0.35 and +0.18 in log (median over the last two thirds) with ``B`` following the frame, +0.05
  relit. (``B`` stays under the frame's light, so a fit biased on one frame, by rain streaks say, is undone by
  the next frame's fit; keeping ``B`` under a reference light instead, ``B <- (I - c) / a``, let such a bias
  accumulate: tuning scene 101 in rain, gain 0.45 and offset +139 after 140 frames.)
* **Persistence** (``persist``, ``foreground_frames`` in ``ispf.py``; 1: off): the foreground is the minimum of
  this frame's and the last ``persist - 1`` trusted frames' in a row (None until there are as many; an untrusted
  frame breaks the row; the earlier frames' foregrounds are first carried by the target's measured motion M,
  when measured). Rain streaks fall anew each frame, and where a colour channel clips near a low sun the
  bands a changing light draws move from frame to frame; the aircraft moves a few pixels. At the true state on
  tuning scenes 100-102, 104 and 150-152, 154 (relit), the silhouette's width came out +0.17 in log (median over
  scenes of the last two thirds' medians), +0.30 in low sun and +0.15-0.24 in rain, measured on 88 % of frames;
  with two frames -0.025 (low sun +0.01-0.05, rain -0.15 to -0.03), on 98 %.
* **Colour** (``colour``, ``foreground_colour`` in ``ispf.py``, on by default since session 23): given the frame in
  BGR too, a colour background ``B_c`` is kept beside ``B`` (the same known pixels, steps and relighting, each
  channel its own gain and offset), and on a still camera's frame ``F`` is thresholded from the largest of the
  grey difference ``s = I - (a B + c)`` and each channel's colour beyond it, ``|s_c - s|`` with
  ``s_c = I_c - (a_c B_c + c_c)`` (rows' offsets removed from each), instead of the grey one alone (trust too is
  decided on it); the camera's shift and staleness and the target motion stay grey. Why: a wing
  painted at the apron's grey level (thin grey wings with a coloured edge, in rain) is no grey difference; its
  pieces broke from the fuselage's, lay outside a track that had narrowed, and were dropped, so the extent
  measured the track's own width and held it there (held-out rain approaches: X̂'s width 0.55 of the truth's
  late in the approach). About the true state narrowed to 0.6 of its width, late in rain approach 301 the grey
  extent measures 0.65 of the truth's width, the colour one 0.99. Why the colour beyond the grey and not each
  channel's own difference (measured first): in rain the relit background's dark tree line on the horizon was
  off by 10-13 levels in red and 4 in green and blue (the light fit's error on the darkest pixels), a row too far
  off for the rows' offsets (``row_max``); joined to the wing tips this band widened X̂ at the stop (held-out
  rain approaches: the last tenth's IoU 0.80 -> 0.74, the stop's aspect error 0.09 -> 0.39 in the median). The
  part of the error common to the channels is grey, and under the grey threshold as before.
* **Rows' offsets** (``row_offset``, ``background_rows`` in ``ispf.py``): on a trusted frame the silhouette
  is thresholded (same threshold) after each image row's median of ``I - (a B + c)`` over its pixels outside
  the target is removed (:func:`row_offsets`; a row with fewer than ``row_min`` such pixels, or whose
  median exceeds ``row_max`` grey levels, keeps 0: a vehicle that fills a row is not a band).
  Why: a smooth sky gradient rounded to grey levels under a drifting light differs from ``B`` by bands of
  about one grey level, constant along each row; the 5x5 blur averages the pixel noise but not a band, so
  on a low-noise frame the bands are foreground. Late in an approach the aircraft reaches into the sky,
  the bands merge with its fin and wing tips, and the silhouette runs off the extent's grid (not measured)
  or widens it (tuning scene 100, at the true state, 40-85 % of the approach: measured on 28 of 67 frames,
  1.35x the width; with the rows removed 64 of 67, 1.08x). Trust (``max_outside``) is decided on the
  one-gain foreground as before: in rain the least-squares offset is biased by the streaks, the rows'
  medians would remove that bias too and let frames full of streaks through.
* **Trust**: the frame gives no measurement (counted as ``untrusted``) when the camera moved — the
  phase correlation of the frame with the previous one, the target's region masked
  (``cv2.phaseCorrelate``), finds a shift of more than ``max_shift`` pixels of the level — or when
  more than ``max_outside`` of the pixels outside the target are foreground (the whole scene changed).
  The foreground threshold is relative to the frame's own differences, so without the shift test a
  panning camera looks static.
* **Moving camera** (``camera_moving``): a camera that pans slowly over low texture passes the
  per-frame shift test (TinyTLP CarChase2, a chase camera over a grey road with a fixed caption: the
  phase correlation finds the caption's zero shift, median 0.02 level px against 0.01 on the synthetic
  stands). What a moving camera cannot hide is that the running background goes stale: outside the
  target, the frame is further from ``a B + c`` than from the previous frame. On a stand ``B`` averages
  the noise and is nearer (the ratio of the mean differences: median <= 0.88, rain included, on the
  synthetic stands); on a moving camera it is 1.7-3.3 (OTB Car4/Car1, CarChase2, UAV123
  building4/wakeboard10, median). The camera counts as moving while the median of this ratio over the
  last ``stale_window`` frames exceeds ``max_stale`` (once 3 frames are in it: the first frames' ``B``
  is one frame; a frame-to-frame change below ``NOISE_FLOOR`` counts as that, so that a noise-free
  still frame does not divide by zero; the floor was 1 grey level until session 24, above what a smooth
  scene changes on a moving camera: CarChase2's road 0.95 in its 10th percentile, 0.56 in the median at
  0.4x contrast or 0.35x light, where the floored ratio fell to about 1 and the chase camera was taken
  for a stand; the synthetic stands' ratio is the same with any floor from 0.1 to 1); then no frame
  gives a foreground (no extent, no silhouette),
  whatever its shift. The target motion keeps its own rule: it compares two frames, not ``B`` (with the
  foreground gated, the motion on or off scores the same on the five real sequences: Car4 0.838 / 0.840,
  CarChase2 0.913 / 0.907, the others equal, 3 tracker seeds).
  After a stand camera is knocked, ``B`` is stale until the running median has relearnt it, and no
  foreground is measured until then either.
* **Cost**: everything runs at the pyramid level at most ``max_width`` (320) pixels wide, about 2 ms
  a frame on one core at 640x480 and at 1280x720 alike.
* **Flicker** (``flicker_gain``, off by default): a per-pixel threshold added to ``k σ``, learnt
  outside the target as ``flicker_gain`` times the pixel's own difference (a sigma-delta step of
  ``flicker_step`` a frame), for edges that shimmer and glare that moves.
* **Target motion** (:func:`target_motion`, ``motion=True``; ``motion_gain`` in ``ispf.py``): the
  similarity that moved the corners under the previous estimate, from Lucas-Kanade between the
  previous and this frame at the working level. Measured only while the camera is still: from the start
  (a stand camera) until one frame's phase-correlation shift exceeds ``motion_max_shift`` (0.15 level
  px; the synthetic stands: < 0.1 in 90 % of frames, OTB Car4's following camera: 0.23 in the median),
  then again after ``still_frames`` frames below it.
* **Start silhouette** (:func:`start_silhouette`; ``start_refit`` in ``ispf.py``): the start region is unknown
  to ``B`` for the first frames, so no foreground exists there while the appearance model learns the start
  box. What moved inside it does: ``d = |median(last three frames) - median(first three)|`` (gain and offset
  fitted outside the region; the medians drop rain streaks that last one frame), 5x5-blurred; a pixel moved
  when ``d`` exceeds its median outside the region by ``z`` noise widths (1.4826 MAD outside) and by at least
  ``min_contrast`` grey levels (the width alone is 0.06 grey levels on a clean stand: the light's own small
  changes passed it and the silhouette came out round); inside the start state grown ``grow``, closed 5x5.
  Measured: its principal axis, its elongation (ratio of the principal standard deviations) and the fraction
  of the pixels outside the region that moved (rain, a moving camera; tuning stands: <= 0.05 in clear light
  and low sun, 0.07-0.16 in rain). The first ``keep_first`` frames at the level are kept for it. With
  ``axis="hull"`` (``start_axis`` in ``ispf.py``, the default since session 19) the frames are the camera's own,
  in colour (a pixel's difference is its largest channel's: a painted wing at the ground's grey level), 3x3
  blurred, and the axis is that of the filled convex hull of the largest connected piece: the wing tips and the
  fin set it, not the filled fuselage, and rain streaks apart from the aircraft are left out. Tuning approaches
  (first 6 frames): the rain starts' axes 1-10 deg off (20-64 on the grey level on 7 of 10); ``fill``, the
  hull's area over the start rectangle's, is 0.01-0.10 for an aircraft hidden behind the bridge, 0.22-0.40 in
  view.
* **Extent** (:func:`foreground_extent`): ``F`` sampled on a grid covering ``extent`` times the
  estimate's template rectangle, in the estimate's template coordinates ``(u, v)``; threshold, close
  3x3, the connected components that overlap the rectangle (a small one, ``small_share``, only inside the
  estimate's rectangle: it holds the extent, it cannot widen it); their bounding box ``[u0, u1] x [v0, v1]``
  is the measured rectangle (a silhouette that reaches the grid's border is not measured: it is
  merged with something larger than the target), with the principal axis of its cells in the image
  (for ``extent_rotation`` in ``ispf.py``). With ``axes="silhouette"`` (``extent_axes`` in ``ispf.py``, off:
  the tuning seeds' gains were not confirmed held out) the sides are the cells' extents along the silhouette's own principal axes
  instead (the estimate's rotation kept): along the estimate's axes a rotation error of the estimate gives the
  turned silhouette's bounding box, 1.35x too high for a 2:1 rectangle 10 deg off, and the scale followed it.
* **Freeze** (``freeze``, off; ``background_freeze`` in ``ispf.py``): ``B`` not learnt inside the target's
  rectangle grown ``freeze`` times while the camera is still, so that a standing aircraft is not absorbed.
  Measured with the extent kept on at the still frames: much worse (tuning scenes 100-112, loose box, mean AUC
  0.678 -> 0.525), not the default.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from . import affine_group as ag

GRID_SIDE = 64          # samples per side of the extent grid
PIECES_WITHIN = 0.8     # the silhouette's pieces kept: those within this half-side of X̂'s centre [X̂'s sides]
PIECE_SHARE = 0.1       # ... and overlapping that square by at least this fraction of the largest overlap (a
                        # smaller piece: only with small_share, and only inside X̂'s rectangle)
EXTENT_CLOSE = 3        # the closing joining the silhouette's cells on the extent grid [cells]
NOISE_FLOOR = 0.25      # grey levels: a smaller mean frame-to-frame change is taken as this (camera_moving)


@dataclass
class StartSilhouette:
    """What moved inside the start region over the first frames (:func:`start_silhouette`)."""

    axis_angle: float       # image angle of the silhouette's major axis [rad], in [-pi/2, pi/2)
    elongation: float       # ratio of its principal standard deviations (major / minor)
    outside: float          # fraction of the pixels outside the region that moved as much (camera, rain)
    pixels: int             # silhouette pixels (axis hull: the hull's) in the images given
    fill: float = 1.0       # axis hull: the hull's area over the start rectangle's (an aircraft hidden: a piece)


@dataclass
class Extent:
    """The foreground's bounding rectangle in the estimate's template frame (unit square = estimate)."""

    centre_u: float
    centre_v: float
    width: float            # in template widths
    height: float           # in template heights
    axis_angle: float = 0.0     # image angle of the silhouette's major axis minus the template's u axis [rad]
    elongation: float = 1.0     # ratio of the silhouette's principal standard deviations (major / minor)

    def correction(self) -> np.ndarray:
        """C (3x3) with ``X · C`` = the state whose template rectangle is this rectangle."""
        return np.array([[self.width, 0.0, self.centre_u], [0.0, self.height, self.centre_v], [0.0, 0.0, 1.0]])


def _level_image(frame: np.ndarray, level: int) -> np.ndarray:
    image = np.asarray(frame, dtype=np.float32)
    for _ in range(level):
        if min(image.shape[:2]) < 16:
            break
        image = cv2.pyrDown(image)
    return image


def state_mask(state: np.ndarray, grow: float, shape: tuple[int, int], scale: float) -> np.ndarray:
    """uint8 mask (``shape``) of the state's template rectangle grown ``grow`` times about its centre,
    in an image ``scale`` times the frame's size."""
    grown = state @ ag.exp_coords(np.array([np.log(grow), 0, 0, 0, 0, 0]))
    quad = ag.to_quad(grown) * scale
    mask = np.zeros(shape, np.uint8)
    if np.isfinite(quad).all() and np.abs(quad).max() < 1e6:
        cv2.fillConvexPoly(mask, np.round(quad).astype(np.int32), 1)
    return mask


class StaticBackground:
    """The empty stand's background and the foreground of each frame (see the module docstring)."""

    def __init__(self, max_width: int = 320, step: float = 2.0, k: float = 2.0, max_outside: float = 0.2,
                 guard: float = 1.3, max_shift: float = 0.5, still_level: float = 3.0, still_frames: int = 5,
                 flicker_gain: float = 0.0, flicker_step: float = 1.0, motion: bool = False,
                 motion_max_shift: float = 0.15, max_stale: float = 1.35, stale_window: int = 25,
                 keep_first: int = 0, row_offset: bool = False, row_min: int = 16, row_max: float = 2.0,
                 freeze: float = 0.0, relight: bool = False, persist: int = 1, colour: bool = False,
                 still_window: int = 0, still_gap: int = 4):
        self.keep_first = keep_first
        self.still_window, self.still_gap = still_window, still_gap
        self._key: np.ndarray | None = None    # still_window: the frame the slow motion is measured against
        self._key_age = 0                      # ... frames since it
        self._moved = False                    # ... whether the target moved against it (or between two frames)
        self.colour = colour
        self.colour_background: np.ndarray | None = None  # colour: B of the BGR frames (H x W x 3), else None
        self._colour_image: np.ndarray | None = None      # colour: this frame at the level, BGR
        self.relight = relight
        self.persist = persist
        self._recent: list[np.ndarray] = []         # the last persist - 1 trusted frames' foregrounds
        self.freeze = freeze
        self.first: list[np.ndarray] = []           # the first keep_first frames at the level (start_silhouette)
        self.measure_motion = motion
        self.row_offset, self.row_min, self.row_max = row_offset, row_min, row_max
        self.max_stale, self.stale_window = max_stale, stale_window
        self._stale: list[float] = []
        self.camera_moving = False
        self.motion_max_shift, self.still_run = motion_max_shift, 0
        self.motion: np.ndarray | None = None
        self.max_width, self.step, self.k, self.max_outside, self.guard = max_width, step, k, max_outside, guard
        self.level = 0
        self.max_shift, self.still_level, self.still_frames = max_shift, still_level, still_frames
        self.flicker_gain, self.flicker_step = flicker_gain, flicker_step
        self.flicker: np.ndarray | None = None
        self._window: np.ndarray | None = None
        self.background: np.ndarray | None = None
        self.foreground: np.ndarray | None = None
        self.trusted = False
        self.scale = 1.0
        self.known: np.ndarray | None = None
        self._still: np.ndarray | None = None
        self._previous: np.ndarray | None = None

    def start(self, frame: np.ndarray, state: np.ndarray, colour: np.ndarray | None = None) -> None:
        """B = the frame at the pyramid level at most ``max_width`` wide (the cost per frame stays that of
        a 320 x 240 image at any camera resolution); the region around ``state`` is unknown. ``colour``: the
        same frame in BGR, when the camera gives one (``colour``)."""
        width = np.asarray(frame).shape[1]
        self.level = int(max(0, np.ceil(np.log2(max(width / self.max_width, 1.0)))))
        image = _level_image(frame, self.level)
        self.scale = image.shape[1] / np.asarray(frame).shape[1]
        hole = state_mask(state, self.guard, image.shape, self.scale)
        self.background = image.copy()
        self._colour_image = self._colour_level(colour, image.shape)
        self.colour_background = None if self._colour_image is None else self._colour_image.copy()
        self.known = hole == 0
        self._still = np.zeros(image.shape, np.int32)
        self._previous = image
        self.flicker = np.zeros(image.shape, np.float32) if self.flicker_gain > 0 else None
        self.still_run = self.still_frames + 1         # a stand camera: still until a frame says otherwise
        self._stale, self.camera_moving = [], False
        self._drop_track(image)

    def _drop_track(self, image: np.ndarray) -> None:
        """Forget what belongs to a track (its foreground and motion; the ``keep_first`` frames start at ``image``)."""
        self.foreground, self.trusted, self.motion = None, False, None
        self._key, self._key_age, self._moved = None, 0, False
        self._recent = []
        self.first = [image] if self.keep_first > 0 else []

    def _colour_level(self, colour: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
        """``colour`` (a BGR frame) at the level, or None (``colour`` off, no BGR frame, another size)."""
        if not self.colour or colour is None or np.asarray(colour).ndim != 3:
            return None
        image = _level_image(colour, self.level)
        return image if image.shape[:2] == shape else None

    def restart(self, frame: np.ndarray, state: np.ndarray, colour: np.ndarray | None = None) -> None:
        """A new track on the same camera (a restart mid-approach: lost, re-acquired, the detector override):
        what ``B`` knows of the stand is kept (background, known pixels, still counts, the camera's stale
        ratio and still run); only what belongs to the old track is dropped (this frame's foreground and
        motion; the ``keep_first`` frames start again at ``frame``), and ``frame`` is learnt as any frame.
        ``start`` instead makes the region around ``state`` unknown until the aircraft has left it; mid-approach
        it never leaves it, so no foreground was measured there again (docs/docking_tracker.md, "Session 10:
        restarts"). A frame of another size than ``B`` starts afresh."""
        image = _level_image(frame, self.level)
        if self.background is None or image.shape != self.background.shape:
            self.start(frame, state, colour)
            return
        self._drop_track(image)
        self._colour_image = self._colour_level(colour, image.shape)
        self._learn(image)

    @property
    def target_still(self) -> bool:
        """The motion is measured on this frame and no corner under the estimate moved (``motion`` None): between
        two frames, and with ``still_window`` also not against the keyframe (:meth:`_slow_motion`)."""
        return self.measure_motion and self.motion is None and not self._moved

    def _slow_motion(self, image: np.ndarray, state: np.ndarray) -> None:
        """``still_window`` > 0: a target whose corners moved less than ``target_motion``'s ``min_move`` between two
        frames may still be moving, slowly: an aircraft 50 m out closing at 3 m/s moves its corners about a tenth
        of a level pixel a frame at 14 Hz, and every frame of such an approach was judged still (the extent never
        measured; 600-frame tuning approaches: the template's height over the last 15 m -51 % to +34 % of the
        truth's). So the motion is also measured against a keyframe, ``still_gap`` to ``still_window`` frames back:
        the target moved when that motion is measured (the keyframe then moves to this frame), and is still once
        ``still_window`` frames have passed without it (the keyframe moves on too). A motion between two frames
        moves the keyframe here."""
        if self.still_window <= 0:
            return
        if self.motion is not None or self._key is None:
            self._key, self._key_age, self._moved = image, 0, self.motion is not None
            return
        self._key_age += 1
        if self._key_age < self.still_gap:
            return
        if target_motion(self._key, image, state, self.scale) is not None:
            self._key, self._key_age, self._moved = image, 0, True
            return
        self._moved = False
        if self._key_age >= self.still_window:
            self._key, self._key_age = image, 0

    def observe(self, frame: np.ndarray, state: np.ndarray, colour: np.ndarray | None = None) -> np.ndarray | None:
        """F of ``frame`` given the target near ``state`` (None if untrusted); then B moves toward it.
        ``colour``: the same frame in BGR, when the camera gives one (``colour``: F from its channels)."""
        image = _level_image(frame, self.level)
        if self.background is None or image.shape != self.background.shape:
            self.start(frame, state, colour)
            return None
        self._colour_image = (self._colour_level(colour, image.shape) if self.colour_background is not None
                              else None)
        if self._colour_image is None:
            self.colour_background = None      # a grey frame: the colour background is not kept up any more
        outside = state_mask(state, self.guard, image.shape, self.scale) == 0
        self.foreground, self.trusted, self.motion = None, False, None
        shift, lit, lit_colour = np.inf, None, None
        if outside.sum() >= 100:             # else too little background to measure anything
            shift = self.camera_shift(image, outside)
            gain, offset = _light_fit(self.background, image, outside)
            lit = gain * self.background + offset
            signed = image - lit
            difference = np.abs(signed)
            self.camera_moving = self._stale_background(difference, image, outside)
        self.still_run = self.still_run + 1 if shift <= self.motion_max_shift else 0
        if self.measure_motion and shift <= self.max_shift and self.still_run > self.still_frames:
            self.motion = target_motion(self._previous, image, state, self.scale)
            self._slow_motion(image, state)
        else:
            self._key, self._key_age, self._moved = None, 0, False
        still_camera = shift <= self.max_shift and not self.camera_moving   # this frame measures a foreground
        if still_camera and self.colour_background is not None:    # the foreground from the channels, each lit
            lit_colour, signed = self._colour_difference(signed, outside)
            difference = np.abs(signed).max(axis=0)
        if still_camera:
            d = cv2.blur(difference * self.known, (5, 5))
            median, sigma = _median_and_noise(d[outside][::5])
            threshold = median + self.k * sigma + (self.flicker if self.flicker is not None else 0.0)
            fg = np.clip((d - threshold) / (self.k * sigma), 0.0, 1.0)
            if self.flicker is not None:
                target = self.flicker_gain * np.maximum(d - median, 0.0)
                self.flicker += np.where(outside & self.known,
                                         np.clip(target - self.flicker, -self.flicker_step, self.flicker_step), 0.0)
            self.trusted = bool(np.isfinite(fg).all() and (fg[outside] > 0.5).mean() <= self.max_outside)
            if self.trusted and self.row_offset:    # trust and threshold as above; the silhouette without the rows' bands
                d = cv2.blur(self._without_rows(signed, outside & self.known) * self.known, (5, 5))
                fg = np.clip((d - threshold) / (self.k * sigma), 0.0, 1.0)
            self.foreground = self._persistent(fg * self.known) if self.trusted else None
        if not self.trusted:
            self._recent = []
        if len(self.first) < self.keep_first:
            self.first.append(image)
        if self.relight and still_camera:       # (a still camera had the background outside to fit the light)
            self.background = lit               # B takes this frame's light at once (still camera), the scene by step
            if lit_colour is not None:
                self.colour_background = lit_colour
        frozen = None           # freeze: only on a still camera (after a pan, B inside the region must be relearnt)
        if self.freeze > 0 and still_camera:
            frozen = state_mask(state, self.freeze, image.shape, self.scale) > 0
        self._learn(image, frozen)
        return self.foreground

    def _colour_difference(self, signed: np.ndarray, outside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The colour background under this frame's light (each channel its own gain and offset, fitted
        ``outside`` the target) and the stack (4 x H x W) of the grey difference ``signed`` and each channel's
        difference beyond it: a light the fit leaves uneven moves every channel alike and stays grey."""
        lit, beyond = [], []
        for c in range(3):
            background, image = self.colour_background[..., c], self._colour_image[..., c]
            gain, offset = _light_fit(background, image, outside)
            lit.append(gain * background + offset)
            beyond.append(image - lit[-1] - signed)
        return np.stack(lit, axis=2), np.stack([signed, *beyond])

    def _without_rows(self, signed: np.ndarray, region: np.ndarray) -> np.ndarray:
        """``|signed|`` with each image row's offset removed (:func:`row_offsets` over ``region``); of a stack of
        differences (C x H x W: the grey one and the channels' colour), each one's rows removed, then the largest."""
        if signed.ndim == 2:
            return np.abs(signed - row_offsets(signed, region, self.row_min, self.row_max)[:, None])
        return np.max([self._without_rows(channel, region) for channel in signed], axis=0)

    def _persistent(self, foreground: np.ndarray) -> np.ndarray | None:
        """``persist`` > 1: the minimum of this frame's foreground and the last ``persist - 1`` trusted frames' in a
        row (None until there are as many): rain streaks, and the bands a changing light draws where a colour
        channel clips, are foreground on one frame; the target stays. The earlier frames' foregrounds are first
        carried by the target's measured motion M (``motion``, when measured), so a target that moves a large
        part of its size a frame is not cut to the overlap of its two silhouettes."""
        if self.persist <= 1:
            return foreground
        recent = self._recent
        if self.motion is not None and recent:
            to_level = np.diag([self.scale, self.scale, 1.0])
            carry = (to_level @ self.motion @ np.linalg.inv(to_level))[:2]
            size = (foreground.shape[1], foreground.shape[0])
            recent = [cv2.warpAffine(f, carry, size, flags=cv2.INTER_LINEAR, borderValue=0.0) for f in recent]
        self._recent = (recent + [foreground])[-(self.persist - 1):]
        if len(recent) < self.persist - 1:
            return None
        return np.minimum.reduce([foreground, *recent])

    def _stale_background(self, difference: np.ndarray, image: np.ndarray, outside: np.ndarray) -> bool:
        """Whether the camera moves (module docstring): the median, over the last ``stale_window`` frames,
        of the mean ``|I - (a B + c)|`` over the known pixels outside the target divided by the mean
        ``|I - I_prev|`` there exceeds ``max_stale``."""
        region = outside & self.known
        if region.sum() < 100:
            return self.camera_moving                   # too little known background to judge: as before
        change = float(np.abs(image - self._previous)[region].mean())
        stale = float(difference[region].mean()) / max(change, NOISE_FLOOR)
        self._stale = (self._stale + [stale])[-self.stale_window:]
        return len(self._stale) >= 3 and self.stale_ratio > self.max_stale

    @property
    def stale_ratio(self) -> float:
        """The median ratio over the last ``stale_window`` frames (NaN before the first)."""
        return float(np.median(self._stale)) if self._stale else float("nan")

    def _learn(self, image: np.ndarray, frozen: np.ndarray | None = None) -> None:
        """B moves toward the frame on known pixels (not on ``frozen`` ones: with ``freeze``, the target's rectangle
        grown ``freeze`` times); an unknown pixel (the start region) becomes known,
        at its value, once it has been still for ``still_frames`` frames (the aircraft has left it)."""
        change = cv2.blur(np.abs(image - self._previous), (3, 3))
        sample = change[::4, ::4]
        noise = float(np.median(sample))                        # the frame-to-frame change of a still pixel
        still = change < max(self.still_level, 3.0 * noise)
        self._still = np.where(still, np.minimum(self._still + 1, self.still_frames), 0)
        learnt = ~self.known & (self._still >= self.still_frames)
        self.background[learnt] = image[learnt]
        self.known |= learnt
        moving = self.known if frozen is None else self.known & ~frozen
        self.background += np.where(moving, np.clip(image - self.background, -self.step, self.step), 0)
        if self.colour_background is not None and self._colour_image is not None:     # the same steps, per channel
            self.colour_background[learnt] = self._colour_image[learnt]
            self.colour_background += np.where(moving[..., None], np.clip(
                self._colour_image - self.colour_background, -self.step, self.step), 0)
        self._previous = image

    def camera_shift(self, image: np.ndarray, outside: np.ndarray | None = None) -> float:
        """How far the camera moved since the previous frame [level pixels]: the phase-correlation shift
        (``cv2.phaseCorrelate``), the target's region (``~outside``) taken from the previous frame so that
        the target's own motion does not count. (Against the background instead, the target's fading
        trail in it gave spurious shifts of 30-90 px on a still camera.)"""
        if self._window is None or self._window.shape != image.shape:
            self._window = cv2.createHanningWindow(image.shape[::-1], cv2.CV_32F)
        previous = self._previous.astype(np.float32)       # copies: cv2.phaseCorrelate writes into its inputs
        moved = image.astype(np.float32) if outside is None else np.where(outside, image, previous)
        (dx, dy), _ = cv2.phaseCorrelate(previous, moved.astype(np.float32), self._window)
        return float(np.hypot(dx, dy))


def _light_fit(background: np.ndarray, image: np.ndarray, outside: np.ndarray) -> tuple[float, float]:
    """``(a, c)`` of ``a B + c``, the background under the image's light: gain and offset fitted by least squares
    on every 7th pixel outside the target; no change, ``(1, 0)``, when the fit is degenerate (a flat background)
    or its gain is not a light change (outside 0.25-4)."""
    b, i = background[outside][::7], image[outside][::7]
    (gain, offset), *_ = np.linalg.lstsq(np.stack([b, np.ones_like(b)], 1), i, rcond=None)
    if not (np.isfinite(gain) and np.isfinite(offset) and 0.25 < gain < 4.0):
        return 1.0, 0.0
    return float(gain), float(offset)


def _median_and_noise(values: np.ndarray) -> tuple[float, float]:
    """The median of ``values`` and their robust spread ``σ = 1.4826 MAD`` (+ 1e-3: never 0)."""
    median = float(np.median(values))
    return median, 1.4826 * float(np.median(np.abs(values - median))) + 1e-3


def start_silhouette(images: list[np.ndarray], state: np.ndarray, scale: float, z: float = 4.0, grow: float = 1.3,
                     surround: float = 1.6, min_pixels: int = 30, min_contrast: float = 1.0,
                     axis: str = "mask", blur: int = 5) -> StartSilhouette | None:
    """The silhouette of what moved inside ``state``'s rectangle over ``images`` (>= 4 frames of a still camera
    at ``scale`` times the frame's size, grey or BGR, the first at the start; module docstring), or None (too few
    frames, too little outside the region to measure the noise, fewer than ``min_pixels`` silhouette pixels).

    ``axis`` mask: the principal axis of every moved pixel in the region (closed 5x5); hull: of the filled convex
    hull of the largest connected piece, so that the wing tips and the fin set the axis and not the filled blob
    of the fuselage (in rain most of the mask: session 16, 12-36 deg off in 6 of 7 tuning rain starts), nor the rain
    streaks apart from it. On BGR images a pixel's difference is the largest of its three channels'."""
    if len(images) < 4:
        return None
    first = _median_of_three(*(np.asarray(i) for i in images[:3])).astype(np.float32)    # exact in any dtype
    last = _median_of_three(*(np.asarray(i) for i in images[-3:])).astype(np.float32)
    shape = first.shape[:2]
    outside = state_mask(state, surround, shape, scale) == 0
    if outside.sum() < 100:
        return None
    channels = [(first, last)] if first.ndim == 2 else [(first[..., c], last[..., c]) for c in range(first.shape[2])]
    d = np.zeros(shape, np.float32)
    for before, after in channels:
        gain, offset = _light_fit(before, after, outside)
        d = np.maximum(d, np.abs(after - (gain * before + offset)).astype(np.float32))
    if blur > 1:
        d = cv2.blur(d, (blur, blur))
    median, sigma = _median_and_noise(d[outside])
    moved = d - median > max(z * sigma, min_contrast)
    region = state_mask(state, grow, shape, scale) > 0
    mask = cv2.morphologyEx((moved & region).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    ys, xs = np.nonzero(mask)
    if len(xs) < min_pixels:
        return None
    fill = 1.0
    if axis == "hull":
        _, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        piece = np.stack(np.nonzero(labels == largest)[::-1], axis=1).astype(np.int32)
        hull = np.zeros_like(mask)
        cv2.fillConvexPoly(hull, cv2.convexHull(piece), 1)
        ys, xs = np.nonzero(hull)
        fill = float(len(xs) / max((state_mask(state, 1.0, shape, scale) > 0).sum(), 1))
    major, elongation = principal_axis(np.stack([xs, ys]).astype(float))
    angle = half_turn(float(np.arctan2(major[1], major[0])))
    return StartSilhouette(angle, elongation, float(moved[outside].mean()), int(len(xs)), fill)


def _median_of_three(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The pixelwise median of three images (exactly ``np.median`` of their stack, ~20x faster)."""
    return np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))


def principal_axis(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The major principal axis of 2 x n ``points`` (a unit vector: the covariance's leading eigenvector) and
    the elongation, the ratio of the major to the minor standard deviation (a filled w x h rectangle's is w / h)."""
    evals, evecs = np.linalg.eigh(np.cov(points))
    return evecs[:, 1], float(np.sqrt(max(evals[1], 1e-12) / max(evals[0], 1e-12)))


def half_turn(angle):
    """An axis's angle (or angles) in [-pi/2, pi/2): an axis has no direction, so angles are modulo pi."""
    return (angle + np.pi / 2) % np.pi - np.pi / 2


def row_offsets(signed: np.ndarray, outside: np.ndarray, min_count: int = 16, max_offset: float = 2.0) -> np.ndarray:
    """Per image row, the median of ``signed`` (frame minus background) over the row's pixels outside the
    target; 0 for a row with fewer than ``min_count`` of them, or whose median exceeds ``max_offset`` grey
    levels (not a band: an object, a crossing vehicle, fills the row) (``row_offset``, module docstring)."""
    masked = np.where(outside, signed, np.nan)
    count = outside.sum(axis=1)
    offsets = np.zeros(signed.shape[0], np.float32)
    rows = count >= min_count
    if rows.any():
        offsets[rows] = _row_medians(masked[rows])
    offsets[np.abs(offsets) > max_offset] = 0.0
    return offsets


def _row_medians(masked: np.ndarray) -> np.ndarray:
    """``np.nanmedian(masked, axis=1)`` (bit for bit) for rows with at least one number, about 6x faster: NaN sorts
    last, so each row's median is the mean of the middle two of its first ``n`` sorted values."""
    ordered = np.sort(masked, axis=1)
    count = np.count_nonzero(~np.isnan(masked), axis=1)
    low = np.take_along_axis(ordered, ((count - 1) // 2)[:, None], axis=1)[:, 0]
    high = np.take_along_axis(ordered, (count // 2)[:, None], axis=1)[:, 0]
    return (low + high) / 2


def foreground_extent(foreground: np.ndarray, state: np.ndarray, scale: float, extent: float = 1.6,
                      threshold: float = 0.5, min_fill: float = 0.02, axes: str | float = "estimate",
                      min_elongation: float = 1.15, small_share: float = 0.0) -> Extent | None:
    """The foreground's rectangle in the template frame of ``state`` (module docstring), or None.

    ``foreground`` is F at ``scale`` times the frame's size; ``extent`` how far around the state's
    rectangle to look (in its own sizes); ``min_fill`` the smallest silhouette, as a fraction of the
    rectangle, that is measured. ``axes`` estimate: the bounding box along the state's own u and v axes;
    silhouette: the sides are the silhouette's extents along its own principal axes (the one nearer the
    state's u axis gives the width), the state's rotation kept (:func:`_principal_sides`), when the
    silhouette has an axis (elongation at least ``min_elongation``; else as estimate); a number: the sides along
    the axis at that image angle [rad] (a running average of the silhouette's axis) and its normal.
    The silhouette is the connected pieces (after a 3-cell closing) that overlap the square of half-side
    ``PIECES_WITHIN`` about X̂'s centre by at least a tenth of the largest overlap (rain specks are smaller),
    and with ``small_share`` > 0 the cells inside X̂'s own rectangle of the smaller pieces that overlap it by at
    least ``small_share`` of the largest: such a piece may keep the rectangle as large as X̂, never make it
    larger. Why (session 20): a fin fading into a low sun's glare, or a thin wing broken by rain into pieces,
    is 4-10 % of the fuselage's piece; dropped, the extent measured the fuselage alone and pulled X̂ down to it,
    frame after frame (tuning 114, low sun: X̂'s height 1.04 -> 0.55 of the truth's; held out 213, rain: its
    width 0.57). Kept everywhere (the share 0.03 for every piece), rain specks far out widened it instead
    (tuning 107, 116, 119: -0.03 to -0.16 a run).
    Why not X̂'s own rectangle (0.5, until session 15): rain breaks a thin wing from the fuselage, a piece
    outside a too narrow X̂ was dropped, the extent measured X̂'s own width and X̂ stayed narrow (tuning
    113, 119: log aspect -0.7 at the stop, IoU 0.47).
    """
    n = GRID_SIDE
    u = ((np.arange(n) + 0.5) / n - 0.5) * extent
    uu, vv = np.meshgrid(u, u)
    grid = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)]).astype(np.float32)
    affine = (np.asarray(state, dtype=float)[:2, :] * scale).astype(np.float32)
    affine[:, 2] -= 0.5                             # pixel centres of the scaled image (as warp_patches)
    maps = affine @ grid
    patch = cv2.remap(foreground, maps[0].reshape(n, n), maps[1].reshape(n, n), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    binary = cv2.morphologyEx((patch > threshold).astype(np.uint8), cv2.MORPH_CLOSE,
                              np.ones((EXTENT_CLOSE, EXTENT_CLOSE), np.uint8))
    count, labels = cv2.connectedComponents(binary, connectivity=8)
    inner = (np.abs(uu) < 0.5) & (np.abs(vv) < 0.5)
    near = (np.abs(uu) < PIECES_WITHIN) & (np.abs(vv) < PIECES_WITHIN)
    if count <= 1:
        return None
    overlap = np.bincount(labels[near], minlength=count)
    overlap[0] = 0
    largest = overlap.max()
    keep = np.flatnonzero(overlap >= PIECE_SHARE * largest)
    keep = keep[keep > 0]
    kept = np.isin(labels, keep)
    if small_share > 0:
        small = np.flatnonzero((overlap >= small_share * largest) & (overlap < PIECE_SHARE * largest))
        kept |= np.isin(labels, small[small > 0]) & inner
    ys, xs = np.nonzero(kept)
    if len(xs) < min_fill * inner.sum():
        return None
    if xs.min() == 0 or ys.min() == 0 or xs.max() == n - 1 or ys.max() == n - 1:
        return None
    # principal axis of the silhouette's cells in image pixels, against the template's u axis
    linear = np.asarray(state, dtype=float)[:2, :2]
    major, elongation = principal_axis(linear @ np.stack([u[xs], u[ys]]))
    angle = half_turn(float(np.arctan2(major[1], major[0]) - np.arctan2(linear[1, 0], linear[0, 0])))
    cell = extent / n
    if not isinstance(axes, str) or (axes == "silhouette" and elongation >= min_elongation):
        major = major if isinstance(axes, str) else np.array([np.cos(axes), np.sin(axes)])
        centre_u, centre_v, width, height = _principal_sides(linear, u[xs], u[ys], cell, major)
        return Extent(centre_u, centre_v, width, height, angle, elongation)
    u0, u1 = u[xs.min()] - cell / 2, u[xs.max()] + cell / 2
    v0, v1 = u[ys.min()] - cell / 2, u[ys.max()] + cell / 2
    return Extent((u0 + u1) / 2, (v0 + v1) / 2, u1 - u0, v1 - v0, angle, elongation)


def _principal_sides(linear: np.ndarray, us: np.ndarray, vs: np.ndarray, cell: float,
                     major: np.ndarray) -> tuple[float, float, float, float]:
    """The silhouette's cells (template coordinates ``us``, ``vs``, side ``cell``) measured along its own principal
    axes in the image (``major``: the unit image direction of one of them): ``(centre_u, centre_v, width,
    height)`` in the template frame of the state whose linear part is ``linear`` (2x2, image per template unit),
    the width being the extent along whichever principal axis is nearer the state's u axis over the length of
    that axis, the height likewise.

    Why (issue 11, session 11): the bounding box along the state's own axes is the silhouette's turned
    rectangle's bounding box when the state's rotation is off (by 5 deg on a 2:1 aircraft: 4 % wider, 17 %
    higher), and the extent correction carried that into the scale. Along the silhouette's own axes the sides
    do not depend on the state's rotation; the rotation is left to the shape prior's rotation pull."""
    half = cell / 2
    corners = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    points = (np.stack([us, vs], 1)[:, None, :] + corners[None]).reshape(-1, 2) @ linear.T   # image offsets
    a_u, a_v = np.linalg.norm(linear[:, 0]), np.linalg.norm(linear[:, 1])
    minor = np.array([-major[1], major[0]])
    axis_u, axis_v = (major, minor) if abs(major @ linear[:, 0]) >= abs(minor @ linear[:, 0]) else (minor, major)
    along_u, along_v = points @ axis_u, points @ axis_v
    centre = axis_u * (along_u.max() + along_u.min()) / 2 + axis_v * (along_v.max() + along_v.min()) / 2
    centre_u, centre_v = np.linalg.solve(linear, centre)
    return (float(centre_u), float(centre_v), float(np.ptp(along_u)) / a_u, float(np.ptp(along_v)) / a_v)


def target_motion(previous: np.ndarray, image: np.ndarray, state: np.ndarray, scale: float, grow: float = 1.3,
                  ring: float = 2.5, min_move: float = 0.5, min_points: int = 8, max_points: int = 200,
                  fit_threshold: float = 0.5, max_agree: float = 0.5) -> np.ndarray | None:
    """The target's own motion between two frames of a still camera: M (3x3, frame pixels) with
    ``M · X_{t-1}`` = where the pixels under X_{t-1} went, or None.

    Corners inside ``state``'s rectangle grown ``grow`` times (``cv2.goodFeaturesToTrack``) are followed
    by pyramidal Lucas-Kanade, forward and back (a point that does not come back within 0.5 px is
    dropped); the points that moved more than ``min_move`` level pixels are the target's (the camera is
    still, so the background's do not move), and a similarity (shift, scale, rotation) is fitted to them
    with RANSAC (``cv2.estimateAffinePartial2D``). ``previous`` and ``image`` are the frames at ``scale``
    times the frame's size. None when fewer than ``min_points`` points moved (a still or hidden target),
    or when more than ``max_agree`` of the corners on a ring around the target (out to ``ring`` times the
    state) moved as the fit says: that is the background's motion (a camera that follows the target
    slowly, which the phase correlation of the frame does not see: OTB Car4), not the target's.
    """
    inner = state_mask(state, grow, image.shape, scale)
    outer = state_mask(state, ring, image.shape, scale) & (inner == 0)
    prev8 = np.clip(previous, 0, 255).astype(np.uint8)
    next8 = np.clip(image, 0, 255).astype(np.uint8)
    points = cv2.goodFeaturesToTrack(prev8, max_points, 0.01, 3, mask=inner)
    if points is None or len(points) < min_points:
        return None
    around = cv2.goodFeaturesToTrack(prev8, max_points // 2, 0.01, 3, mask=outer)
    count = len(points)
    if around is not None:
        points = np.concatenate([points, around])
    lk = dict(winSize=(15, 15), maxLevel=3, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03))
    moved, ok, _ = cv2.calcOpticalFlowPyrLK(prev8, next8, points, None, **lk)
    back, ok_back, _ = cv2.calcOpticalFlowPyrLK(next8, prev8, moved, None, **lk)
    good = (ok.ravel() == 1) & (ok_back.ravel() == 1) & (np.linalg.norm((back - points)[:, 0], axis=1) < 0.5)
    shift = np.linalg.norm((moved - points)[:, 0], axis=1)
    target = good[:count] & (shift[:count] > min_move)
    if target.sum() < min_points:
        return None
    fit, inliers = cv2.estimateAffinePartial2D(points[:count][target], moved[:count][target], method=cv2.RANSAC,
                                               ransacReprojThreshold=fit_threshold)
    if fit is None or inliers is None or inliers.sum() < min_points:
        return None
    if not 0.8 < np.sqrt(abs(np.linalg.det(fit[:, :2]))) < 1.25:      # no aircraft grows 25 % in a frame
        return None
    ring_good = good[count:]
    if ring_good.sum() >= min_points:          # the surroundings move the same way: a camera that follows the target
        p, q = points[count:][ring_good][:, 0], moved[count:][ring_good][:, 0]
        agree = np.linalg.norm(p @ fit[:, :2].T + fit[:, 2] - q, axis=1) < fit_threshold
        if agree.mean() > max_agree:
            return None
    motion = np.vstack([fit, [0.0, 0.0, 1.0]])
    offset = 0.5 * scale - 0.5                      # pixel centres of the scaled image (as warp_patches)
    to_level = np.array([[scale, 0.0, offset], [0.0, scale, offset], [0.0, 0.0, 1.0]])
    return np.linalg.inv(to_level) @ motion @ to_level
