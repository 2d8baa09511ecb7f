"""Docking guidance from the tracked aircraft: distance to go, lateral offset, closing speed, state (no ROS).

What a visual docking guidance system (VDGS) shows the pilot, computed per frame from the docking
tracker's affine state X̂_t (seed 000 §2: the template's image is the affine quadrilateral) and a
:class:`~aircraft_docking_tracker.docking.stand.StandCalibration`:

1. **The nose in the image**: X̂_t applied to the template's nose point (the aircraft type's
   ``nose_in_template``: p = TL + u (TR - TL) + v (BL - TL) of the tracked quadrilateral).
2. **Its depth, two ways**, both along the nose pixel's ray:
   * *ground plane*: where the ray meets the plane z = nose height (the calibrated camera). Its error
     grows with the square of the depth: Z_g = Δh / ray_z, so a pixel error δv moves it by
     |∂Z_g/∂v| δv ~ Z² δv / (f Δh), and at a low camera (small Δh) a pixel is metres;
   * *apparent size*: the weak-perspective scale of the tracked template, Z_s = f H / h, with H the
     type's template height (ground to fin top: a turn does not shorten it, as it does the span) and h
     the quadrilateral's vertical sides in pixels, times the shortening of a vertical at the nose that the
     calibrated camera predicts (a camera looking down sees verticals short: 1 % at 5 degrees). Its error
     grows only linearly: δZ_s = Z δh / h.
   They disagree in opposite ways at distance -- the ground plane's error explodes, the size's stays
   a fixed fraction -- so they are **fused by inverse variance** on the depth, with σ_g = |∂Z_g/∂v|
   ``pixel_sigma`` and σ_s = Z_s ``size_sigma``: far away the size decides, close to a high camera the
   ground plane does. A ray that does not meet the plane leaves the size alone.
   b. **Near the stop, the nose wheel** (:mod:`~aircraft_docking_tracker.docking.nose_gear`): once the
   template is ``gear_min_height_px`` tall, the aircraft's symmetry axis and the nose wheel's ground
   contact on it are measured in the frame, and when they are found the contact replaces the nose
   pixel: its ground-plane depth is on the apron (z = 0, the camera's whole height above it), with
   ``gear_pixel_sigma``, fused with the size's as above, and the nose is the type's
   ``nose_gear_setback_m`` ahead of the contact along the line. The quadrilateral's sideways and size
   errors (tens of pixels, a few percent, late in an approach) then no longer reach the figures. The two
   depths are independent, so they check each other: with ``gear_agree_sigma``, a contact whose depth lies
   further than that many sigmas from the size's (a tyre-like step on the apron, found under a quadrilateral
   that has slipped) is refused and counted, and the quadrilateral's figure is used.
3. **On the apron**: the fused nose point, projected on the lead-in line (a polyline, entry first):
   ``distance_m`` = arc length from the nose's foot to the stop mark's foot (positive before the
   mark, negative past it); ``lateral_m`` = signed offset from the line, **positive when the nose is
   to the pilot's right** of the line (the pilot faces the camera, so it is the camera's left; the
   display then points the pilot to the left).
4. **Smoothing**: a constant-velocity Kalman filter over (distance, lateral) with white-noise
   acceleration ``accel_sigma`` and the fused measurement's variance; ``speed_mps`` is the closing
   speed, minus the filtered rate of the distance (positive while approaching). A time jump (a stamp
   going back, or a gap over ``max_gap_s``) restarts the filter. **Gate**: once the filter has settled
   (:data:`GATE_AFTER` measurements), a distance more than ``gate_sigma`` sigmas of the innovation
   from the prediction is rejected and counted (an aircraft does not jump; a tracker that slips onto the
   jet bridge does), and the prediction is shown; rejected for longer than ``gate_hold_s``, the filter
   restarts from the new figures. The closing rate is held within ``max_speed_mps``; a rate at that clamp is no
   aircraft (a track that jumped, or re-acquired on the wrong thing), and the approach followed and the time in
   slow down (step 5) count again from there.
5. **State** (as the display shows it): 0 no aircraft (the tracker waits), 1 tracking, 2 slow down
   (within ``slow_down_m`` of the mark), 3 STOP (within ``stop_m`` of the mark, or past it by less than
   ``overshoot_m``; once shown it holds until the aircraft is ``stop_release_m`` beyond ``stop_m``
   again), 4 overshoot (more than ``overshoot_m`` past the mark), 5 lost (the tracker lost the aircraft:
   no figure is shown, and the filter starts afresh on the next track). STOP and overshoot need an
   approach: since the filter (re)started it must have followed the nose ``approach_m`` towards the
   mark, the figure must move slower than ``arrive_mps`` towards it and ``recede_mps`` away from it (an
   aircraft reaches its mark at walking pace, and does not back away), and the nose must be within
   ``stop_lateral_m`` of the lead-in line (a docking nose follows it), else slow down is shown in their place --
   a track that starts on, or restarts onto, something standing near the mark (a vehicle, the jet bridge) shows
   no STOP; slow down must have been shown for
   ``slow_down_min_s`` first, continuously (a tracker that slips between the aircraft and the clutter makes
   the figure jump across the zone in a frame); and STOP and overshoot come on only on a frame whose
   measurement was taken, never while the gate holds the prediction. An aircraft **standing still** (its smoothed
   figure moving less than ``halted_mps`` on average over ``halted_s``) within ``halted_stop_m`` of the mark is shown
   STOP too, with the same guards: a stand whose survey reads its last metres long would otherwise leave an aircraft
   at its mark on slow down. STOP, once shown, is cleared only by a
   measurement of a followed approach (or by the tracker losing the aircraft): a smoothing that restarted
   at the mark -- a tracker that breaks up once the aircraft has stood there -- keeps it on.
6. **At rest under STOP** (``stop_holds``): an aircraft shown STOP brakes to rest at its mark, and a track on it
   that breaks up (a template grown onto the jet bridge, a nose wheel found on the apron) reads it tens of metres
   away. While STOP is shown the smoothing takes the aircraft to be at rest: a measurement the gate rejects -- on
   either figure -- leaves the figures as they were (no prediction, rate 0, the gate not widening), the gate never
   gives up on them (``gate_hold_s`` does not restart the smoothing), and once the figures rest on the nose wheel a
   frame without it is not taken. An aircraft that creeps on past its mark moves a few centimetres a frame: it is
   followed, and shown overshoot.
"""
from __future__ import annotations

