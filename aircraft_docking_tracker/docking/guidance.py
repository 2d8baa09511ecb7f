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
     the quadrilateral's vertical sides in pixels. Its error grows only linearly: δZ_s = Z δh / h.
   They disagree in opposite ways at distance -- the ground plane's error explodes, the size's stays
   a fixed fraction -- so they are **fused by inverse variance** on the depth, with σ_g = |∂Z_g/∂v|
   ``pixel_sigma`` and σ_s = Z_s ``size_sigma``: far away the size decides, close to a high camera the
   ground plane does. A ray that does not meet the plane leaves the size alone.
3. **On the apron**: the fused nose point, projected on the lead-in line (a polyline, entry first):
   ``distance_m`` = arc length from the nose's foot to the stop mark's foot (positive before the
   mark, negative past it); ``lateral_m`` = signed offset from the line, **positive when the nose is
   to the pilot's right** of the line (the pilot faces the camera, so it is the camera's left; the
   display then points the pilot to the left).
4. **Smoothing**: a constant-velocity Kalman filter over (distance, lateral) with white-noise
   acceleration ``accel_sigma`` and the fused measurement's variance; ``speed_mps`` is the closing
   speed, minus the filtered rate of the distance (positive while approaching). A time jump (a stamp
   going back, or a gap over ``max_gap_s``) restarts the filter.
5. **State** (as the display shows it): 0 no aircraft (the tracker waits), 1 tracking, 2 slow down
   (within ``slow_down_m`` of the mark), 3 STOP (within ``stop_m`` of the mark, or past it by less than
   ``overshoot_m``; once shown it holds until the aircraft is ``stop_release_m`` beyond ``stop_m``
   again), 4 overshoot (more than ``overshoot_m`` past the mark), 5 lost (the tracker lost the aircraft:
   no figure is shown, and the filter starts afresh on the next track).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..config import ConfigError, param
from .stand import AircraftType, StandCalibration, load_stand

NO_AIRCRAFT, TRACKING, SLOW_DOWN, STOP, OVERSHOOT, LOST = range(6)
GUIDANCE_STATES = {NO_AIRCRAFT: "no aircraft", TRACKING: "tracking", SLOW_DOWN: "slow down", STOP: "STOP",
                   OVERSHOOT: "overshoot", LOST: "lost"}

#: The ``docking/guidance`` row (and ``ground_truth/guidance``): distance to go and lateral offset [m],
#: closing speed [m/s] (NaN when there is no figure to show) and the state code above.
GUIDANCE_DTYPE = np.dtype([("distance_m", "<f4"), ("lateral_m", "<f4"), ("speed_mps", "<f4"), ("state", "<i4")])


@dataclass
class GuidanceConfig:
    """Where the stand file is, which aircraft docks, and the guidance's constants."""

    stand_file: str = param("", "stand calibration file (a name in config/stands, or a path); empty: no guidance "
                            "(start-up only)", read_only=True)
    aircraft_type: str = param("", "aircraft type of the stand file whose stop mark and dimensions apply; empty: "
                               "the file's first (start-up only)", read_only=True)
    pixel_sigma: float = param(3.0, "the tracked nose's position error [px, 1 sigma] (ground-plane range's weight)",
                               low=0.01, high=1000.0)
    size_sigma: float = param(0.01, "the tracked template's relative size error [1 sigma] (apparent-size range's "
                              "weight)", low=1e-4, high=1.0)
    accel_sigma: float = param(2.0, "white-noise acceleration of the smoothing filter [m/s^2] (an aircraft brakes at "
                               "up to about 2; less lags into a false overshoot at the stop)", low=1e-3, high=100.0)
    max_gap_s: float = param(1.0, "a gap between frames longer than this [s] (or a stamp going back) restarts "
                             "the smoothing", low=0.0, high=3600.0)
    slow_down_m: float = param(15.0, "slow down shown within this distance of the stop mark [m]", low=0.0,
                               high=1000.0)
    stop_m: float = param(0.0, "STOP shown once the distance to go is at or below this [m]", low=-10.0, high=10.0)
    stop_release_m: float = param(0.5, "STOP, once shown, holds until the distance is this much above stop_m [m]",
                                  low=0.0, high=100.0)
    overshoot_m: float = param(0.5, "overshoot shown when the nose is more than this past the mark [m]", low=0.0,
                               high=100.0)

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


def locate_nose(stand: StandCalibration, aircraft: AircraftType, quad: np.ndarray, pixel_sigma: float,
                size_sigma: float) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """(nose pixel, fused nose point on the stand [m], depth from the ground plane, depth from the size,
    fused depth's sigma [m]) of one tracked quadrilateral (steps 1-2 of the module docstring)."""
    camera = stand.camera
    nose = template_point(quad, aircraft.nose_in_template)
    extent = vertical_extent(quad)
    depth_size = camera.focal_px * aircraft.height_m / extent if extent > 0 else np.nan
    depth_ground, depth_below = camera.depth_on_plane([nose, nose + (0.0, 1.0)], aircraft.nose_height_m)
    weights, depths = [], []
    if np.isfinite(depth_size):
        weights.append(1.0 / (depth_size * size_sigma) ** 2)
        depths.append(depth_size)
    if np.isfinite(depth_ground) and np.isfinite(depth_below):
        weights.append(1.0 / ((depth_ground - depth_below) * pixel_sigma) ** 2)
        depths.append(depth_ground)
    if not weights:
        return nose, np.full(3, np.nan), float(depth_ground), float(depth_size), float("nan")
    depth = float(np.dot(weights, depths) / np.sum(weights))
    return (nose, camera.point_at_depth(nose, depth)[0], float(depth_ground), float(depth_size),
            float(1.0 / np.sqrt(np.sum(weights))))


