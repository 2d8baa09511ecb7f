"""Synthetic UAV scene: small vehicles seen from a drifting drone camera (no ROS).

What it shows (issue 3; seed 003's setting): a nadir or oblique camera drifting over textured
terrain (fields, roads); 3-30 small vehicles (car or camouflage textures, 12-60 px) that
accelerate, turn, cross each other's paths, hide under tree canopies or smoke for up to 150
frames, enter and leave the view; static clutter that looks like them (containers, sheds, dark
bushes of vehicle size).

Everything lives on a flat *world* image (pixels at drone scale 1). Each frame the camera's
footprint (a rectangle for nadir, a trapezoid for oblique) is mapped onto the image by one
homography, so a vehicle's ground truth is the bounding box of its four world corners under that
homography, clipped to the image. Visibility is measured from the pixels actually drawn: the
vehicle's alpha times one minus the canopy / smoke alpha above it, times the part of its box
inside the image. A vehicle whose visibility is below ``hidden_below`` is *hidden*: it is still in
the ground truth (``state`` 2), but no detector or tracker is expected to see it.

Ground truth per frame is a ``TRACK_DTYPE`` table (see ``object_table``) with these meanings:
``id`` the vehicle (1-based, never reused), ``x, y, w, h`` its box [px], ``vx, vy`` the box
centre's velocity [px/s], ``score`` the visible fraction in [0, 1], ``class_id`` 0 car /
1 camouflaged vehicle, ``age`` frames since it first appeared, ``misses`` consecutive hidden
frames, ``state`` 1 visible / 2 hidden.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import cv2
import numpy as np

from aircraft_docking_tracker.config import param, validate
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, TRACK_DTYPE
from aircraft_docking_tracker.scenarios import render

CLASS_CAR, CLASS_CAMO = 0, 1
STATE_VISIBLE, STATE_HIDDEN = 1, 2
SPRITE_SUPERSAMPLE = 4
# The camera height the UAV set-up (config/uav_camera.yaml, uav_vehicles_heading_all_views.json) is made for: 3x lower
# than the scene's default, so that vehicles' shorter box sides are >= 33 px (5th percentile 39 px)
# instead of >= 10 px; see docs/uav_camera.md.
UAV_SETUP_GROUND_RESOLUTION = 3.0
# Seed ranges of the UAV set-up's protocol (disjoint): cascade training, choice of the operating point,
# evaluation (bench/uav_detector.py, the tests). The demo's seed 106 is in none of the first two.
UAV_TRAIN_SEEDS = range(1000, 2000)
UAV_TUNING_SEEDS = range(2000, 3000)
UAV_EVAL_SEEDS = range(3000, 4000)

# Earlier UAV camera set-ups, as overrides of config/uav_camera.yaml's detector: bench/uav_detector.py measures
# them beside the set-up and test/test_detector_uav_setup.py checks that the set-up still beats each.
# the set-up of sessions 45-47 (issue 12), before session 48's scan for speed: pyramid step 1.2, groups of at least two
# windows, every group shown to the patch network; every earlier set-up below too
UAV_BEFORE_SPEED = {"scale_factor": 1.2, "min_neighbors": 2, "patch_net_floor": -50.0}
# the set-up of sessions 39-42, before the patch network (session 43): the groups placed by the box
# regressor's image stages, the tree verifier's log odds alone against its threshold, every group half inside a
# better one dropped (no containment exemption, session 45); every earlier set-up below too
UAV_BEFORE_PATCH_NET = {**UAV_BEFORE_SPEED, "patch_net": "", "box_regressor": "uav_vehicles_box_regressor_image.json",
                        "verifier_threshold": 1.9, "containment_exempt_log_odds": 50.0, "suppression_iou": 1.0}
# the set-up before session 39: windows grouped by their upright boxes; every earlier set-up below too
UAV_UPRIGHT_GROUPS = {**UAV_BEFORE_PATCH_NET, "group_shape": "upright"}
# the set-up before the colour blobs' views (issue 12 session 33): the scan's windows alone, the turned views' whole
# canvases, the pyramid step it had then; every earlier set-up below also scanned so
UAV_BEFORE_BLOBS = {**UAV_UPRIGHT_GROUPS, "blob_views": False, "turned_crop": 0.0, "scale_factor": 1.2}
# the set-up before the colour verifier: the cascade's window count alone, its operating point (tuning seeds)
UAV_CASCADE_ONLY = {**UAV_BEFORE_BLOBS, "verifier": "", "box_regressor": "", "low_confidence_band": 0.0, "min_neighbors": 8,
                    "containment": 0.4, "box_scale": 0.9}
# the set-up before the box regressor (session 8): the verifier on the groups' mean boxes, its operating point
UAV_VERIFIER_ONLY = {**UAV_BEFORE_BLOBS, "verifier": "uav_vehicles_verifier.json", "verifier_threshold": 1.217, "box_regressor": "",
                     "min_neighbors": 3, "containment": 0.4, "box_scale": 0.9}
# the set-up before the tree verifier (session 9): the logistic verifier, with the box regressor
UAV_LOGISTIC = {**UAV_BEFORE_BLOBS, "verifier": "uav_vehicles_verifier.json", "verifier_threshold": 1.217,
                "box_regressor": "uav_vehicles_box_regressor.json"}
# the set-up before the box regressor's image stages (session 12): its member statistics alone
UAV_MEMBER_BOXES = {**UAV_BEFORE_BLOBS, "box_regressor": "uav_vehicles_box_regressor.json"}
# the upright set-up at this altitude: upright 3:2 windows, vehicles at any heading in them
UAV_UPRIGHT = {"model": "uav_vehicles_low.json", "min_size": 36.0, "max_size": 180.0, "min_neighbors": 64,
               "window_margin": 1.0, "group_iou": 0.2, "containment": 0.4, "box_scale": 0.9}


@dataclass
class UavSceneConfig(render.StreamConfig):
    """Everything that shapes a UAV scene (the seed picks the rest)."""

    fps: float = param(25.0, "camera frame rate [Hz]", low=1.0, high=120.0)
    difficulty: int = param(1, "0 easy (few vehicles, no hiding), 1 normal, 2 hard (many, smoke, clutter)",
                            low=0, high=2)
    vehicles: int = param(0, "number of vehicles over the whole scene; 0: seed picks by difficulty", low=0, high=60)
    view: str = param("auto", "camera view; auto: chosen by the seed", choices=("auto", "nadir", "oblique"))
    max_hide_frames: int = param(150, "longest planned hiding under trees or smoke [frames]", low=0, high=1000)
    hidden_below: float = param(0.3, "visible fraction below which a vehicle counts as hidden", low=0.0, high=1.0)
    ground_resolution: float = param(1.0, "image pixels per ground pixel at the nominal zoom: the camera height "
                                     "(1: the default altitude, vehicles 12-60 px; 2.5: a camera 2.5x lower, every "
                                     "ground length 2.5x larger in the image; the ground is drawn at scale 1, so a "
                                     "lower camera magnifies it without adding detail)", low=0.25, high=8.0)
    min_in_frame: float = param(0.3, "a vehicle is in the ground truth once this fraction of its box is in the image",
                                low=0.0, high=1.0)


@dataclass
class UavFrame:
    """One rendered frame and its ground truth."""

    index: int
    stamp_ns: int
    image: np.ndarray                 # (H, W, 3) uint8 BGR
    ground_truth: np.ndarray          # TRACK_DTYPE rows
    homography: np.ndarray            # (3, 3) world -> image


# --- sprites -------------------------------------------------------------------------------------

def draw_vehicle_sprite(rng: np.random.Generator, length: float, width: float, kind: int):
    """Top view of a vehicle pointing along +x: BGR sprite and alpha at SPRITE_SUPERSAMPLE x its size."""
    k = SPRITE_SUPERSAMPLE
    L, W = max(int(round(length * k)), 8), max(int(round(width * k)), 4)
    img = np.zeros((W, L, 3), np.uint8)
    alpha = np.zeros((W, L), np.float32)
    cv2.rectangle(alpha, (0, 0), (L - 1, W - 1), 1.0, -1)
    if kind == CLASS_CAR:
        body = tuple(int(c) for c in rng.choice([[200, 200, 205], [30, 30, 35], [40, 40, 170], [150, 90, 30],
                                                  [180, 180, 180], [60, 120, 200], [90, 60, 40]]))
        img[:] = body
        roof = tuple(int(min(255, c * 1.15 + 15)) for c in body)
        cv2.rectangle(img, (int(0.62 * L), int(0.12 * W)), (int(0.8 * L), int(0.88 * W)), (40, 45, 50), -1)  # windscreen
        cv2.rectangle(img, (int(0.18 * L), int(0.14 * W)), (int(0.3 * L), int(0.86 * W)), (50, 55, 60), -1)  # rear window
        cv2.rectangle(img, (int(0.3 * L), int(0.16 * W)), (int(0.62 * L), int(0.84 * W)), roof, -1)
        for y in (int(0.18 * W), int(0.82 * W)):                                                  # head lights
            cv2.circle(img, (L - 2 * k // 2, y), max(k // 2, 1), (200, 230, 240), -1)
    else:
        colors = [[40, 75, 60], [30, 50, 70], [70, 100, 95], [25, 35, 40]]
        img[:] = render.blotches(rng, (W, L), colors, scale=max(4, W // 3))
        cv2.circle(img, (int(0.45 * L), W // 2), int(0.3 * W), (35, 60, 55), -1)              # turret
        cv2.line(img, (int(0.45 * L), W // 2), (L - 1, W // 2), (30, 40, 40), max(k // 2, 2))  # barrel
        cv2.rectangle(img, (0, 0), (L - 1, int(0.12 * W)), (30, 35, 35), -1)                   # tracks
        cv2.rectangle(img, (0, int(0.88 * W)), (L - 1, W - 1), (30, 35, 35), -1)
    img = cv2.GaussianBlur(img, (0, 0), k * 0.35)
    return img, alpha


def draw_canopy(rng: np.random.Generator, shape: tuple[int, int], centers, radii):
    """Tree canopy (BGR, alpha) covering discs at ``centers`` with ``radii`` on a world of ``shape``."""
    h, w = shape
    alpha = np.zeros((h, w), np.float32)
    for (cx, cy), r in zip(centers, radii):
        for _ in range(3):       # each disc made of a few overlapping crowns
            off = rng.normal(0, 0.25 * r, 2)
            cv2.circle(alpha, (int(cx + off[0]), int(cy + off[1])), int(r * rng.uniform(0.9, 1.1)), 1.0, -1, cv2.LINE_AA)
    alpha = np.clip(cv2.GaussianBlur(alpha, (0, 0), 1.5) * 1.2, 0, 1)
    return alpha


# --- the scene -----------------------------------------------------------------------------------

class UavScene:
    """A UAV scene fixed by (config, seed); :meth:`frames` renders it lazily, frame by frame."""

    def __init__(self, config: UavSceneConfig | None = None, seed: int = 0):
        self.config = cfg = validate(config or UavSceneConfig())
        self.seed = int(seed)
        rng = np.random.default_rng([self.seed, 3])
        self.view = cfg.view if cfg.view != "auto" else str(rng.choice(["nadir", "oblique"]))
        self.noise_sigma = (2.0, 4.0, 7.0)[cfg.difficulty]
        n_default = {0: (3, 6), 1: (6, 15), 2: (15, 30)}[cfg.difficulty]
        self.n_vehicles = cfg.vehicles or int(rng.integers(n_default[0], n_default[1] + 1))
        self._plan_camera(rng)
        self._plan_vehicles(rng)
        self.world = self._draw_world(rng)
        self._plan_hiding(rng)

    # camera ------------------------------------------------------------------------------------
    def _plan_camera(self, rng: np.random.Generator) -> None:
        """Footprint centre, heading and zoom per frame (slow drift), and the world that holds them."""
        cfg = self.config
        n, w, h = cfg.frames, cfg.width, cfg.height
        t = np.arange(n, dtype=np.float64)
        speed = rng.uniform(0.2, 0.8) * (1 + cfg.difficulty) / 2            # world px per frame
        direction = rng.uniform(0, 2 * np.pi)
        wobble = rng.uniform(5, 20)
        phase = rng.uniform(0, 2 * np.pi, 2)
        cx = speed * t * np.cos(direction) + wobble * np.sin(2 * np.pi * t / max(n, 1) + phase[0])
        cy = speed * t * np.sin(direction) + wobble * np.sin(2 * np.pi * t / max(n, 1) * 1.3 + phase[1])
        self.cam_heading = np.radians(rng.uniform(-8, 8)) * np.sin(2 * np.pi * t / max(n, 1) + phase[1])
        self.cam_zoom = 1.0 + 0.1 * np.sin(2 * np.pi * t / max(n, 1) * 0.7 + phase[0])
        self.tilt = 1.0 if self.view == "nadir" else float(rng.uniform(1.3, 1.6))  # far edge / near edge
        half = np.array([w, h]) / 2.0
        margin = 80 + 0.5 * max(w, h) * self.tilt
        lo = np.array([cx.min(), cy.min()]) - half * self.tilt - margin
        hi = np.array([cx.max(), cy.max()]) + half * self.tilt + margin
        self.world_size = (int(hi[1] - lo[1]), int(hi[0] - lo[0]))            # (h, w)
        self.cam_center = np.stack([cx - lo[0], cy - lo[1]], axis=1)

    def footprint(self, index: int) -> np.ndarray:
        """World corners seen at the image's TL, TR, BR, BL (the far edge is the top one)."""
        w, h = self.config.width / 2.0, self.config.height / 2.0
        z = self.cam_zoom[index] * self.config.ground_resolution
        top = self.tilt
        corners = np.array([[-w * top, -h], [w * top, -h], [w, h], [-w, h]]) / z
        if self.tilt != 1.0:
            corners[:2, 1] *= (1 + self.tilt) / 2          # the far half covers more ground
        c, s = np.cos(self.cam_heading[index]), np.sin(self.cam_heading[index])
        return corners @ np.array([[c, s], [-s, c]]) + self.cam_center[index]

    def homography(self, index: int) -> np.ndarray:
        """World -> image homography of frame ``index``."""
        w, h = self.config.width, self.config.height
        image = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float32)
        return cv2.getPerspectiveTransform(self.footprint(index).astype(np.float32), image).astype(np.float64)

    # vehicles ----------------------------------------------------------------------------------
    def _plan_vehicles(self, rng: np.random.Generator) -> None:
        """Trajectories (world x, y, heading per frame) from an anchor, integrated both ways.

        Each vehicle passes an anchor point at an anchor frame inside the view; away from it, it
        accelerates, brakes and turns in piecewise-constant manoeuvres. Groups of 2-4 vehicles share
        an anchor point, a few frames apart, from different directions: they cross each other.
        """
        cfg = self.config
        n = cfg.frames
        self.kind = rng.choice([CLASS_CAR, CLASS_CAMO], size=self.n_vehicles, p=[0.6, 0.4])
        self.length = rng.uniform(20.0, 50.0, self.n_vehicles)
        self.width_px = self.length * rng.uniform(0.42, 0.55, self.n_vehicles)
        self.track = np.full((self.n_vehicles, n, 3), np.nan)      # x, y, heading
        anchors: list[tuple[np.ndarray, int]] = []
        i = 0
        while i < self.n_vehicles:
            group = int(min(rng.integers(2, 5), self.n_vehicles - i)) if rng.random() < 0.35 else 1
            t_anchor = int(rng.integers(n // 6, max(n // 6 + 1, 5 * n // 6)))
            fp = self.footprint(t_anchor)
            point = fp.mean(axis=0) + rng.uniform(-0.3, 0.3, 2) * (fp.max(axis=0) - fp.min(axis=0))
            heading0 = rng.uniform(0, 2 * np.pi)
            for g in range(group):
                heading = heading0 + g * np.pi / group + rng.uniform(-0.2, 0.2)
                speed = rng.uniform(0.8, 3.0)
                delay = int(g * (self.length[i] + 8) / speed)
                self.track[i] = self._integrate(rng, point, heading, speed, t_anchor + delay)
                i += 1
            anchors.append((point, t_anchor))
        self.sprites = [draw_vehicle_sprite(rng, L, W, k) for L, W, k in zip(self.length, self.width_px, self.kind)]

    def _integrate(self, rng, point, heading, speed, t_anchor) -> np.ndarray:
        """One trajectory through ``point`` at frame ``t_anchor``, straight within 15 frames of it."""
        n = self.config.frames
        out = np.zeros((n, 3))
        for direction in (1, -1):
            pos, hd, v = np.array(point, float), float(heading), float(speed)
            turn = accel = 0.0
            left, t = 15, t_anchor
            while (direction == 1 and t < n) or (direction == -1 and t >= 0):
                if 0 <= t < n:
                    out[t] = (pos[0], pos[1], hd)
                left -= 1
                if left <= 0:       # next manoeuvre: keep going, or turn; speed up or brake
                    left = int(rng.integers(15, 80))
                    turn = rng.choice([0.0, 0.0, rng.uniform(-0.05, 0.05)])
                    accel = rng.uniform(-0.04, 0.04)
                hd += direction * turn
                v = float(np.clip(v + direction * accel, 0.3, 4.0))
                pos = pos + direction * v * np.array([np.cos(hd), np.sin(hd)])
                t += direction
        return out

    def in_view(self) -> np.ndarray:
        """``(vehicles, frames)`` mask: the vehicle's centre is inside the image."""
        cfg = self.config
        out = np.zeros((self.n_vehicles, cfg.frames), bool)
        for t in range(cfg.frames):
            p = cv2.perspectiveTransform(self.track[None, :, t, :2].astype(np.float64), self.homography(t))[0]
            out[:, t] = (p[:, 0] >= 0) & (p[:, 0] < cfg.width) & (p[:, 1] >= 0) & (p[:, 1] < cfg.height)
        return out

    def _plan_hiding(self, rng: np.random.Generator) -> None:
        """Hide some vehicles for up to ``max_hide_frames``: under a canopy or (hard) in smoke."""
        cfg = self.config
        self.smoke: list[dict] = []
        n_hide = {0: 0, 1: max(1, self.n_vehicles // 5), 2: max(2, self.n_vehicles // 4)}[cfg.difficulty]
        if cfg.max_hide_frames <= 0:
            n_hide = 0
        centers, radii = [], []
        seen = self.in_view()
        speed = np.linalg.norm(np.diff(self.track[:, :, :2], axis=1), axis=2)
        movers = np.flatnonzero((seen.sum(axis=1) > 40) & (speed.min(axis=1) >= 1.0))
        for v in rng.permutation(movers)[:n_hide]:
            radius = 0.5 * np.hypot(self.length[v], self.width_px[v]) + 4
            # entering and leaving the cover adds about 2 (radius + 6) / speed frames of hiding
            longest = cfg.max_hide_frames - int(2 * (radius + 6) / speed[v].min())
            duration = int(rng.integers(min(30, max(longest, 1)), max(longest, 1) + 1))
            frames_seen = np.flatnonzero(seen[v])
            t0 = int(rng.choice(frames_seen[: max(1, len(frames_seen) - duration // 2)]))
            path = self.track[v, t0:t0 + duration, :2]
            if cfg.difficulty == 2 and rng.random() < 0.5:
                centre = path.mean(axis=0)
                reach = np.linalg.norm(path - centre, axis=1).max() + radius + 6
                self.smoke.append({"center": centre, "radius": float(min(reach, 100)), "t0": t0, "t1": t0 + duration})
            else:
                step = max(1, int(radius / 2 / max(np.median(np.linalg.norm(np.diff(path, axis=0), axis=1)), 0.1)))
                centers += [p for p in path[::step]]
                radii += [radius + rng.uniform(2, 6) for _ in path[::step]]
        # decorative groves too, so that canopies are not a give-away; off every vehicle's path, so
        # that the only long hiding is the planned one (<= max_hide_frames)
        h, w = self.world_size
        path_points = self.track[:, ::3, :2].reshape(-1, 2)
        groves = int(rng.integers(4, 10))
        for _ in range(40 * groves):
            if groves == 0:
                break
            c = rng.uniform(0, 1, 2) * (w, h)
            if np.min(np.linalg.norm(path_points - c, axis=1)) < 110:
                continue
            groves -= 1
            for _ in range(int(rng.integers(3, 12))):
                centers.append(c + rng.normal(0, 25, 2))
                radii.append(float(rng.uniform(10, 22)))
        self.canopy_alpha = draw_canopy(rng, self.world_size, centers, radii)
        leaves = render.blotches(rng, self.world_size, [[20, 60, 30], [30, 85, 45], [40, 100, 60], [15, 45, 25]],
                                 scale=6)
        self.canopy = leaves
        render.blend_into(self.world, leaves, self.canopy_alpha)
        self.smoke_sprites = []
        for s in self.smoke:
            r = int(s["radius"])
            puff = render.value_noise(rng, (2 * r, 2 * r), scales=(max(2, r // 3), max(2, r // 8)), weights=(0.7, 0.3))
            yy, xx = np.mgrid[-r:r, -r:r]
            fall = np.clip(1.5 * (1.0 - np.hypot(xx, yy) / r), 0, 1)
            s["alpha"] = np.clip((0.75 + 0.5 * puff) * fall * 1.3, 0, 1).astype(np.float32)
            s["color"] = (np.full((2 * r, 2 * r, 3), 190) * (0.8 + 0.3 * puff[..., None])).clip(0, 255).astype(np.uint8)

    # world -------------------------------------------------------------------------------------
    def _draw_world(self, rng: np.random.Generator):
        """Fields of several colours, dirt roads, and vehicle-sized clutter (no canopy yet)."""
        h, w = self.world_size
        field_noise = render.value_noise(rng, (h, w), scales=(160, 40, 8, 2), weights=(0.45, 0.3, 0.15, 0.1))
        palette = np.array([[60, 110, 90], [70, 130, 120], [80, 120, 140], [55, 95, 75], [90, 140, 150]], np.float32)
        zones = render.value_noise(rng, (h, w), scales=(256,), weights=(1.0,))
        idx = np.minimum((zones * len(palette)).astype(int), len(palette) - 1)
        world = palette[idx] * (0.8 + 0.4 * field_noise[..., None])
        world = np.clip(world, 0, 255).astype(np.uint8)
        for _ in range(int(rng.integers(2, 5))):                       # roads
            p0 = rng.uniform(0, 1, 2) * (w, h)
            ang = rng.uniform(0, np.pi)
            d = np.array([np.cos(ang), np.sin(ang)]) * (w + h)
            cv2.line(world, tuple((p0 - d).astype(int)), tuple((p0 + d).astype(int)), (110, 130, 140),
                     int(rng.uniform(18, 40)), cv2.LINE_AA)
        n_clutter = int(w * h / 40000 * (1 + self.config.difficulty))
        for _ in range(n_clutter):                                     # look-alikes: containers, sheds, bushes
            c = rng.uniform(0, 1, 2) * (w, h)
            L = rng.uniform(14, 50)
            W = L * rng.uniform(0.4, 0.7)
            box = cv2.boxPoints(((float(c[0]), float(c[1])), (float(L), float(W)), float(rng.uniform(0, 180))))
            kind = rng.integers(0, 3)
            color = [tuple(int(v) for v in rng.choice([[40, 40, 150], [150, 100, 40], [160, 160, 165]])),
                     (45, 70, 60), (35, 55, 40)][kind]
            cv2.fillConvexPoly(world, box.astype(np.int32), color, cv2.LINE_AA)
            if kind == 0:
                cv2.polylines(world, [box.astype(np.int32)], True, (30, 30, 30), 1, cv2.LINE_AA)
        return world

    # frames ------------------------------------------------------------------------------------
    def vehicle_affine(self, v: int, t: int) -> np.ndarray:
        """Sprite pixels -> world pixels for vehicle ``v`` at frame ``t``."""
        x, y, hd = self.track[v, t]
        c, s = np.cos(hd), np.sin(hd)
        k = 1.0 / SPRITE_SUPERSAMPLE
        sh, sw = self.sprites[v][1].shape
        rot = np.array([[c, -s], [s, c]]) * k
        a = np.eye(3)
        a[:2, :2] = rot
        a[:2, 2] = np.array([x, y]) - rot @ np.array([sw / 2.0, sh / 2.0])
        return a

    def smoke_alpha_at(self, s: dict, t: int) -> float:
        """Smoke opacity at frame ``t``: fades in over 10 frames before t0, out over 10 after t1."""
        return float(np.clip(min(t - s["t0"] + 10, s["t1"] + 10 - t) / 10.0, 0.0, 1.0))

    def frames(self) -> Iterator[UavFrame]:
        """Render every frame in order (a generator: memory stays flat)."""
        cfg = self.config
        rng = np.random.default_rng([self.seed, 4])
        size = (cfg.width, cfg.height)
        prev_centre: dict[int, tuple[int, np.ndarray]] = {}
        first_seen: dict[int, int] = {}
        hidden_run: dict[int, int] = {}
        for t in range(cfg.frames):
            world = self.world.copy()
            H = self.homography(t)
            occluder = self.canopy_alpha
            smoke_now = [(s, self.smoke_alpha_at(s, t)) for s in self.smoke]
            rows_out = []
            centres = cv2.perspectiveTransform(self.track[None, :, t, :2].astype(np.float64), H)[0]
            near = (centres[:, 0] > -80) & (centres[:, 0] < cfg.width + 80) & \
                   (centres[:, 1] > -80) & (centres[:, 1] < cfg.height + 80)
            for v in np.flatnonzero(near):
                A = self.vehicle_affine(v, t)
                sprite, alpha = self.sprites[v]
                pasted = render.paste_affine(world, sprite, alpha, A)
                if pasted is None:
                    continue
                rows, cols, walpha = pasted
                render.blend_into(world[rows, cols], self.canopy[rows, cols], occluder[rows, cols])
                occ = occluder[rows, cols].copy()
                for s, strength in smoke_now:
                    occ = np.maximum(occ, self._smoke_alpha(s, strength, rows, cols))
                area = float(walpha.sum())
                unoccluded = float((walpha * (1.0 - occ)).sum()) / area if area > 0 else 0.0
                sh, sw = alpha.shape
                corners = np.array([[0, 0], [sw, 0], [sw, sh], [0, sh]], np.float64)
                world_corners = corners @ A[:2, :2].T + A[:2, 2]
                img_pts = cv2.perspectiveTransform(world_corners[None].astype(np.float64), H)[0]
                x0, y0 = img_pts.min(axis=0)
                x1, y1 = img_pts.max(axis=0)
                full = (x1 - x0) * (y1 - y0)
                cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, cfg.width), min(y1, cfg.height)
                if cx1 <= cx0 or cy1 <= cy0 or full <= 0:
                    continue
                in_frame = (cx1 - cx0) * (cy1 - cy0) / full
                if in_frame < cfg.min_in_frame:
                    continue
                visible = unoccluded * in_frame
                vid = v + 1
                centre = np.array([(cx0 + cx1) / 2, (cy0 + cy1) / 2])
                last = prev_centre.get(vid)
                vel = (centre - last[1]) * cfg.fps if last is not None and last[0] == t - 1 else np.zeros(2)
                prev_centre[vid] = (t, centre)
                first_seen.setdefault(vid, t)
                hidden = visible < cfg.hidden_below
                hidden_run[vid] = hidden_run.get(vid, 0) + 1 if hidden else 0
                rows_out.append((vid, cx0, cy0, cx1 - cx0, cy1 - cy0, vel[0], vel[1], visible, int(self.kind[v]),
                                 t - first_seen[vid], hidden_run[vid], STATE_HIDDEN if hidden else STATE_VISIBLE))
            for s, strength in smoke_now:     # smoke drifts over everything, vehicles included
                if strength > 0:
                    rows, cols = self._smoke_box(s)
                    r, (cx, cy) = s["alpha"].shape[0] // 2, s["center"].astype(int)
                    crop = (slice(rows.start - cy + r, rows.stop - cy + r), slice(cols.start - cx + r, cols.stop - cx + r))
                    render.blend_into(world[rows, cols], s["color"][crop], s["alpha"][crop] * strength)
            image = cv2.warpPerspective(world, H, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            if self.view == "oblique":        # haze towards the far edge
                haze = np.linspace(0.35, 0.0, cfg.height, dtype=np.float32)[:, None]
                render.blend_into(image, np.full_like(image, 200), np.repeat(haze, cfg.width, axis=1))
            image = render.camera_effects(image, rng, 1.0, (1.0, 1.0, 1.0), self.noise_sigma)
            gt = np.array(rows_out, dtype=TRACK_DTYPE) if rows_out else np.zeros(0, TRACK_DTYPE)
            yield UavFrame(t, render.frame_stamp_ns(t, cfg.fps), image, gt, H)

    def _smoke_box(self, s: dict) -> tuple[slice, slice]:
        """World rows and columns covered by smoke ``s`` (clipped to the world)."""
        r = s["alpha"].shape[0] // 2
        cx, cy = int(s["center"][0]), int(s["center"][1])
        h, w = self.world_size
        return slice(max(cy - r, 0), min(cy + r, h)), slice(max(cx - r, 0), min(cx + r, w))

    def _smoke_alpha(self, s: dict, strength: float, rows: slice, cols: slice) -> np.ndarray:
        """Opacity of smoke ``s`` over ``world[rows, cols]``."""
        out = np.zeros((rows.stop - rows.start, cols.stop - cols.start), np.float32)
        srows, scols = self._smoke_box(s)
        y0, y1 = max(rows.start, srows.start), min(rows.stop, srows.stop)
        x0, x1 = max(cols.start, scols.start), min(cols.stop, scols.stop)
        if strength <= 0 or y1 <= y0 or x1 <= x0:
            return out
        r, (cx, cy) = s["alpha"].shape[0] // 2, s["center"].astype(int)
        out[y0 - rows.start:y1 - rows.start, x0 - cols.start:x1 - cols.start] = \
            s["alpha"][y0 - cy + r:y1 - cy + r, x0 - cx + r:x1 - cx + r] * strength
        return out


def detection_truth(gt: np.ndarray, min_visible: float = 0.7) -> tuple[np.ndarray, np.ndarray]:
    """One frame's ground truth as detector targets: boxes ``(n, 4)`` x, y, w, h and *ignore* flags
    (hidden, or less than ``min_visible`` of the vehicle visible: neither a miss nor a false alarm)."""
    boxes = np.column_stack([gt["x"], gt["y"], gt["w"], gt["h"]]).astype(np.float64).reshape(-1, 4)
    return boxes, (gt["state"] != STATE_VISIBLE) | (gt["score"] < min_visible)


def synthesize_detections(gt: np.ndarray, rng: np.random.Generator, miss_rate: float = 0.05,
                          clutter_rate: float = 0.5, jitter_px: float = 2.0,
                          frame_size: tuple[int, int] = (640, 480), hidden_below: float = 0.3) -> np.ndarray:
    """Detector-like ``DETECTION_DTYPE`` rows from one frame's ground truth (no detector needed).

    Each vehicle with visible fraction ``score >= hidden_below`` is reported with probability
    ``1 - miss_rate``, its corners jittered by N(0, ``jitter_px``), score in [0.5, 1); hidden ones
    never. Plus Poisson(``clutter_rate``) false alarms of vehicle size anywhere in the
    ``frame_size`` (w, h) image, score in [0.3, 0.8).
    """
    if not (0.0 <= miss_rate <= 1.0) or clutter_rate < 0 or jitter_px < 0:
        raise ValueError(f"bad rates: miss_rate={miss_rate}, clutter_rate={clutter_rate}, jitter_px={jitter_px}")
    visible = gt[(gt["score"] >= hidden_below) & (rng.random(len(gt)) >= miss_rate)]
    out = []
    for row in visible:
        d = rng.normal(0.0, jitter_px, 4)
        x0, y0 = row["x"] + d[0], row["y"] + d[1]
        x1, y1 = row["x"] + row["w"] + d[2], row["y"] + row["h"] + d[3]
        out.append((x0, y0, max(x1 - x0, 1.0), max(y1 - y0, 1.0), rng.uniform(0.5, 1.0), row["class_id"]))
    w, h = frame_size
    for _ in range(rng.poisson(clutter_rate)):
        bw = rng.uniform(12, 60)
        bh = bw * rng.uniform(0.5, 1.0)
        out.append((rng.uniform(0, w - bw), rng.uniform(0, h - bh), bw, bh, rng.uniform(0.3, 0.8), CLASS_CAR))
    return np.array(out, dtype=DETECTION_DTYPE) if out else np.zeros(0, DETECTION_DTYPE)