import functools
import logging
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ..config import ConfigError, param
from .nose_gear import NOSE_GEAR_DTYPE, measure_nose_gear, template_height
from .stand import AircraftType, StandCalibration, load_stand

NO_AIRCRAFT, TRACKING, SLOW_DOWN, STOP, OVERSHOOT, LOST = range(6)
GUIDANCE_STATES = {NO_AIRCRAFT: "no aircraft", TRACKING: "tracking", SLOW_DOWN: "slow down", STOP: "STOP",
                   OVERSHOOT: "overshoot", LOST: "lost"}

#: The ``docking/guidance`` row (and ``ground_truth/guidance``): distance to go and lateral offset [m],
#: closing speed [m/s] (NaN when there is no figure to show) and the state code above.
GUIDANCE_DTYPE = np.dtype([("distance_m", "<f4"), ("lateral_m", "<f4"), ("speed_mps", "<f4"), ("state", "<i4")])


#: The guidance's parameters' prefix (``guidance.*``) in the node and the tools.
PARAM_PREFIX = "guidance."


@dataclass
class GuidanceConfig:
    """Where the stand file is, which aircraft docks, and the guidance's constants."""

    stand_file: str = param("", "stand calibration file (a name in config/stands, or a path); empty: no guidance "
                            "(start-up only)", read_only=True)
    aircraft_type: str = param("", "aircraft type of the stand file whose stop mark and dimensions apply; empty: "
                               "the file's first (start-up only)", read_only=True)
    pixel_sigma: float = param(3.0, "the tracked nose's position error [px, 1 sigma] (ground-plane range's weight)",
                               low=0.01, high=1000.0)
    size_sigma: float = param(0.1, "the tracked template's relative size error [1 sigma] (apparent-size range's "
                              "weight; tracked quadrilaterals are a few percent off late in an approach, tens in the "
                              "worst runs)", low=1e-4, high=1.0)
    accel_sigma: float = param(8.0, "white-noise acceleration of the smoothing filter [m/s^2] (how closely it follows "
                               "the figures: the nose wheel's are good to a pixel, and a filter that lags shows STOP "
                               "late or a false overshoot)", low=1e-3, high=100.0)
    max_gap_s: float = param(1.0, "a gap between frames longer than this [s] (or a stamp going back) restarts "
                             "the smoothing", low=0.0, high=3600.0)
    slow_down_m: float = param(15.0, "slow down shown within this distance of the stop mark [m]", low=0.0,
                               high=1000.0)
    stop_m: float = param(0.15, "STOP shown once the distance to go is at or below this [m] (inside the +-0.5 m an "
                          "advanced VDGS stops to: a figure a tenth of a metre long at the mark still shows STOP; "
                          "longer ones have halted_stop_m). 0.25 until session 31: stands whose survey reads short "
                          "then showed STOP 0.55-1.07 m early (fresh 7010, 7012, 8019); 0.15 changed no other STOP's "
                          "verdict on 360 runs, 0.1 lost one", low=-10.0, high=10.0)
    stop_release_m: float = param(0.5, "STOP, once shown, holds until the distance is this much above stop_m [m]",
                                  low=0.0, high=100.0)
    overshoot_m: float = param(0.5, "overshoot shown when the nose is more than this past the mark [m]", low=0.0,
                               high=100.0)
    gate_sigma: float = param(8.0, "a measured distance further than this many sigmas from the smoothing's "
                              "prediction is rejected and counted (an aircraft does not jump); 0: no gate",
                              low=0.0, high=1000.0)
    gate_hold_s: float = param(1.0, "rejected for longer than this [s], the smoothing restarts from the new figures "
                               "(the gate holds its prediction until then)", low=0.0, high=60.0)
    max_speed_mps: float = param(12.0, "the smoothing's closing speed is held within this [m/s] (an aircraft taxies "
                                 "in at a few; a two-point start on noisy figures can give a rate of tens); a rate at "
                                 "it is no aircraft: STOP and overshoot need an approach followed anew after it",
                                 low=0.1, high=1000.0)
    approach_m: float = param(3.0, "STOP and overshoot are shown only once the smoothing has followed the nose "
                              "this far towards the mark since it (re)started [m] (a lock on something standing, "
                              "or a figure that jumps, shows slow down instead)", low=0.0, high=1000.0)
    slow_down_min_s: float = param(1.5, "STOP and overshoot are shown only after slow down was shown this long, "
                                   "continuously, since the smoothing (re)started [s] (an aircraft covers the last "
                                   "slow_down_m in several seconds; a figure that jumps to the mark does not)",
                                   low=0.0, high=60.0)
    recede_mps: float = param(2.0, "STOP and overshoot come on only while the figure does not recede faster than this "
                              "[m/s] (the closing speed at least minus this): an aircraft at its mark does not back "
                              "away; a track on something else that ran through the mark and comes back does "
                              "(fresh approach 1009: STOP shown 108 m early, the figure coming back from overshoot). "
                              "Of the 240 guidance bench runs (tuning, held out, two fresh sets) 0.5, 1 and 2 change "
                              "the same two: that one, and a tuning STOP first shown at 0.07 m, now at 0.0 m; "
                              "1000: off", low=0.0, high=1000.0)
    arrive_mps: float = param(2.0, "STOP and overshoot come on only while the figure closes no faster than this [m/s]: "
                              "an aircraft reaches its mark at walking pace (the bench's at 0.5-1.4 m/s); a figure "
                              "that leaps there does not (a track on something else, a nose wheel's row a few pixels "
                              "off for a frame). On the 240 guidance bench runs 2, 2.5, 3 and 4 take every STOP shown "
                              "more than 1 m early (6 runs of 240, one 171 m: one now shows no STOP, the others "
                              "within 0.5 m) and put none outside 0.5 m; the tuning set chose 2; 1000: off",
                              low=0.0, high=1000.0)
    stop_lateral_m: float = param(3.0, "STOP and overshoot come on only while the nose is within this of the lead-in "
                                  "line [m]: a docking nose follows the line (every STOP within 0.5 m of the mark on "
                                  "420 bench runs came 0.40 m or less off it), a track on something standing beside "
                                  "it need not (with session 32's nose-wheel edge two such tracks showed STOP 19 and "
                                  "151 m early, 5.9 and 9.8 m off the line; no other run changes); 1000: off",
                                  low=0.0, high=1000.0)
    halted_stop_m: float = param(0.5, "STOP is also shown for an aircraft standing still within this of the mark [m] "
                                 "(the +-0.5 m an advanced VDGS stops to): a stand surveyed to half a pixel can read "
                                 "its last metres a few tenths long, and an aircraft stood at its mark without STOP "
                                 "(8 of the 240 guidance bench runs, 0.3-0.45 m long: fresh approaches 1012 and "
                                 "1018, held-out 217); at or below stop_m: off", low=0.0, high=10.0)
    halted_mps: float = param(0.1, "standing still: the smoothed figure moved less than this on average over the last "
                              "halted_s, every frame measured [m/s] (the smoothing's rate alone swings by tenths at a "
                              "standstill); 0.1 to 0.2 change the same runs", low=0.0, high=10.0)
    halted_s: float = param(1.0, "standing still: over this long [s] (1 and 2 change the same runs)", low=0.01,
                            high=60.0)
    stop_holds: bool = param(True, "while STOP is shown the aircraft is braking to rest at its mark: a measurement the "
                             "gate rejects (on either figure) leaves the figures where they were (no prediction, rate "
                             "0), the gate never gives up on them (no gate_hold_s restart), and once the nose wheel is "
                             "measured a figure without it is not taken. A creep past the mark is still followed, "
                             "frame by frame, to overshoot. A tracker that breaks up on the parked aircraft had shown "
                             "it 20-45 m past its mark under STOP (fresh approaches 6001, 6007, 6010; held out 201, "
                             "207, 219)")
    gear_pixel_sigma: float = param(0.25, "the nose wheel's measured ground contact's error [px, 1 sigma] (its "
                                    "range's weight)", low=0.01, high=1000.0)
    gear_min_height_px: float = param(80.0, "measure the nose wheel's ground contact once the tracked template "
                                      "is at least this tall [px]; 0: never (the quadrilateral alone)", low=0.0,
                                      high=10000.0)
    gear_search: float = param(0.5, "the aircraft's symmetry axis is searched this far either side of the "
                               "tracked nose [template heights]", low=0.01, high=1.0)
    gear_window: float = param(0.12, "the symmetry window's half-width, and the tyre's search either side of where "
                               "the template puts it when a symmetric axis is chosen (gear_axes) [template heights]",
                               low=0.01, high=0.5)
    gear_contact_window: float = param(0.15, "the ground contact's search either side of where the tracked "
                                       "template puts it [template heights] (a template a quarter too small or "
                                       "too large puts the tyre a window or more off; 0.12, the symmetry's "
                                       "window, until session 36; on the tuning set 0.21 takes steps far below "
                                       "the tyre)", low=0.01, high=0.5)
    gear_lowest_step: float = param(0.75, "the ground contact is the lowest peak of the tyre-to-apron step in its "
                                    "search that reaches this fraction of the largest there: under the tyre there "
                                    "is only apron, and a strong step above it (tuning 114: 30 px up, the largest "
                                    "on most frames) is not the contact; 0: the largest step", low=0.0, high=1.0)
    gear_band: float = param(0.02, "the ground contact's grey profile is averaged this far either side of the "
                             "axis [template heights]", low=0.0, high=0.2)
    gear_min_symmetry: float = param(0.5, "the mirror correlation a symmetry axis needs", low=-1.0, high=1.0)
    gear_min_contrast: float = param(12.0, "the step from tyre to apron a ground contact needs [grey levels]",
                                     low=0.0, high=255.0)
    gear_axes: int = param(3, "how many symmetric axes (the best about each peak of the coarse search, most "
                           "symmetric first) are looked at for the nose wheel: the first whose tyre-to-apron step "
                           "reaches gear_axis_contrast is taken (an engine's round cowl can be as symmetric as the "
                           "nose, but has no tyre under it), the most symmetric if none does; 1: the most symmetric "
                           "axis alone", low=1, high=3)
    gear_axis_contrast: float = param(30.0, "the tyre-to-apron step that makes a symmetric axis the nose wheel's "
                                      "when several are looked at (gear_axes) [grey levels]", low=0.0, high=255.0)
    gear_agree_sigma: float = param(0.0, "a measured ground contact whose range lies further than this many sigmas "
                                    "from the apparent size's is not taken for the nose wheel (a step on the apron "
                                    "is); 0: every contact is taken", low=0.0, high=1000.0)

    def validate(self) -> None:
        """A stand file that exists and passes every check, holding ``aircraft_type`` (the one validation every
        parameter goes through: a bad file is refused like any bad value, with the key at fault)."""
        if self.stand_file:
            stand = load_stand(self.stand_file)
            if self.aircraft_type:
                stand.aircraft_type(self.aircraft_type)
        elif self.aircraft_type:
            raise ConfigError("aircraft_type is set but there is no stand_file to hold it", ("aircraft_type",))


