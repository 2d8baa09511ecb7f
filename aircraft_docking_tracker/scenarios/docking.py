"""Synthetic docking scene: an aircraft taxis onto its stand, seen by the fixed stand camera (no ROS).

What it shows (issue 3): a fixed camera at the stand looking down the lead-in line; an aircraft
(fuselage, wings, engines, tail fin, livery) taxis along a curved lead-in line and stops at the
stop line; its image grows by ``growth`` (>= 4x) and turns by ``turn_deg`` (20-40 deg); lighting
drifts; sensor noise; rain or a low sun at some seeds; a ground vehicle crossing in front or the
jet bridge hides part of it.

The geometry is exact by construction. The aircraft is a sprite drawn once in *template*
coordinates (a ``TEMPLATE_W x TEMPLATE_H`` rectangle, 36 m wingspan); each frame it is pasted
through one affine map ``A_t`` (3x3). So the ground truth, the image of the template rectangle
under ``A_t`` in the order TL, TR, BR, BL, is the affine quadrilateral the docking tracker
estimates (seed 000's state X is such a matrix), and the nose is ``A_t`` applied to the template's
nose point. ``A_t`` comes from a pinhole camera: the nose's ground position along the lead-in
line is projected to the image, the scale is focal / depth, the in-image rotation follows the
heading's deviation from the final line; the template's vertical is scaled so that the nose wheel's
ground contact is drawn where the camera sees the nose's foot on the apron (exactly so on the final
straight, where the heading's deviation is 0), so that the wheel's contact is as true as the nose.

Ground frame: metres, origin at the stop position of the nose, +Y away from the camera along the
final straight of the lead-in line, +X to the right as the camera sees it, Z up.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Iterator

import cv2
import numpy as np

from aircraft_docking_tracker.config import param, validate
from aircraft_docking_tracker.scenarios import render

TEMPLATE_W, TEMPLATE_H = 400, 200          # template rectangle [template px]
WINGSPAN_M = 36.0                         # template width in metres (A320-like)
M_PER_TPL = WINGSPAN_M / TEMPLATE_W
NOSE_TPL = np.array([200.0, 150.0])       # nose point in template pixels
GROUND_TPL_Y = 196.0                      # the wheels touch the ground at this template row
NOSE_HEIGHT_M = (GROUND_TPL_Y - NOSE_TPL[1]) * M_PER_TPL
SPRITE_SCALE = 2                          # the sprite is drawn at 2x the template resolution
SUPERSAMPLE = 8                           # ... each of its pixels from 8 x 8 samples
_SHIFT = 4                                # fractional bits of OpenCV's drawing coordinates


@dataclass
class DockingSceneConfig(render.StreamConfig):
    """Everything that shapes a docking scene (the seed picks the rest)."""

    fps: float = param(14.0, "camera frame rate [Hz] (seed 000's camera: 14)", low=1.0, high=120.0)
    difficulty: int = param(1, "0 easy (clear, little noise), 1 normal, 2 hard (noise, weather, occlusion)",
                            low=0, high=2)
    weather: str = param("auto", "weather; auto: chosen by the seed", choices=("auto", "clear", "rain", "low_sun"))
    occluder: str = param("auto", "what hides part of the aircraft; auto: chosen by the seed",
                          choices=("auto", "none", "vehicle", "jet_bridge", "both"))
    growth: float = param(0.0, "image scale at the stop / at the start; 0: seed picks 4-6", low=0.0, high=20.0)
    turn_deg: float = param(0.0, "heading change along the lead-in curve [deg]; 0: seed picks 20-40",
                            low=0.0, high=90.0)
    stop_fraction: float = param(0.15, "fraction of the frames spent standing at the stop line", low=0.0, high=0.9)
    camera_height_m: float = param(6.0, "stand camera height above the apron [m]", low=1.0, high=50.0)
    camera_distance_m: float = param(45.0, "stand camera distance in front of the stop position [m]",
                                     low=10.0, high=500.0)
    pitch_deg: float = param(5.0, "stand camera downward pitch [deg]", low=0.0, high=45.0)
    lateral_offset_m: float = param(0.0, "how far the nose wanders off the lead-in line [m, amplitude]: a slow "
                                    "sway that shrinks to 30 % of it at the stop; 0: on the line", low=0.0, high=10.0)


@dataclass
class DockingFrame:
    """One rendered frame and its ground truth."""

    index: int
    stamp_ns: int
    image: np.ndarray                     # (H, W, 3) uint8 BGR
    affine: np.ndarray                    # (3, 3) template -> image
    quad: np.ndarray                      # (4, 2) TL, TR, BR, BL of the template rectangle in the image
    nose: np.ndarray                      # (2,) nose in the image
    nose_ground: np.ndarray               # (2,) nose on the apron [m]
    guidance: np.ndarray                  # (3,) exact distance to go [m], lateral offset [m] (pilot's right +), closing speed [m/s]
    mask: np.ndarray                      # (H, W) float32 aircraft alpha before occluders
    visible: np.ndarray                   # (H, W) float32 aircraft alpha after occluders
    occluded_fraction: float = 0.0


class StandCamera:
    """Pinhole camera at (0, -distance, height) looking along +Y, pitched down."""

    def __init__(self, width: int, height: int, distance_m: float, height_m: float, pitch_deg: float):
        self.width, self.height = width, height
        self.f = min(0.9 * width, 1.2 * height)         # the whole aircraft in view at 4:3 and 16:9
        self.cx, self.cy = width / 2.0, height / 2.0
        self.position = np.array([0.0, -distance_m, height_m])
        p = np.radians(pitch_deg)
        self.pitch_deg = pitch_deg
        self.forward = np.array([0.0, np.cos(p), -np.sin(p)])
        self.down = np.array([0.0, -np.sin(p), -np.cos(p)])
        self.right = np.array([1.0, 0.0, 0.0])

    def depth(self, points) -> np.ndarray:
        return (np.atleast_2d(points) - self.position) @ self.forward

    def project(self, points) -> np.ndarray:
        """Ground-frame points (N, 3) [m] -> image points (N, 2) [px]."""
        d = np.atleast_2d(np.asarray(points, np.float64)) - self.position
        z = d @ self.forward
        return np.stack([self.cx + self.f * (d @ self.right) / z, self.cy + self.f * (d @ self.down) / z], axis=1)

    def as_dict(self) -> dict:
        return {"width": self.width, "height": self.height, "focal_px": self.f, "cx": self.cx, "cy": self.cy,
                "distance_m": -float(self.position[1]), "height_m": float(self.position[2]),
                "position_m": self.position.tolist(), "pitch_deg": self.pitch_deg, "looks_along": "+Y"}



def lead_in_path(turn_deg: float, straight_m: float, curve_m: float, total_m: float, step_m: float = 0.5):
    """The lead-in line, from the stop position outwards: arc length s, points (X, Y), heading psi.

    Heading (deviation from the final straight, radians) is 0 for s < straight_m, eases to
    ``turn_deg`` over the next ``curve_m`` metres (smoothstep) and stays there.
    """
    s = np.arange(0.0, total_m + step_m, step_m)
    u = np.clip((s - straight_m) / curve_m, 0.0, 1.0)
    psi = np.radians(turn_deg) * u * u * (3 - 2 * u)
    x = np.concatenate([[0.0], np.cumsum(np.sin(psi[:-1]) * step_m)])
    y = np.concatenate([[0.0], np.cumsum(np.cos(psi[:-1]) * step_m)])
    return s, np.stack([x, y], axis=1), psi


def draw_aircraft(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The aircraft seen nose-on from slightly above: BGR sprite and alpha at SPRITE_SCALE x template.

    Fuselage (nose disc receding to the tail), swept wings with dihedral, two engines on pylons,
    horizontal stabilisers, tail fin, cockpit windows, landing gear; a livery colour on the fin,
    wing stripes and engine cowls; surface texture noise.

    Every shape is drawn at ``SUPERSAMPLE`` times the sprite's resolution, from sub-pixel vertices, and
    averaged down: an edge at template row ``y`` lands at ``y`` in the sprite's pixel-centre coordinates
    (``cv2.warpAffine``'s) to within ``1 / (SUPERSAMPLE SPRITE_SCALE)`` template px (OpenCV's fill takes in one
    more row of the fine canvas at a bottom edge: the nose wheel's bottom lands at 196.06). Drawn straight at
    the sprite's resolution, OpenCV's fill covered the last row's pixel whole: the nose wheel's bottom,
    where the guidance measures the aircraft's ground contact, lay a third of a template pixel low.
    """
    k = SPRITE_SCALE * SUPERSAMPLE
    h, w = TEMPLATE_H * k, TEMPLATE_W * k
    img = np.zeros((h, w, 3), np.uint8)
    alpha = np.zeros((h, w), np.uint8)
    livery = tuple(int(c) for c in rng.choice([[150, 40, 20], [30, 30, 170], [40, 120, 30], [20, 140, 220],
                                                 [120, 30, 110]]))
    white, grey, dark = (235, 235, 232), (170, 172, 175), (40, 40, 45)
    frac = 1 << _SHIFT

    def fixed(points):
        """Template px -> fixed-point pixel-centre coordinates of the supersampled canvas (whose pixels
        ``j S .. j S + S - 1`` average into the sprite's pixel ``j``)."""
        return np.round((np.asarray(points, np.float64) * k + (SUPERSAMPLE - 1) / 2) * frac).astype(np.int32)

    def poly(points, color):
        pts = fixed(points)
        cv2.fillPoly(img, [pts], color, cv2.LINE_8, _SHIFT)
        cv2.fillPoly(alpha, [pts], 255, cv2.LINE_8, _SHIFT)

    def disc(center, radius, color):
        c = tuple(int(v) for v in fixed([center])[0])
        r = int(round(radius * k * frac))
        cv2.circle(img, c, r, color, -1, cv2.LINE_8, _SHIFT)
        cv2.circle(alpha, c, r, 255, -1, cv2.LINE_8, _SHIFT)

    def line(a, b, width, color):
        pa, pb = (tuple(int(v) for v in q) for q in fixed([a, b]))
        cv2.line(img, pa, pb, color, int(width * k), cv2.LINE_8, _SHIFT)
        cv2.line(alpha, pa, pb, 255, int(width * k), cv2.LINE_8, _SHIFT)

    # tail fin and horizontal stabilisers (far away, drawn first)
    poly([[195, 62], [205, 62], [204, 6], [198, 4]], livery)
    poly([[200, 58], [132, 52], [130, 56], [200, 66], [270, 56], [268, 52]], grey)
    # fuselage receding from the nose to the tail
    poly([[176, 150], [224, 150], [208, 58], [192, 58]], white)
    # wings: root at the fuselage, swept up-and-out to the tips (dihedral)
    poly([[180, 142], [4, 112], [4, 106], [182, 132]], grey)
    poly([[220, 142], [396, 112], [396, 106], [218, 132]], grey)
    poly([[60, 122], [4, 112], [4, 108], [60, 116]], livery)            # wing-tip stripes
    poly([[340, 122], [396, 112], [396, 108], [340, 116]], livery)
    line((4, 106), (4, 96), 2, livery)                                    # winglets
    line((396, 106), (396, 96), 2, livery)
    # engines on pylons under the wings
    for ex in (120.0, 280.0):
        poly([[ex - 3, 140], [ex + 3, 140], [ex + 3, 128], [ex - 3, 128]], grey)
        disc((ex, 160), 15, livery)
        disc((ex, 160), 11, (70, 70, 75))
        disc((ex, 160), 4, (150, 150, 150))
    # landing gear
    for gx, top in ((200.0, 168.0), (172.0, 150.0), (228.0, 150.0)):
        poly([[gx - 1.5, top], [gx + 1.5, top], [gx + 1.5, 190], [gx - 1.5, 190]], grey)
        poly([[gx - 5, 186], [gx + 5, 186], [gx + 5, GROUND_TPL_Y], [gx - 5, GROUND_TPL_Y]], dark)
    # nose (the fuselage cross-section), cockpit windows, livery cheat line
    disc(NOSE_TPL, 24, white)
    poly([[184, 136], [216, 136], [213, 142], [187, 142]], dark)
    poly([[176, 150], [224, 150], [222, 156], [178, 156]], livery)
    disc((200, 150), 3, (120, 120, 125))
    size = (TEMPLATE_W * SPRITE_SCALE, TEMPLATE_H * SPRITE_SCALE)
    img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    alpha = cv2.resize(alpha, size, interpolation=cv2.INTER_AREA)
    h, w = alpha.shape
    # texture: smooth shading noise on every surface
    shade = 0.85 + 0.3 * render.value_noise(rng, (h, w), scales=(32, 8), weights=(0.7, 0.3))
    img = np.clip(img.astype(np.float32) * shade[..., None], 0, 255).astype(np.uint8)
    return img, alpha.astype(np.float32) / 255.0


