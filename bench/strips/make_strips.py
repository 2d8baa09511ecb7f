"""Frame strips of the synthetic scenes (bench/strips/docking.png, uav.png), ground truth drawn in.

    python bench/strips/make_strips.py

Docking rows: 640x480 clear with a crossing vehicle; rain with both occluders; 1280x720 low sun with
the jet bridge. UAV rows: nadir, hard (smoke, many vehicles); oblique, normal (canopies). Green:
ground truth (docking quad and nose; UAV boxes with ids); red: UAV vehicles hidden (state 2).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from aircraft_docking_tracker.scenarios.strips import strip_image, write_image
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
from aircraft_docking_tracker.scenarios.uav import UavScene, UavSceneConfig

HERE = Path(__file__).resolve().parent
TILE = 320


def pick(scene, count: int = 6):
    n = scene.config.frames
    wanted = set(np.linspace(0, n - 1, count).astype(int).tolist())
    return [f for f in scene.frames() if f.index in wanted]


def stack(rows) -> np.ndarray:
    width = max(r.shape[1] for r in rows)
    return np.vstack([np.pad(r, ((0, 4), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows])


def main() -> None:
    docking = [
        ("seed 3, clear, vehicle", DockingScene(DockingSceneConfig(weather="clear", occluder="vehicle"), 3)),
        ("seed 4, rain, hard", DockingScene(DockingSceneConfig(weather="rain", occluder="both", difficulty=2), 4)),
        ("seed 5, 720p low sun", DockingScene(DockingSceneConfig(width=1280, height=720, fps=25.0, weather="low_sun",
                                                                  occluder="jet_bridge"), 5)),
    ]
    write_image(stack([strip_image(pick(s), TILE, caption) for caption, s in docking]), HERE / "docking.png")
    uav = [
        ("seed 1, nadir, hard", UavScene(UavSceneConfig(view="nadir", difficulty=2), 1)),
        ("seed 2, oblique", UavScene(UavSceneConfig(view="oblique", difficulty=1), 2)),
    ]
    write_image(stack([strip_image(pick(s), TILE, caption) for caption, s in uav]), HERE / "uav.png")


if __name__ == "__main__":
    main()