@dataclass
class GuidanceResult:
    """One frame's guidance; the figures are NaN when no aircraft is tracked."""

    state: int = NO_AIRCRAFT
    distance_m: float = float("nan")
    lateral_m: float = float("nan")
    speed_mps: float = float("nan")
    nose_px: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    nose_stand: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))   # fused, unsmoothed [m]
    depth_ground_m: float = float("nan")          # optical-axis depth of the nose from the ground plane
    depth_size_m: float = float("nan")            # ... and from the apparent size
    gear_measured: bool = False                   # the nose wheel's ground contact was measured
    gear_refused: bool = False                    # ... and refused: its range disagreed with the size's
    measurement_taken: bool = True                # False: the gate rejected this frame's measurement

    def row(self) -> np.ndarray:
        """This frame as a one-row :data:`GUIDANCE_DTYPE` table."""
        return np.array([(self.distance_m, self.lateral_m, self.speed_mps, self.state)], dtype=GUIDANCE_DTYPE)


# --------------------------------------------------------------------------- geometry
def template_point(quad: np.ndarray, fraction) -> np.ndarray:
    """The point at ``fraction`` (of width, height) of the template, through the affine quadrilateral
    TL, TR, BR, BL: X̂ applied to the template point."""
    quad = np.asarray(quad, np.float64)
    return quad[0] + fraction[0] * (quad[1] - quad[0]) + fraction[1] * (quad[3] - quad[0])