def template_corners() -> np.ndarray:
    """The template rectangle TL, TR, BR, BL [template px]."""
    return np.array([[0, 0], [TEMPLATE_W, 0], [TEMPLATE_W, TEMPLATE_H], [0, TEMPLATE_H]], np.float64)


def apply_affine(affine: np.ndarray, points) -> np.ndarray:
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    return pts @ affine[:2, :2].T + affine[:2, 2]


class DockingScene:
    """A docking scene fixed by (config, seed); :meth:`frames` renders it lazily, frame by frame."""

    def __init__(self, config: DockingSceneConfig | None = None, seed: int = 0):
        self.config = cfg = validate(config or DockingSceneConfig())
        self.seed = int(seed)
        rng = np.random.default_rng([self.seed, 1])
        self.camera = StandCamera(cfg.width, cfg.height, cfg.camera_distance_m, cfg.camera_height_m, cfg.pitch_deg)
        self.growth = cfg.growth or float(rng.uniform(4.3, 6.0))
        self.turn_deg = (cfg.turn_deg or float(rng.uniform(20.0, 40.0))) * rng.choice([-1.0, 1.0])
        weathers = {0: ["clear"], 1: ["clear", "clear", "rain", "low_sun"], 2: ["rain", "low_sun", "clear"]}[cfg.difficulty]
        self.weather = cfg.weather if cfg.weather != "auto" else str(rng.choice(weathers))
        occluders = {0: ["none"], 1: ["vehicle", "vehicle", "jet_bridge"], 2: ["both", "vehicle"]}[cfg.difficulty]
        self.occluder = cfg.occluder if cfg.occluder != "auto" else str(rng.choice(occluders))
        self.noise_sigma = (1.5, 4.0, 8.0)[cfg.difficulty]

        # Lead-in path long enough that depth(start) / depth(stop) = growth.
        d_stop = float(self.camera.depth([0.0, 0.0, NOSE_HEIGHT_M])[0])
        travel = d_stop * (self.growth - 1.0)
        straight = float(rng.uniform(0.15, 0.3)) * travel
        curve = float(rng.uniform(0.3, 0.45)) * travel
        s, xy, psi = lead_in_path(self.turn_deg, straight, curve, travel * 1.6)
        for _ in range(4):        # the curve shortens the depth travelled: stretch until the growth holds
            n_move = int(round(cfg.frames * (1.0 - cfg.stop_fraction)))
            depth_end = self.camera.depth(np.c_[xy, np.full(len(xy), NOSE_HEIGHT_M)])
            i_start = int(np.searchsorted(depth_end, d_stop * self.growth))
            if i_start < len(s):
                break
            s, xy, psi = lead_in_path(self.turn_deg, straight, curve, s[-1] * 1.5)
        i_start = min(i_start, len(s) - 1)
        self.path_s, self.path_xy, self.path_psi = s[: i_start + 1], xy[: i_start + 1], psi[: i_start + 1]
        self.paint_xy = xy                                   # the painted line runs on beyond the start
        self.n_move = max(n_move, 2)
        # its own stream, so that scenes without a lateral offset stay as they were
        self.sway_phase = float(np.random.default_rng([self.seed, 3]).uniform(0, 2 * np.pi))
        self.sprite, self.sprite_alpha = draw_aircraft(rng)
        self.background = self._draw_background(rng)
        self._plan_occluders(rng)
        self.light_phase = float(rng.uniform(0, 2 * np.pi))
        self.light_period = float(rng.uniform(0.6, 1.5)) * cfg.frames
        self.sun = (float(rng.uniform(0.1, 0.9)) * cfg.width, float(rng.uniform(0.0, 0.25)) * cfg.height)

    # --- motion and geometry -----------------------------------------------------------------
    def arc_length(self, index: int) -> float:
        """Remaining path length to the stop line at frame ``index``: decelerating, then standing."""
        u = min(index / (self.n_move - 1), 1.0)
        return float(self.path_s[-1] * (1.0 - u) ** 1.6)

    def closing_speed(self, index: int) -> float:
        """Minus the rate of :meth:`arc_length` [m/s] (0 once standing)."""
        u = index / (self.n_move - 1)
        if u >= 1.0:
            return 0.0
        return float(1.6 * self.path_s[-1] * (1.0 - u) ** 0.6 * self.config.fps / (self.n_move - 1))

    def guidance_truth(self) -> np.ndarray:
        """(frames, 3): every frame's exact distance to go along the line [m], lateral offset [m, the pilot's
        right +] and closing speed [m/s] (``DockingFrame.guidance``, without rendering)."""
        return np.array([[self.arc_length(i), self.lateral_offset(self.arc_length(i)), self.closing_speed(i)]
                         for i in range(self.config.frames)])

    def lateral_offset(self, s: float) -> float:
        """The nose's offset from the line at arc length ``s`` [m], positive to the pilot's right: a sway of
        ``lateral_offset_m`` over ~40 m of path that shrinks to 30 % of it at the stop."""
        amplitude = self.config.lateral_offset_m
        return float(amplitude * np.sin(2 * np.pi * s / 40.0 + self.sway_phase) * (0.3 + 0.7 * min(s / 30.0, 1.0)))

    def pose(self, index: int) -> tuple[np.ndarray, np.ndarray, float]:
        """``(affine 3x3 template -> image, nose on the ground [m], heading deviation [rad])``."""
        s = self.arc_length(index)
        x = np.interp(s, self.path_s, self.path_xy[:, 0])
        y = np.interp(s, self.path_s, self.path_xy[:, 1])
        psi = float(np.interp(s, self.path_s, self.path_psi))
        if self.config.lateral_offset_m:   # the pilot's right, driving towards the stop: (-cos psi, sin psi)
            offset = self.lateral_offset(s)
            x, y = x - offset * np.cos(psi), y + offset * np.sin(psi)
        nose3 = np.array([x, y, NOSE_HEIGHT_M])
        nose_img, foot_img = self.camera.project([nose3, [x, y, 0.0]])
        scale = self.camera.f / float(self.camera.depth(nose3)[0]) * M_PER_TPL
        # yawed aircraft seen nose-on: the wing span looks shorter, and the image turns with the heading
        squeeze = 0.8 + 0.2 * np.cos(psi)
        c, sn = np.cos(psi), np.sin(psi)
        across, down = np.array([c, sn]), np.array([-sn, c])
        # the template's vertical is scaled so that the nose wheel's ground contact lies as far below the nose as
        # the camera sees the nose's foot on the apron (at the nose's depth alone it fell 0.2-0.4 px low, 0.1-0.3 m
        # of range); turned with the heading, it lands there when the heading's deviation is 0
        down_scale = float(np.linalg.norm(foot_img - nose_img)) / (GROUND_TPL_Y - NOSE_TPL[1])
        linear = np.column_stack([scale * squeeze * across, down_scale * down])
        affine = np.eye(3)
        affine[:2, :2] = linear
        affine[:2, 2] = nose_img - linear @ NOSE_TPL
        return affine, np.array([x, y]), psi

    def _lead_in_samples(self) -> np.ndarray:
        """About 60 points of the lead-in path [m], from the stop position outwards."""
        return self.path_xy[:: max(1, len(self.path_xy) // 60)]

    def stand_geometry(self) -> dict:
        """Lead-in line and stop line in ground [m] and image [px] coordinates, with the camera."""
        lead = self._lead_in_samples()
        stop = np.array([[-6.0, 0.0], [6.0, 0.0]])
        to3 = lambda xy: np.c_[xy, np.zeros(len(xy))]        # noqa: E731 (painted on the apron)
        return {
            "frame_id": "camera", "units": {"ground": "m", "image": "px"},
            "image_size": [self.config.width, self.config.height],
            "lead_in_ground": np.round(lead, 3).tolist(),
            "lead_in_image": np.round(self.camera.project(to3(lead)), 2).tolist(),
            "stop_line_ground": stop.tolist(),
            "stop_line_image": np.round(self.camera.project(to3(stop)), 2).tolist(),
            "stop_nose_image": np.round(self.camera.project([0.0, 0.0, NOSE_HEIGHT_M])[0], 2).tolist(),
            "nose_height_m": NOSE_HEIGHT_M, "camera": self.camera.as_dict(), "metres_per_template_px": M_PER_TPL,
            "template_size": [TEMPLATE_W, TEMPLATE_H], "nose_template": NOSE_TPL.tolist(),
            "stop_frame": int(self.n_move - 1), "growth": self.growth, "turn_deg": self.turn_deg,
            "weather": self.weather, "occluder": self.occluder, "seed": self.seed,
        }

    # --- drawing ------------------------------------------------------------------------------
    def _draw_background(self, rng: np.random.Generator) -> np.ndarray:
        """Sky, a distant terminal and tree line, the apron with slab joints and the stand markings."""
        cfg, cam = self.config, self.camera
        w, h = cfg.width, cfg.height
        horizon = int(round(cam.cy - cam.f * np.tan(np.radians(cam.pitch_deg))))
        img = np.zeros((h, w, 3), np.float32)
        rows = np.arange(h, dtype=np.float32)[:, None]
        sky = np.array([235, 205, 170], np.float32) - rows[:horizon] / max(horizon, 1) * np.array([60, 40, 20])
        img[:horizon] = sky[:, None, :]
        concrete = 125 + 50 * render.value_noise(rng, (h, w), scales=(96, 24, 4), weights=(0.5, 0.3, 0.2))
        img[horizon:] = concrete[horizon:, :, None] * np.array([1.0, 1.0, 0.97], np.float32)
        # distant terminal buildings and a tree line on the horizon
        for _ in range(int(rng.integers(3, 7))):
            bx = int(rng.uniform(0, w))
            bw, bh = int(rng.uniform(0.08, 0.25) * w), int(rng.uniform(0.02, 0.06) * h)
            cv2.rectangle(img, (bx, horizon - bh), (bx + bw, horizon), tuple(float(v) for v in rng.uniform(90, 160, 3)), -1)
        trees = render.value_noise(rng, (1, w), scales=(16, 4), weights=(0.7, 0.3))[0]
        for x in range(w):
            th = int(2 + trees[x] * 0.02 * h)
            img[max(horizon - th, 0):horizon, x] = (50, 80, 60)
        img = np.clip(img, 0, 255).astype(np.uint8)
        # slab joints: lines of constant X and Y on the apron
        for gx in np.arange(-60.0, 61.0, 7.5):
            pts = cam.project(np.c_[np.full(40, gx), np.linspace(cam.position[1] + 5.0, 400.0, 40), np.zeros(40)])
            cv2.polylines(img, [pts.astype(np.int32)], False, (105, 105, 102), 1, cv2.LINE_AA)
        for gy in np.arange(-20.0, 400.0, 7.5):
            pts = cam.project(np.c_[np.linspace(-80, 80, 20), np.full(20, gy), np.zeros(20)])
            cv2.polylines(img, [pts.astype(np.int32)], False, (105, 105, 102), 1, cv2.LINE_AA)
        # stand markings: yellow lead-in line (0.15 m wide) and the stop bar
        yellow = (0, 200, 235)
        for off in (-0.12, 0.0, 0.12):
            pts = cam.project(np.c_[self.paint_xy[:, 0] + off, self.paint_xy[:, 1], np.zeros(len(self.paint_xy))])
            cv2.polylines(img, [np.round(pts).astype(np.int32)], False, yellow, 1, cv2.LINE_AA)
        for dy in np.linspace(-0.3, 0.3, 5):
            stop = cam.project([[-6.0, dy, 0.0], [6.0, dy, 0.0]])
            cv2.line(img, tuple(np.round(stop[0]).astype(int)), tuple(np.round(stop[1]).astype(int)), yellow, 1, cv2.LINE_AA)
        return img

    def _plan_occluders(self, rng: np.random.Generator) -> None:
        """Timing and placement of the crossing ground vehicle; the jet bridge's fixed place."""
        cfg = self.config
        self.vehicle = None
        if self.occluder in ("vehicle", "both"):
            duration = int(rng.uniform(0.12, 0.22) * cfg.frames)
            middle = int(rng.uniform(0.35, 0.75) * self.n_move)
            _, nose_ground, _ = self.pose(middle)
            nose_depth = float(self.camera.depth([*nose_ground, NOSE_HEIGHT_M])[0])
            depth = max(nose_depth - float(rng.uniform(3.0, 8.0)), 12.0)
            y = depth + self.camera.position[1]          # ground Y at that depth (small pitch)
            length = float(rng.uniform(6.0, 9.0))
            # cross just the aircraft's image (its span seen at the vehicle's depth), in front of it
            half_span = 0.6 * WINGSPAN_M * depth / nose_depth + length / 2
            direction = float(rng.choice([-1.0, 1.0]))
            self.vehicle = {
                "t0": middle - duration // 2, "t1": middle + duration // 2, "y": y,
                "x0": nose_ground[0] - direction * half_span, "x1": nose_ground[0] + direction * half_span,
                "length": length, "height": float(rng.uniform(3.5, 5.0)),
                "color": tuple(float(c) for c in rng.choice([[20, 160, 230], [230, 230, 230], [40, 90, 200]])),
            }
        self.jet_bridge = self.occluder in ("jet_bridge", "both")

    def _draw_vehicle(self, img: np.ndarray, mask: np.ndarray, index: int) -> None:
        v = self.vehicle
        if v is None or not (v["t0"] <= index <= v["t1"]):
            return
        u = (index - v["t0"]) / max(v["t1"] - v["t0"], 1)
        x = v["x0"] + (v["x1"] - v["x0"]) * u
        cam, L, H = self.camera, v["length"], v["height"]

        def box(x0, x1, z0, z1, color):
            pts = cam.project([[x0, v["y"], z0], [x1, v["y"], z0], [x1, v["y"], z1], [x0, v["y"], z1]])
            pts = np.round(pts).astype(np.int32)
            cv2.fillConvexPoly(img, pts, color, cv2.LINE_AA)
            cv2.fillConvexPoly(mask, pts, 1.0)

        box(x - L / 2, x + L / 2, 0.5, H * 0.8, v["color"])                     # body
        box(x + L / 2 - 2.0, x + L / 2, 0.5, H, (60, 60, 60))                    # cab
        box(x + L / 2 - 1.8, x + L / 2 - 0.2, H * 0.6, H * 0.95, (120, 90, 60))  # windscreen
        for wx in (x - L / 2 + 1.0, x + L / 2 - 1.2):
            box(wx - 0.5, wx + 0.5, 0.0, 0.9, (25, 25, 25))                      # wheels

    def _draw_jet_bridge(self, img: np.ndarray, mask: np.ndarray) -> None:
        """A tunnel on a pillar reaching in from the left, 2 m in front of the stop line."""
        if not self.jet_bridge:
            return
        cam = self.camera
        y = -2.0
        tunnel = cam.project([[-60.0, y, 4.0], [-9.0, y, 4.0], [-9.0, y, 7.0], [-60.0, y, 7.0]])
        pillar = cam.project([[-25.0, y, 0.0], [-23.5, y, 0.0], [-23.5, y, 4.0], [-25.0, y, 4.0]])
        for pts, color in ((tunnel, (150, 155, 160)), (pillar, (90, 90, 95))):
            pts = np.round(pts).astype(np.int32)
            cv2.fillConvexPoly(img, pts, color, cv2.LINE_AA)
            cv2.fillConvexPoly(mask, pts, 1.0)
        for wx in np.arange(-55.0, -10.0, 3.0):        # windows
            pts = np.round(cam.project([[wx, y, 5.0], [wx + 1.5, y, 5.0], [wx + 1.5, y, 6.2], [wx, y, 6.2]]))
            cv2.fillConvexPoly(img, pts.astype(np.int32), (80, 60, 40), cv2.LINE_AA)

    def frames(self) -> Iterator[DockingFrame]:
        """Render every frame in order (a generator: memory stays flat)."""
        cfg = self.config
        rng = np.random.default_rng([self.seed, 2])
        h, w = cfg.height, cfg.width
        glare = render.sun_glare((h, w), self.sun, 0.25 * w) if self.weather == "low_sun" else None
        truth = self.guidance_truth()
        for i in range(cfg.frames):
            affine, nose_ground, _ = self.pose(i)
            img = self.background.copy()
            mask = np.zeros((h, w), np.float32)
            sprite_to_image = affine @ np.diag([1.0 / SPRITE_SCALE, 1.0 / SPRITE_SCALE, 1.0])
            pasted = render.paste_affine(img, self.sprite, self.sprite_alpha, sprite_to_image)
            if pasted is not None:
                rows, cols, walpha = pasted
                mask[rows, cols] = walpha
            occ = np.zeros((h, w), np.float32)
            self._draw_vehicle(img, occ, i)
            self._draw_jet_bridge(img, occ)
            visible = mask * (1.0 - occ)
            # lighting drift (slow gain oscillation plus a trend), tint, weather, sensor noise
            t = i / max(cfg.frames - 1, 1)
            gain = 1.0 + 0.12 * (1 + cfg.difficulty) / 2 * np.sin(2 * np.pi * i / self.light_period + self.light_phase) \
                - 0.1 * cfg.difficulty * t
            tint = (1.0, 1.0, 1.0)
            if self.weather == "rain":
                img = cv2.addWeighted(img, 0.75, np.full_like(img, 120), 0.25, 0.0)
                render.rain_streaks(img, rng, count=int(0.0015 * w * h), length=0.04 * h)
                gain *= 0.85
            elif self.weather == "low_sun":
                img = np.clip(img.astype(np.float32) + glare, 0, 255).astype(np.uint8)
                tint = (0.85, 0.97, 1.12)
            img = render.camera_effects(img, rng, gain, tint, self.noise_sigma)
            quad = apply_affine(affine, template_corners())
            area = float(mask.sum())
            yield DockingFrame(i, render.frame_stamp_ns(i, cfg.fps), img, affine, quad,
                               apply_affine(affine, NOSE_TPL)[0], nose_ground, truth[i], mask, visible,
                               1.0 - float(visible.sum()) / area if area > 0 else 1.0)

    def stand_calibration(self, click_sigma_px: float = 0.5) -> dict:
        """What a surveyor would write in this stand's file (``config/stands/*.yaml`` layout,
        :mod:`aircraft_docking_tracker.docking.stand`): the measured focal length, ten apron marks (on the stop
        stop bar's line and slab-joint crossings) clicked in the image with ``click_sigma_px`` of
        error, the painted lead-in line (entry first, running 10 m on past the stop) and the one aircraft type.
        The marks span the apron's depth from 20 m before the stop to 30 m past it: the camera's pose, and
        with it every range, is as good as their spread."""
        cam = self.camera
        marks = np.array([[x, y] for y in (-20.0, -10.0, 0.0, 15.0, 30.0) for x in (-7.5, 7.5)])
        clicked = cam.project(np.c_[marks, np.zeros(len(marks))])
        clicked += np.random.default_rng([self.seed, 4]).normal(0.0, click_sigma_px, clicked.shape)
        lead = self._lead_in_samples()[::-1]
        lead = np.vstack([lead[:-1], [0.0, 0.0], [0.0, -10.0]])
        return {
            "stand": f"synthetic stand {self.seed}",
            "camera": {"image_size": [self.config.width, self.config.height], "focal_px": round(float(cam.f), 3),
                       "points": [{"image": np.round(c, 2).tolist(), "stand": m.tolist()}
                                  for c, m in zip(clicked, marks)]},
            "lead_in": np.round(lead, 3).tolist(),
            "aircraft": {"synthetic_a320": {
                "stop_m": [0.0, 0.0], "nose_height_m": round(float(NOSE_HEIGHT_M), 4),
                "height_m": round(TEMPLATE_H * M_PER_TPL, 4), "wingspan_m": WINGSPAN_M,
                "nose_in_template": [float(NOSE_TPL[0] / TEMPLATE_W), float(NOSE_TPL[1] / TEMPLATE_H)]}},
        }

    def stand_json(self) -> str:
        return json.dumps(self.stand_geometry())