# --------------------------------------------------------------------------- smoothing
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

    def step(self, dt: float, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Predict over ``dt`` [s], update with measurements ``z`` of variances ``r``; the filtered (value, rate).
        The first measurement sets the value (rate 0), the second the rate by difference (two-point start)."""
        z, r = np.asarray(z, np.float64), np.asarray(r, np.float64)
        self.seen += 1
        if self.seen == 1 or (self.seen == 2 and dt > 0):
            rate = (z - self.x[:, 0]) / dt if self.seen == 2 else np.zeros_like(z)
            self.x[:, 0], self.x[:, 1] = z, rate
            self.P[:] = 0.0
            self.P[:, 0, 0] = r
            self.P[:, 1, 1] = 2 * r / dt ** 2 if self.seen == 2 else 1e6
            self.P[:, 0, 1] = self.P[:, 1, 0] = r / dt if self.seen == 2 else 0.0
            return self.x.copy()
        F = np.array([[1.0, dt], [0.0, 1.0]])
        q = self.accel_sigma ** 2 * np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]])
        self.x = self.x @ F.T
        self.P = F @ self.P @ F.T + q
        innovation = z - self.x[:, 0]
        s = self.P[:, 0, 0] + r
        gain = self.P[:, :, 0] / s[:, None]
        self.x += gain * innovation[:, None]
        self.P -= gain[:, :, None] * self.P[:, None, 0, :]
        return self.x.copy()


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

    def reset(self) -> None:
        self.filter.reset()
        self.last_stamp_ns = None
        self.showing_stop = False

    def configure(self, config: GuidanceConfig) -> None:
        """New constants (the stand and the aircraft type stay as they were built)."""
        self.config = replace(config, stand_file=self.config.stand_file, aircraft_type=self.config.aircraft_type)
        self.filter.accel_sigma = config.accel_sigma

    def measure(self, quad: np.ndarray) -> tuple[GuidanceResult, float]:
        """One frame's unsmoothed guidance figures and the fused depth's sigma [m]."""
        cfg = self.config
        nose, point, depth_ground, depth_size, sigma = locate_nose(self.stand, self.aircraft, quad, cfg.pixel_sigma,
                                                                   cfg.size_sigma)
        result = GuidanceResult(TRACKING, nose_px=nose, nose_stand=point, depth_ground_m=depth_ground,
                                depth_size_m=depth_size)
        if np.isfinite(point).all():
            arc, result.lateral_m = along_line(self.stand.lead_in, point)
            result.distance_m = self.stop_arc - arc
        return result, sigma

    def update(self, quad: np.ndarray | None, tracking: bool, lost: bool, stamp_ns: int) -> GuidanceResult:
        """The guidance for one frame: ``quad`` the tracked quadrilateral (None while waiting), ``tracking``
        whether the tracker reports it, ``lost`` whether it lost it."""
        cfg = self.config
        if quad is None or not (tracking or lost):
            self.reset()
            return GuidanceResult(NO_AIRCRAFT)
        if lost:
            self.reset()
            return GuidanceResult(LOST)
        result, sigma = self.measure(quad)
        if not np.isfinite(result.distance_m):
            self.reset()
            return GuidanceResult(LOST, nose_px=result.nose_px)
        dt = (stamp_ns - self.last_stamp_ns) * 1e-9 if self.last_stamp_ns is not None else 0.0
        if self.last_stamp_ns is not None and not (0.0 < dt <= cfg.max_gap_s):
            self.restarts += 1
            self.filter.reset()
        self.last_stamp_ns = stamp_ns
        lateral_sigma = cfg.pixel_sigma * float(np.linalg.norm(result.nose_stand - self.stand.camera.centre)) \
            / self.stand.camera.focal_px
        (distance, rate), (lateral, _) = self.filter.step(dt, [result.distance_m, result.lateral_m],
                                                          [sigma ** 2, lateral_sigma ** 2])
        result.distance_m, result.lateral_m, result.speed_mps = float(distance), float(lateral), float(-rate)
        result.state = display_state(result.distance_m, self.showing_stop, cfg)
        self.showing_stop = result.state == STOP
        return result


def guide_track(guidance: DockingGuidance, quads: np.ndarray, tracking: np.ndarray, lost: np.ndarray,
                stamps_ns) -> np.ndarray:
    """:meth:`DockingGuidance.update` over a whole tracked run (quadrilaterals NaN while waiting), as the node
    calls it frame by frame; one ``GUIDANCE_DTYPE`` row per frame."""
    rows = np.zeros(len(quads), dtype=GUIDANCE_DTYPE)
    for i, (quad, is_tracking, is_lost, stamp) in enumerate(zip(quads, tracking, lost, stamps_ns)):
        known = np.isfinite(quad).all()
        rows[i] = guidance.update(quad if known else None, bool(is_tracking), bool(is_lost), int(stamp)).row()[0]
    return rows


def display_state(distance: float, showing_stop: bool, config: GuidanceConfig) -> int:
    """The state shown for a distance to go (step 5), given whether STOP is shown now."""
    if distance < -config.overshoot_m:
        return OVERSHOOT
    if distance <= config.stop_m or (showing_stop and distance <= config.stop_m + config.stop_release_m):
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