def vertical_extent(quad: np.ndarray) -> float:
    """The quadrilateral's vertical sides (TL-BL, TR-BR), mean length [px]."""
    quad = np.asarray(quad, np.float64)
    return 0.5 * float(np.linalg.norm(quad[3] - quad[0]) + np.linalg.norm(quad[2] - quad[1]))


def _nearest_segment(line: np.ndarray, point) -> tuple[int, float, np.ndarray]:
    """(segment index, arc length of ``point``'s foot from the line's first point, the foot) on the polyline;
    beyond either end the end segment is extended."""
    p = np.asarray(point, np.float64)[:2]
    a, b = line[:-1], line[1:]
    seg = b - a
    length = np.linalg.norm(seg, axis=1)
    t = np.einsum("ij,ij->i", p - a, seg) / length ** 2
    t_clamped = np.clip(t, 0.0, 1.0)
    t_clamped[0] = min(t[0], 1.0)                  # before the entry: extend the first segment
    t_clamped[-1] = max(t_clamped[-1], t[-1])      # past the end: extend the last
    feet = a + t_clamped[:, None] * seg
    i = int(np.argmin(np.linalg.norm(p - feet, axis=1)))
    arc = float(np.concatenate([[0.0], np.cumsum(length)])[i] + t_clamped[i] * length[i])
    return i, arc, feet[i]


def _direction(line: np.ndarray, segment: int) -> np.ndarray:
    step = line[segment + 1] - line[segment]
    return step / np.linalg.norm(step)


def along_line(line: np.ndarray, point) -> tuple[float, float]:
    """(arc length from the line's first point, signed offset positive to the right of the direction of
    travel) of ``point``'s foot on the polyline; beyond either end the end segment is extended."""
    i, arc, foot = _nearest_segment(line, point)
    direction = _direction(line, i)
    right = np.array([direction[1], -direction[0]])
    return arc, float((np.asarray(point, np.float64)[:2] - foot) @ right)


def stop_bar(line: np.ndarray, stop_m, half_length: float = 3.0) -> np.ndarray:
    """(2, 2): a bar across the line through the stop mark's foot, ``half_length`` each side [m] (for display)."""
    i, _, foot = _nearest_segment(line, stop_m)
    direction = _direction(line, i)
    across = half_length * np.array([direction[1], -direction[0]])
    return np.array([foot - across, foot + across])


#: The survey's error at the stop mark (95 %) above which the start-up note warns [m]: half the +-0.5 m an advanced
#: VDGS stops to, the rest being the measurement's.
SURVEY_WARN_M = 0.25


def survey_sigma(stand: StandCalibration, point) -> tuple[float, float]:
    """The survey's error [m, 1 sigma] at the apron ``point`` along the lead-in line and across it: the marks'
    clicking error propagated through the camera's fit (:meth:`StandCalibration.survey_covariance`), projected on
    the line's direction there. It is a bias: the same on every approach to the stand."""
    covariance = stand.survey_covariance(point)
    along = _direction(stand.lead_in, _nearest_segment(stand.lead_in, point)[0])
    across = np.array([-along[1], along[0]])
    return float(np.sqrt(along @ covariance @ along)), float(np.sqrt(across @ covariance @ across))


def survey_note(guidance: DockingGuidance) -> tuple[int, str]:
    """What the stand's survey allows, once at start-up: (logging level, text); a warning when the stop mark's
    distance is surveyed no better than ``SURVEY_WARN_M`` (95 %)."""
    stand, along, across = guidance.stand, *guidance.survey_95_m
    if not np.isfinite(along):
        return logging.WARNING, f"stand {stand.name!r}: the survey's error at the stop mark cannot be told"
    text = (f"stand {stand.name!r}, {guidance.aircraft.name}: the survey puts the stop mark to +-{along:.2f} m "
            f"along the lead-in line and +-{across:.2f} m across (95 %; the marks' residuals, "
            f"{stand.reprojection_px:.2f} px RMS, read as {stand.click_sigma_px:.2f} px a click)")
    if along <= SURVEY_WARN_M:
        return logging.INFO, text
    return logging.WARNING, (text + f": more than {SURVEY_WARN_M:g} m, half of the +-0.5 m an advanced VDGS stops "
                             "to; the distance to go can be that far off on every approach. Add marks near the stop "
                             "and click them to a fraction of a pixel (README, Calibrating a stand)")


def fuse_depths(depths, sigmas) -> tuple[float, float]:
    """Inverse-variance fusion of depth estimates (NaN ones left out): (depth, its sigma); NaN if none."""
    depths, sigmas = np.asarray(depths, np.float64), np.asarray(sigmas, np.float64)
    ok = np.isfinite(depths) & np.isfinite(sigmas) & (sigmas > 0)
    if not ok.any():
        return float("nan"), float("nan")
    weights = 1.0 / sigmas[ok] ** 2
    return float(np.dot(weights, depths[ok]) / weights.sum()), float(1.0 / np.sqrt(weights.sum()))


def vertical_per_metre(stand: StandCalibration, point: np.ndarray) -> np.ndarray:
    """The image vector [px per metre] of the apron's vertical at the stand ``point`` [m], downwards: its drop to the
    apron over its height (1 m down if it is on the apron or below)."""
    height = float(point[2]) if point[2] > 0 else 1.0
    return np.diff(stand.camera.project([point, point - (0.0, 0.0, height)]), axis=0)[0] / height


def size_depth(stand: StandCalibration, aircraft: AircraftType, quad: np.ndarray) -> float:
    """The nose's optical-axis depth from the template's apparent height (step 2) [m]: Z_s = f H / h, then
    times the shortening of the vertical below the nose that the calibrated camera predicts (its pixels per
    metre over f / Z_s; one step: it changes slowly with the depth). A camera looking down 5 degrees sees it
    about 1 % short, which f H / h alone reads as 1 % further."""
    extent = vertical_extent(quad)
    if not extent > 0:
        return float("nan")
    depth = stand.camera.focal_px * aircraft.height_m / extent
    nose = stand.camera.point_at_depth(template_point(quad, aircraft.nose_in_template), depth)[0]
    shortening = float(np.linalg.norm(vertical_per_metre(stand, nose))) * depth / stand.camera.focal_px
    return depth * shortening if np.isfinite(shortening) and shortening > 0 else depth


def contact_depths(stand: StandCalibration, aircraft: AircraftType, depth_size: float, contact: np.ndarray,
                   size_sigma: float, gear_pixel_sigma: float) -> tuple[list[float], list[float]]:
    """The nose wheel's depth two ways, with their sigmas (step 2b): from the apparent size (the nose's, plus the
    wheel's setback: it stands that much further from a camera it faces) and from its ground contact on the apron
    (``gear_pixel_sigma`` pixels of the contact's row, in metres there)."""
    depth_ground, depth_below = stand.camera.depth_on_plane([contact, contact + (0.0, 1.0)], 0.0)
    return ([depth_size + aircraft.nose_gear_setback_m, float(depth_ground)],
            [depth_size * size_sigma, abs(depth_ground - depth_below) * gear_pixel_sigma])


def contact_disagreement(stand: StandCalibration, aircraft: AircraftType, depth_size: float, gear: np.ndarray,
                         size_sigma: float, gear_pixel_sigma: float) -> float:
    """How many sigmas apart the two independent depths of :func:`contact_depths` are, the quadrilateral's
    :func:`size_depth` being ``depth_size`` (NaN if either is missing: :meth:`DockingGuidance.measure` then refuses
    the contact).
    A contact on the nose wheel agrees with the size to a few of the size's 10 %; a tyre-to-apron step found on
    the apron below a quadrilateral that has slipped lies tens of metres off."""
    contact = np.array([float(gear["ground_x"][0]), float(gear["ground_y"][0])])
    (a, b), (sa, sb) = contact_depths(stand, aircraft, depth_size, contact, size_sigma, gear_pixel_sigma)
    return abs(a - b) / float(np.hypot(sa, sb))


def locate_nose(stand: StandCalibration, aircraft: AircraftType, quad: np.ndarray, pixel_sigma: float,
                size_sigma: float, gear: np.ndarray | None = None,
                gear_pixel_sigma: float = GuidanceConfig.gear_pixel_sigma, depth_size: float | None = None
                ) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """(nose pixel, fused nose point on the stand [m], depth from the ground plane, depth from the size,
    fused depth's sigma [m]) of one tracked quadrilateral (steps 1-2 of the module docstring); with a measured
    nose-wheel ground contact (``gear``, a :data:`~aircraft_docking_tracker.docking.nose_gear.NOSE_GEAR_DTYPE`
    row) the ground-plane depth is the contact's on the apron, and the nose is ``nose_gear_setback_m`` ahead
    of it along the lead-in line (step 2b). ``depth_size``: the quadrilateral's :func:`size_depth` if known."""
    camera = stand.camera
    depth_size = size_depth(stand, aircraft, quad) if depth_size is None else depth_size
    if gear is not None and np.isfinite(gear["ground_y"]).all():
        contact = np.array([float(gear["ground_x"][0]), float(gear["ground_y"][0])])
        depths, sigmas = contact_depths(stand, aircraft, depth_size, contact, size_sigma, gear_pixel_sigma)
        depth, sigma = fuse_depths(depths, sigmas)
        depth_ground = depths[1]
        if not np.isfinite(depth):
            return contact, np.full(3, np.nan), float(depth_ground), float(depth_size), sigma
        foot = camera.point_at_depth(contact, depth)[0][:2]
        i, _, _ = _nearest_segment(stand.lead_in, foot)
        point = np.append(foot + aircraft.nose_gear_setback_m * _direction(stand.lead_in, i), aircraft.nose_height_m)
        nose = np.array([float(gear["axis_x"][0]), float(gear["axis_y"][0])])
        return nose, point, float(depth_ground), float(depth_size), sigma
    nose = template_point(quad, aircraft.nose_in_template)
    depth_ground, depth_below = camera.depth_on_plane([nose, nose + (0.0, 1.0)], aircraft.nose_height_m)
    depth, sigma = fuse_depths([depth_size, depth_ground],
                               [depth_size * size_sigma, abs(depth_ground - depth_below) * pixel_sigma])
    if not np.isfinite(depth):
        return nose, np.full(3, np.nan), float(depth_ground), float(depth_size), sigma
    return nose, camera.point_at_depth(nose, depth)[0], float(depth_ground), float(depth_size), sigma


# --------------------------------------------------------------------------- smoothing
#: Measurements a restarted filter takes before its gate acts: the two-point start's rate is one difference of
#: two noisy figures, and a gate on a wrong rate would reject the right ones while the prediction runs away.
GATE_AFTER = 10


class ConstantVelocityFilter:
    """Independent constant-velocity Kalman filters over a few channels (state: value, rate), white-noise
    acceleration ``accel_sigma`` (filterpy's Q_discrete_white_noise, dim 2)."""

    def __init__(self, channels: int, accel_sigma: float):
        self.accel_sigma = accel_sigma
        self.x = np.zeros((channels, 2))
        self.P = np.zeros((channels, 2, 2))
        self.seen = 0                       # measurements since the (re)start

    def reset(self) -> None:
        self.seen = 0

    def predict(self, dt: float) -> None:
        """The state ``dt`` [s] later (constant velocity; the covariance grows by the white-noise acceleration)."""
        F = np.array([[1.0, dt], [0.0, 1.0]])
        q = self.accel_sigma ** 2 * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
        self.x = self.x @ F.T
        self.P = F @ self.P @ F.T + q

    def step(self, dt: float, z: np.ndarray, r: np.ndarray, gate: float = 0.0,
             max_rate: float = np.inf, at_rest: bool = False) -> tuple[np.ndarray, bool]:
        """Predict over ``dt`` [s], update with measurements ``z`` of variances ``r``; (the filtered (value, rate),
        whether the measurement was taken). The first measurement sets the value (rate 0), the second the rate by
        difference (two-point start). Once ``GATE_AFTER`` are taken, with ``gate`` > 0, a measurement whose first
        channel's innovation exceeds ``gate`` of its sigma (any channel's, for a target ``at_rest``) is not taken:
        the prediction is returned, or, at rest, the state as it was with its rates zeroed (no time passes for it:
        it neither moves nor grows more uncertain, so the gate does not widen). The rates are held within
        ``max_rate``."""
        kept = (self.x.copy(), self.P.copy()) if at_rest else None
        x, taken = self._step(dt, z, r, gate, len(z) if at_rest else 1)
        if not taken and kept is not None:
            self.x, self.P = kept
            x = self.hold()
        self.x[:, 1] = np.clip(self.x[:, 1], -max_rate, max_rate)
        x[:, 1] = self.x[:, 1]
        return x, taken

    def hold(self) -> np.ndarray:
        """A target at rest, not measured: the values stay, the rates are zeroed; the state."""
        self.x[:, 1] = 0.0
        return self.x.copy()

    def _step(self, dt: float, z, r, gate: float, channels: int) -> tuple[np.ndarray, bool]:
        z, r = np.asarray(z, np.float64), np.asarray(r, np.float64)
        if self.seen == 0 or (self.seen == 1 and dt > 0):
            self.seen += 1
            rate = (z - self.x[:, 0]) / dt if self.seen == 2 else np.zeros_like(z)
            self.x[:, 0], self.x[:, 1] = z, rate
            self.P[:] = 0.0
            self.P[:, 0, 0] = r
            self.P[:, 1, 1] = 2 * r / dt ** 2 if self.seen == 2 else 1e6
            self.P[:, 0, 1] = self.P[:, 1, 0] = r / dt if self.seen == 2 else 0.0
            return self.x.copy(), True
        self.predict(dt)
        innovation = z - self.x[:, 0]
        s = self.P[:, 0, 0] + r
        if gate > 0 and self.seen >= GATE_AFTER and (np.abs(innovation) > gate * np.sqrt(s))[:channels].any():
            return self.x.copy(), False
        self.seen += 1
        gain = self.P[:, :, 0] / s[:, None]
        self.x += gain * innovation[:, None]
        self.P -= gain[:, :, None] * self.P[:, None, 0, :]
        return self.x.copy(), True


# --------------------------------------------------------------------------- the guidance
class DockingGuidance:
    """Per frame: the tracker's quadrilateral (or None) and state -> :class:`GuidanceResult`."""

    def __init__(self, stand: StandCalibration, config: GuidanceConfig | None = None):
        self.stand = stand
        self.config = config or GuidanceConfig()
        self.aircraft = stand.aircraft_type(self.config.aircraft_type or next(iter(stand.aircraft)))
        self.stop_arc = along_line(stand.lead_in, self.aircraft.stop_m)[0]
        self.stop_bar = stop_bar(stand.lead_in, self.aircraft.stop_m)
        self.filter = ConstantVelocityFilter(2, self.config.accel_sigma)
        self.last_stamp_ns: int | None = None
        self.showing_stop = False
        self.restarts = 0                 # smoothing restarted by a time jump
        self.rejected = 0                 # measurements the gate rejected
        self.gear_measured = 0            # frames measured at the nose wheel
        self.gear_refused = 0             # contacts refused: their range disagreed with the size's
        self.stop_withheld = 0            # frames STOP or overshoot was withheld: too fast, or off the line
        self.halted_stops = 0             # STOPs shown for an aircraft standing still (halted_stop_m)
        self.held_at_stop = 0             # frames under STOP whose measurement was not taken (stop_holds)
        self.last_taken_ns: int | None = None
        self.last_taken_gear = False      # the last measurement taken was of the nose wheel
        self.farthest_m = float("nan")    # the farthest smoothed distance since the smoothing (re)started
        self._depth_of = None             # (the last quadrilateral, its size_depth)
        self.slow_since_ns: int | None = None   # when slow down (or nearer) was first shown, continuously
        self.recent: deque = deque()      # (stamp, smoothed distance) of the measured frames of the last halted_s

    @functools.cached_property
    def survey_sigma_m(self) -> tuple[float, float]:
        """The survey's error at the stop mark [m, 1 sigma], along the lead-in line and across it (:func:`survey_sigma`;
        2N camera refits: made when first asked, not with every guidance)."""
        return survey_sigma(self.stand, self.aircraft.stop_m)

    @property
    def survey_95_m(self) -> tuple[float, float]:
        """:attr:`survey_sigma_m` at 95 % (two sigmas) [m], as the start-up note and the diagnostics give it."""
        along, across = self.survey_sigma_m
        return 2 * along, 2 * across

    def reset(self) -> None:
        self.restart()
        self.last_stamp_ns = self.last_taken_ns = None
        self.showing_stop = False

    def restart(self) -> None:
        """The smoothing starts afresh: no rate, and no approach followed yet."""
        self.filter.reset()
        self.last_taken_gear = False
        self.farthest_m = float("nan")
        self.slow_since_ns = None
        self.recent.clear()

    def configure(self, config: GuidanceConfig) -> None:
        """New constants (the stand and the aircraft type stay as they were built)."""
        self.config = replace(config, stand_file=self.config.stand_file, aircraft_type=self.config.aircraft_type)
        self.filter.accel_sigma = config.accel_sigma

    def measure_gear(self, image: np.ndarray, quad: np.ndarray | None) -> np.ndarray:
        """The nose wheel's ground contact in ``image`` (grey or BGR) under the tracked ``quad``: one
        :data:`~aircraft_docking_tracker.docking.nose_gear.NOSE_GEAR_DTYPE` row (NaN where not measured)."""
        cfg = self.config
        if quad is None or cfg.gear_min_height_px <= 0 or template_height(quad) < cfg.gear_min_height_px:
            return np.full(1, np.nan, NOSE_GEAR_DTYPE)
        return measure_nose_gear(image, quad, self.aircraft.nose_in_template, self.aircraft.ground_in_template,
                                 self.vertical_at(quad), min_height_px=cfg.gear_min_height_px, search=cfg.gear_search,
                                 window=cfg.gear_window, band=cfg.gear_band, min_symmetry=cfg.gear_min_symmetry,
                                 min_contrast=cfg.gear_min_contrast, axes=cfg.gear_axes,
                                 axis_contrast=cfg.gear_axis_contrast, contact_window=cfg.gear_contact_window,
                                 lowest_step=cfg.gear_lowest_step)

    def vertical_at(self, quad: np.ndarray) -> np.ndarray | None:
        """The image direction of the apron's vertical (down) at the tracked nose, from the calibrated camera."""
        camera = self.stand.camera
        depth = self.size_depth(quad)
        if not np.isfinite(depth):
            return None
        nose = camera.point_at_depth(template_point(quad, self.aircraft.nose_in_template), depth)[0]
        down = vertical_per_metre(self.stand, nose)
        return down if np.isfinite(down).all() and np.linalg.norm(down) > 0 else None

    def size_depth(self, quad: np.ndarray) -> float:
        """:func:`size_depth` of ``quad``, computed once a tracked quadrilateral (:meth:`measure_gear` and
        :meth:`measure` both need it)."""
        if self._depth_of is None or not np.array_equal(self._depth_of[0], quad):
            self._depth_of = (np.array(quad, np.float64), size_depth(self.stand, self.aircraft, quad))
        return self._depth_of[1]

    def measure(self, quad: np.ndarray, gear: np.ndarray | None = None) -> tuple[GuidanceResult, float, float]:
        """One frame's unsmoothed guidance figures, the fused depth's sigma and the lateral offset's [m]."""
        cfg = self.config
        depth_size = self.size_depth(quad)
        measured = gear is not None and bool(np.isfinite(gear["ground_y"]).all())
        refused = measured and cfg.gear_agree_sigma > 0 and not contact_disagreement(
            self.stand, self.aircraft, depth_size, gear, cfg.size_sigma, cfg.gear_pixel_sigma) <= cfg.gear_agree_sigma
        measured = measured and not refused
        nose, point, depth_ground, depth_size, sigma = locate_nose(self.stand, self.aircraft, quad, cfg.pixel_sigma,
                                                                   cfg.size_sigma, gear if measured else None,
                                                                   cfg.gear_pixel_sigma, depth_size)
        result = GuidanceResult(TRACKING, nose_px=nose, nose_stand=point, depth_ground_m=depth_ground,
                                depth_size_m=depth_size, gear_measured=measured, gear_refused=refused)
        lateral_sigma = float("nan")
        if np.isfinite(point).all():
            arc, result.lateral_m = along_line(self.stand.lead_in, point)
            result.distance_m = self.stop_arc - arc
            lateral_sigma = (cfg.gear_pixel_sigma if measured else cfg.pixel_sigma) \
                * float(np.linalg.norm(point - self.stand.camera.centre)) / self.stand.camera.focal_px
        return result, sigma, lateral_sigma

    def update(self, quad: np.ndarray | None, tracking: bool, lost: bool, stamp_ns: int,
               gear: np.ndarray | None = None) -> GuidanceResult:
        """The guidance for one frame: ``quad`` the tracked quadrilateral (None while waiting), ``tracking``
        whether the tracker reports it, ``lost`` whether it lost it, ``gear`` this frame's
        :meth:`measure_gear` (None: the quadrilateral alone)."""
        cfg = self.config
        if quad is None or not (tracking or lost):
            self.reset()
            return GuidanceResult(NO_AIRCRAFT)
        if lost:
            self.reset()
            return GuidanceResult(LOST)
        result, sigma, lateral_sigma = self.measure(quad, gear)
        if not np.isfinite(result.distance_m):
            self.reset()
            return GuidanceResult(LOST, nose_px=result.nose_px)
        self.gear_measured += result.gear_measured
        self.gear_refused += result.gear_refused
        dt = (stamp_ns - self.last_stamp_ns) * 1e-9 if self.last_stamp_ns is not None else 0.0
        at_rest = self.showing_stop and cfg.stop_holds          # step 6
        if self.last_stamp_ns is not None and not (0.0 < dt <= cfg.max_gap_s):
            self.restarts += 1
            self.restart()
        elif (not at_rest and self.last_taken_ns is not None
              and (stamp_ns - self.last_taken_ns) * 1e-9 > cfg.gate_hold_s):
            self.restart()               # rejected for longer than gate_hold_s: the aircraft is where it is now
        self.last_stamp_ns = stamp_ns
        if at_rest and self.last_taken_gear and not result.gear_measured:
            filtered, taken = self.filter.hold(), False    # the nose wheel's figures are not left for the template's
        else:
            filtered, taken = self.filter.step(dt, [result.distance_m, result.lateral_m],
                                               [sigma ** 2, lateral_sigma ** 2], cfg.gate_sigma, cfg.max_speed_mps,
                                               at_rest=at_rest)
        (distance, rate), (lateral, _) = filtered
        if taken:
            self.last_taken_ns, self.last_taken_gear = stamp_ns, result.gear_measured
        else:
            self.rejected += 1
            self.held_at_stop += at_rest
        result.measurement_taken = taken
        result.distance_m, result.lateral_m, result.speed_mps = float(distance), float(lateral), float(-rate)
        if abs(rate) >= cfg.max_speed_mps:
            # a figure moving at the clamp is no aircraft (a track that jumped, a restart on the wrong thing): the
            # approach followed and the time in slow down count again from here
            self.farthest_m, self.slow_since_ns = float(distance), None
        elif taken:
            self.farthest_m = float(np.fmax(self.farthest_m, distance))
        halted = self.standing_still(stamp_ns, result.distance_m if taken else None)
        # STOP and overshoot come on with a measurement, never with a prediction alone, after an approach followed
        # and slow down shown long enough; STOP shown stays on until a measurement of a followed approach clears it
        in_zone_s = (stamp_ns - self.slow_since_ns) * 1e-9 if self.slow_since_ns is not None else 0.0
        approached = taken and self.farthest_m - result.distance_m >= cfg.approach_m
        # an aircraft arriving: at walking pace, not backing away, and on its lead-in line
        plausible = (-cfg.recede_mps <= result.speed_mps <= cfg.arrive_mps
                     and abs(result.lateral_m) <= cfg.stop_lateral_m)
        followed = approached and plausible
        result.state = STOP if self.showing_stop and not followed else display_state(
            result.distance_m, self.showing_stop, cfg, followed and in_zone_s >= cfg.slow_down_min_s, halted)
        if (approached and not plausible and in_zone_s >= cfg.slow_down_min_s and result.state == SLOW_DOWN
                and display_state(result.distance_m, self.showing_stop, cfg, True, halted) != SLOW_DOWN):
            self.stop_withheld += 1      # STOP or overshoot but for arrive_mps / recede_mps / stop_lateral_m
        if result.state == STOP and not self.showing_stop and result.distance_m > cfg.stop_m:
            self.halted_stops += 1       # STOP came for an aircraft standing still short of stop_m
        if result.state == TRACKING:
            self.slow_since_ns = None
        elif self.slow_since_ns is None:
            self.slow_since_ns = stamp_ns
        self.showing_stop = result.state == STOP
        return result

    def standing_still(self, stamp_ns: int, distance: float | None) -> bool:
        """Whether the smoothed figure has moved less than ``halted_mps`` x ``halted_s`` over the last ``halted_s``,
        every frame of it measured (``distance`` None: this frame was not, and the window starts again)."""
        cfg = self.config
        if distance is None:
            self.recent.clear()
            return False
        self.recent.append((stamp_ns, distance))
        while len(self.recent) > 1 and (stamp_ns - self.recent[1][0]) * 1e-9 >= cfg.halted_s:
            self.recent.popleft()
        if (stamp_ns - self.recent[0][0]) * 1e-9 < cfg.halted_s:
            return False
        figures = [d for _, d in self.recent]
        return max(figures) - min(figures) <= cfg.halted_mps * cfg.halted_s

    def guide_frame(self, image: np.ndarray, quad: np.ndarray | None, tracking: bool, lost: bool,
                    stamp_ns: int) -> GuidanceResult:
        """:meth:`update` for one frame (grey or BGR), the nose wheel measured in it while tracking: what the node
        and ``sot_track`` call per frame."""
        gear = self.measure_gear(image, quad) if quad is not None and tracking else None
        return self.update(quad, tracking, lost, stamp_ns, gear)


def guide_track(guidance: DockingGuidance, quads: np.ndarray, tracking: np.ndarray, lost: np.ndarray,
                stamps_ns, gears: np.ndarray | None = None) -> np.ndarray:
    """:meth:`DockingGuidance.update` over a whole tracked run (quadrilaterals NaN while waiting), as the node
    calls it frame by frame, with each frame's :meth:`~DockingGuidance.measure_gear` row from ``gears`` if given
    (measured while tracking: it needs the frame); one ``GUIDANCE_DTYPE`` row per frame."""
    rows = np.zeros(len(quads), dtype=GUIDANCE_DTYPE)
    for i, (quad, is_tracking, is_lost, stamp) in enumerate(zip(quads, tracking, lost, stamps_ns)):
        known = np.isfinite(quad).all()
        gear = gears[i:i + 1] if gears is not None else None
        rows[i] = guidance.update(quad if known else None, bool(is_tracking), bool(is_lost), int(stamp),
                                  gear).row()[0]
    return rows


def display_state(distance: float, showing_stop: bool, config: GuidanceConfig, approached: bool = True,
                  halted: bool = False) -> int:
    """The state shown for a distance to go (step 5), given whether STOP is shown now, whether the nose was
    followed ``approach_m`` towards the mark (if not, slow down stands for STOP and overshoot) and whether the
    aircraft stands still (``halted_s`` within ``halted_mps``: then STOP within ``halted_stop_m``)."""
    if approached and distance < -config.overshoot_m:
        return OVERSHOOT
    if approached and (distance <= config.stop_m or (showing_stop and distance <= config.stop_m
                                                     + config.stop_release_m)
                       or (halted and distance <= config.halted_stop_m)):
        return STOP
    return SLOW_DOWN if distance <= config.slow_down_m else TRACKING


def true_guidance(distances, laterals, speeds, config: GuidanceConfig | None = None) -> np.ndarray:
    """The guidance a perfect system shows over an approach (``ground_truth/guidance``): the exact figures,
    and the states :func:`display_state` gives them under ``config``'s thresholds (the defaults)."""
    config = config or GuidanceConfig()
    rows = np.zeros(len(distances), dtype=GUIDANCE_DTYPE)
    showing_stop = False
    for i, (distance, lateral, speed) in enumerate(zip(distances, laterals, speeds)):
        state = display_state(float(distance), showing_stop, config)
        showing_stop = state == STOP
        rows[i] = (distance, lateral, speed, state)
    return rows
