"""Benchmark of the docking guidance (issue 15): distance to go, lateral offset and STOP from the tracked aircraft.

    nice -n 10 python bench/guidance.py [--approaches 20] [--seeds 3] [--frames 600] [--tune] [--quick]

Protocol:

* **Approaches**: synthetic stands (``DockingScene``) of seeds 200.. (held out; ``--tune`` uses 100..
  and chooses the guidance's constants there), each a different weather, occluder, growth, turn
  (``bench/docking.py``'s ``scene_options``), camera height (5-10 m) and distance (38-58 m), the nose
  swaying up to 1 m off the lead-in line, ``--frames`` frames at 14 Hz (600: closing at about 3 m/s
  15 m out, as an aircraft does; the tracker benches' 150 frames would run at 10-30 m/s there).
* **Tracking**: the docking tracker as the stand runs it (``config/stand_camera.yaml``'s rules, the
  stand cascade's rows every frame) from the ground truth's first box, ``--seeds`` tracker seeds.
* **Calibration**: each stand's file as a surveyor would write it (``DockingScene.stand_calibration``:
  ten apron marks clicked with 0.5 px of error, the measured focal length).
* **Guidance**: :class:`DockingGuidance` on the tracked quadrilaterals and stamps, exactly as the node
  runs it, with the nose wheel measured in each frame under each run's quadrilateral (the frames are
  rendered again for it: they are not kept); the truth is the scene's exact nose position.
* **Measures** (issue 15's targets): within the last 15 m (true distance to go <= 15 m, standing
  included), the median and p95 of |lateral error| and |distance error|; the true distance to go when
  STOP is first shown (within 0.5 m in >= 95 % of approaches; never more than 1 m early; never shown
  counts as a miss); the guidance's time per frame beside the tracker's.

Writes ``bench/results/guidance.json`` / ``.md`` and ``bench/plots/guidance_*.png``; the tracked runs are
cached under ``--cache`` (default a temporary folder) so that ``--tune`` grids cost no tracking.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import functools  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import asdict, replace  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

NEAR_M = 15.0                       # "within the last 15 m"
HELD_OUT_SEED0, TUNE_SEED0 = 200, 100
#: --tune's grid: the neighbourhood of session 27's choice. It was reached in stages on the same tuning approaches:
#: size_sigma {0.01, 0.03, 0.1, 0.3} x gear_pixel_sigma {0.5, 1, 2} x gate_sigma {0, 3, 5, 8} x accel_sigma
#: {0.5, 1, 2, 4} (192 candidates), then this grid's edges pushed out; gear_min_height_px {80, 120, 160} was compared
#: by masking the 80-px measurements (80 best: at 120 the worst run's distance p95 went from 1.2 to 15 m);
#: gear_min_contrast {12, 20, 30, 40} the same way (12 and 30 tie within the rule's rounding: 12 kept), and
#: gate_hold_s {0.15, 0.3, 0.5, 1} with the rest fixed (1: shorter holds leave STOP unshown on 2-8 % of runs).
#: Session 28 added gear_agree_sigma {0 (off), 3, 4, 6} (a contact far from the size's range refused) and stop_m
#: {0, 0.25, 0.4}: with the scene's nose wheel drawn where the truth puts it, the figures at the mark read a tenth of
#: a metre long on many runs, and STOP at exactly 0 m was then never shown on 47 % of the tuning runs. On the redrawn
#: tuning approaches the rule picked gear_agree_sigma 3 (with gate_sigma 12, accel_sigma 4, stop_m 0.25), but run by
#: run the check helped one approach (109: two STOPs 29 and 104 m early put right) and cost three (107, 109, 119:
#: distance p95 0.3-2 m -> 2-40 m, right contacts refused under a quadrilateral that broke up), and its lead came
#: across the rule's rounding (STOP within 0.5 m 58 against 55 runs of 60): gear_agree_sigma stays 0 (off). Among the
#: candidates with it off the rule's first (size_sigma 0.3, slow_down_min_s 3) leads session 27's size_sigma 0.1 and
#: slow_down_min_s 1.5 by 0.02 m of mean p95 across the rounding, a tie: those stay. accel_sigma 4 led 8 here by small
#: margins (STOP > 1 m early 1 against 2 runs, distance p95 mean 1.36 against 1.44 m) and lost on the held-out
#: approaches 200-219 (a STOP 90 m early on 201, distance p95 mean 3.15 against 2.88 m): not a result, 8 stays. What
#: changed is stop_m 0 -> 0.25 (STOP never shown 43 % -> 0 of the tuning runs). The held-out set then having been
#: looked at, the clean estimate is a fresh one: --first-seed 400 (approaches never run by this bench before).
GRID = {"size_sigma": [0.1, 0.3], "gear_pixel_sigma": [0.25, 0.5], "gate_sigma": [8.0, 12.0], "accel_sigma": [4.0, 8.0],
        "slow_down_min_s": [0.0, 1.5, 3.0], "gear_agree_sigma": [0.0, 3.0, 4.0, 6.0], "stop_m": [0.0, 0.25, 0.4]}


def approach_options(k: int) -> dict:
    """The k-th approach: bench/docking.py's weather x occluder x growth x turn, plus camera height and
    distance and the nose's sway."""
    from docking import scene_options  # noqa: PLC0415

    return {**scene_options(k), "camera_height_m": 5.0 + (k * 1.7) % 5.0,
            "camera_distance_m": 38.0 + (k * 7.9) % 20.0, "lateral_offset_m": 1.0}


def track_approach(job: tuple) -> dict:
    """Render one approach, track it with ``tracker_seeds`` seeds; per frame: quads, states, stamps, truth."""
    seed, k, frames, tracker_seeds, cache = job
    path = Path(cache) / f"approach{seed}_{frames}.npz"
    if path.is_file():
        return {"seed": seed, "path": str(path)}
    from docking import run_ours  # noqa: PLC0415

    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: PLC0415

    opts = approach_options(k)
    scene = DockingScene(DockingSceneConfig(width=640, height=480, frames=frames, **opts), seed=seed)
    folder = Path(cache) / f"frames{seed}_{frames}"
    folder.mkdir(parents=True, exist_ok=True)
    files, quads, truth, stamps = [], [], [], []
    for frame in scene.frames():
        files.append(str(folder / f"{frame.index:05d}.png"))
        cv2.imwrite(files[-1], frame.image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        quads.append(frame.quad)
        truth.append(frame.guidance)
        stamps.append(frame.stamp_ns)
    quads = np.array(quads)
    lo, hi = quads.min(axis=1), quads.max(axis=1)
    seq = {"name": str(seed), "kind": "synthetic", "files": files, "gt_quads": quads,
           "gt_boxes": np.concatenate([lo, hi - lo], axis=1), "size": [640, 480]}
    runs = [run_ours(seq, {}, seed=s, start="box") for s in range(tracker_seeds)]
    for f in files:
        os.remove(f)
    np.savez_compressed(path, quads=np.array([r["quads"] for r in runs]),
                        states=np.array([r["states"] for r in runs]),
                        seconds=np.array([r["times"] for r in runs]), truth=np.array(truth),
                        stamps=np.array(stamps, np.int64), gt_quads=quads, options=json.dumps(opts))
    return {"seed": seed, "path": str(path)}


GEAR_KEYS = ("gear_min_height_px", "gear_search", "gear_window", "gear_band", "gear_min_symmetry", "gear_min_contrast",
             "gear_axes", "gear_axis_contrast", "gear_contact_window", "gear_lowest_step")


def measure_gears(job: tuple) -> str:
    """The nose wheel's ground contact under every tracked run's quadrilaterals (the scene rendered anew: the
    frames are not kept), with ``config``'s ``gear_*`` constants; cached beside the tracked runs."""
    path, config = job
    from aircraft_docking_tracker.docking.guidance import DockingGuidance, GuidanceConfig  # noqa: PLC0415
    from aircraft_docking_tracker.docking.nose_gear import NOSE_GEAR_DTYPE  # noqa: PLC0415
    from aircraft_docking_tracker.docking.stand import parse_stand  # noqa: PLC0415
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: PLC0415

    key = "_".join(f"{config[k]:g}" for k in GEAR_KEYS)
    out = Path(path).with_name(Path(path).stem.replace("approach", "gears") + f"_{key}.npy")
    if out.is_file():
        return str(out)
    with np.load(path) as z:
        quads, options = z["quads"], json.loads(str(z["options"]))
    seed = int(Path(path).stem.split("_")[0].removeprefix("approach"))
    scene = DockingScene(DockingSceneConfig(width=640, height=480, frames=quads.shape[1], **options), seed=seed)
    guidance = DockingGuidance(parse_stand(scene.stand_calibration()), GuidanceConfig(**config))
    gears = np.full(quads.shape[:2], np.nan, NOSE_GEAR_DTYPE)
    seconds = np.full(quads.shape[:2], np.nan)
    for frame in scene.frames():
        for run in range(len(quads)):
            quad = quads[run, frame.index]
            if np.isfinite(quad).all():
                t0 = time.perf_counter()
                gears[run, frame.index] = guidance.measure_gear(frame.image, quad)[0]
                seconds[run, frame.index] = time.perf_counter() - t0
    np.save(out, gears)
    np.save(out.with_name(out.stem + "_seconds.npy"), seconds)
    return str(out)


def guide(approach: dict, run: int, config, exact_survey: bool = False) -> dict:
    """The guidance over one tracked run: a ``GUIDANCE_DTYPE`` row per frame, and its mean time per frame; with
    ``exact_survey`` on the stand's exact calibration instead of the surveyor's (the method's own error)."""
    from aircraft_docking_tracker.docking.guidance import DockingGuidance, guide_track  # noqa: PLC0415
    from aircraft_docking_tracker.docking.tracker import LOST, TRACKING  # noqa: PLC0415

    guidance = DockingGuidance(approach["stand_exact" if exact_survey else "stand"], config)
    states = approach["states"][run]
    t0 = time.perf_counter()
    gears = approach["gears"][run] if approach.get("gears") is not None else None
    rows = guide_track(guidance, approach["quads"][run], states == TRACKING, states == LOST, approach["stamps"], gears)
    seconds = (time.perf_counter() - t0) / len(rows)
    return {"rows": rows, "seconds": seconds}


def score(approach: dict, guided: dict) -> dict:
    """Issue 15's measures of one guided run (``evaluation.guidance_metrics``, as ``evaluate`` reports them)."""
    from aircraft_docking_tracker.docking.guidance import true_guidance  # noqa: PLC0415
    from aircraft_docking_tracker.evaluation.guidance_metrics import guidance_errors  # noqa: PLC0415

    truth = true_guidance(*approach["truth"].T)
    e = guidance_errors(guided["rows"], truth, NEAR_M)
    near = approach["truth"][:, 0] <= NEAR_M
    drawn = np.abs(guided["rows"]["distance_m"][near] - approach["drawn"][near])
    return {"_near_errors": np.abs(np.c_[guided["rows"]["lateral_m"][near] - truth["lateral_m"][near],
                                         guided["rows"]["distance_m"][near] - truth["distance_m"][near]]),
            "distance_p95_drawn": float(np.percentile(drawn, 95)) if np.isfinite(drawn).all() else float("inf"),
            "lateral_p50": e["lateral_near_median"], "lateral_p95": e["lateral_near_p95"],
            "distance_p50": e["distance_near_median"], "distance_p95": e["distance_near_p95"],
            "stop_at_m": e["stop_at_m"], "stop_ok": e["stop_within"], "stop_early": e["stop_early"],
            "stop_missed": e["stop_missed"], "state_accuracy": e["state_accuracy"], "speed_p50": e["speed_near_median"],
            "ms_per_frame": guided["seconds"] * 1e3}


@functools.lru_cache(maxsize=1)
def drawn_contact_row() -> float:
    """Where the synthetic scene draws the nose wheel's bottom, in template pixels: the 50 % row of the sprite's
    alpha down the axis (196.06 since session 28's supersampled sprite; 196.32 before, OpenCV filling the last
    row's pixels whole)."""
    from aircraft_docking_tracker.scenarios.docking import NOSE_TPL, SPRITE_SCALE, draw_aircraft  # noqa: PLC0415

    _, alpha = draw_aircraft(np.random.default_rng(0))
    column = alpha[:, int(NOSE_TPL[0] * SPRITE_SCALE)]
    last = int(np.flatnonzero(column > 0.5)[-1])
    return (last - 0.5 + column[last] + column[last + 1]) / SPRITE_SCALE     # the last rows' coverage past row - 0.5


def drawn_distances(scene, stand_exact) -> np.ndarray:
    """Per frame, the distance to go of where the scene draws the nose wheel on the apron (the exact camera): a
    check of the scene, which drew it 0.42-0.50 m short of the truth until session 28 (a flat aircraft at the nose's
    depth, and the tyre filled past its row) and now draws it within a few hundredths of a metre."""
    from aircraft_docking_tracker.docking.guidance import along_line  # noqa: PLC0415
    from aircraft_docking_tracker.scenarios.docking import NOSE_TPL, apply_affine  # noqa: PLC0415

    row = drawn_contact_row()
    aircraft = stand_exact.aircraft_type(next(iter(stand_exact.aircraft)))
    stop_arc = along_line(stand_exact.lead_in, aircraft.stop_m)[0]
    out = []
    for i in range(scene.config.frames):
        pixel = apply_affine(scene.pose(i)[0], [[NOSE_TPL[0], row]])[0]
        out.append(stop_arc - along_line(stand_exact.lead_in, stand_exact.camera.on_plane([pixel])[0])[0])
    return np.array(out)


def survey_at_stop(stand, stand_exact) -> dict:
    """The surveyor's calibration at the stop mark: its error along the lead-in line (where it puts the apron point
    the exact camera sees at the mark, minus the mark: + reads long) and the 95 % the stand's own marks predict
    (``guidance.survey_sigma``, from their residuals alone)."""
    from aircraft_docking_tracker.docking.guidance import along_line, survey_sigma  # noqa: PLC0415

    aircraft = stand.aircraft_type(next(iter(stand.aircraft)))
    pixel = stand_exact.camera.project([[*aircraft.stop_m, 0.0]])
    seen = stand.camera.on_plane(pixel)[0, :2]
    stop_arc = along_line(stand.lead_in, aircraft.stop_m)[0]
    return {"error_m": float(stop_arc - along_line(stand.lead_in, seen)[0]),
            "predicted95_m": 2 * survey_sigma(stand, aircraft.stop_m)[0]}


def load(paths: list[str]) -> list[dict]:
    """The cached tracked runs, each with its stand's calibration (the file made anew, as a surveyor would: it needs
    no rendering; read once here, not per run)."""
    from aircraft_docking_tracker.docking.stand import parse_stand  # noqa: PLC0415
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: PLC0415

    out = []
    for p in paths:
        with np.load(p) as z:
            a = {k: z[k] for k in z.files}
        a["options"] = json.loads(str(a["options"]))
        a["seed"] = int(Path(p).stem.split("_")[0].removeprefix("approach"))
        frames = len(a["stamps"])
        scene = DockingScene(DockingSceneConfig(width=640, height=480, frames=frames, **a["options"]), seed=a["seed"])
        a["stand"] = parse_stand(scene.stand_calibration())
        a["stand_exact"] = parse_stand(scene.stand_calibration(click_sigma_px=0.0))
        a["drawn"] = drawn_distances(scene, a["stand_exact"])
        a["survey"] = survey_at_stop(a["stand"], a["stand_exact"])
        out.append(a)
    return out


def evaluate(approaches: list[dict], config, exact_survey: bool = False) -> list[dict]:
    rows = []
    for a in approaches:
        for run in range(len(a["quads"])):
            rows.append({"seed": a["seed"], "run": run, **score(a, guide(a, run, config, exact_survey))})
    return rows


def summary(rows: list[dict]) -> dict:
    """Pooled over runs: mean and worst of the per-run p95s (a run with frames without a figure has an infinite
    p95: its worst shows it, its mean takes it as 20 m), STOP rates."""
    def col(k):
        values = np.array([r[k] for r in rows], float)
        return np.minimum(values, 20.0) if k.endswith("_p95") else values

    def worst(k):
        return float(np.max([r[k] for r in rows]))
    pooled = np.nan_to_num(np.concatenate([r["_near_errors"] for r in rows]), nan=np.inf)   # no figure: infinite
    return {"runs": len(rows),
            "lateral_p95_pooled": float(np.percentile(pooled[:, 0], 95, method="higher")),
            "distance_p95_pooled": float(np.percentile(pooled[:, 1], 95, method="higher")),
            "lateral_p95_mean": float(np.mean(col("lateral_p95"))), "lateral_p95_worst": worst("lateral_p95"),
            "lateral_p50_median": float(np.median(col("lateral_p50"))),
            "distance_p95_mean": float(np.mean(col("distance_p95"))),
            "distance_p95_worst": worst("distance_p95"),
            "distance_p50_median": float(np.median(col("distance_p50"))),
            "stop_ok": float(np.mean(col("stop_ok"))), "stop_early": float(np.mean(col("stop_early"))),
            "stop_missed": float(np.mean(col("stop_missed"))), "state_accuracy": float(np.mean(col("state_accuracy"))),
            "speed_p50_median": float(np.median(col("speed_p50"))),
            "runs_without_figures": int(sum(not np.isfinite(r["distance_p95"]) for r in rows)),
            "lateral_p95_median": float(np.median([r["lateral_p95"] for r in rows])),
            "distance_p95_median": float(np.median([r["distance_p95"] for r in rows])),
            "runs_lateral_met": int(sum(r["lateral_p95"] <= 0.25 for r in rows)),
            "runs_distance_met": int(sum(r["distance_p95"] <= 0.5 for r in rows)),
            "distance_p95_drawn_median": float(np.median([r["distance_p95_drawn"] for r in rows])),
            "runs_distance_drawn_met": int(sum(r["distance_p95_drawn"] <= 0.5 for r in rows)),
            "stop_at_worst_early": float(np.nanmax(col("stop_at_m"))) if np.isfinite(col("stop_at_m")).any() else None,
            "ms_per_frame": float(np.median(col("ms_per_frame")))}


_APPROACHES: list[dict] = []
WORKERS = 2


def _set_approaches(approaches: list[dict]) -> None:
    _APPROACHES[:] = approaches


def _candidate_summary(chosen: dict) -> dict:
    from aircraft_docking_tracker.docking.guidance import GuidanceConfig  # noqa: PLC0415

    return summary(evaluate(_APPROACHES, replace(GuidanceConfig(), **chosen)))


def tune(approaches: list[dict]) -> tuple[dict, list]:
    """Choose the constants on the tuning approaches (every run of every approach counts; the worst is reported
    beside): the fewest early STOPs, then the most STOPs within 0.5 m, then the smallest mean of the lateral and
    distance p95s, then the closing speed's median error. Rates are compared to 0.1 (6 of 60 runs) and the p95s to
    0.1 m: closer than that is within what another tracker seed moves (measured: one seed's STOP moves by metres);
    ties are then broken by the same figures unrounded, and last by the closing speed."""
    candidates = [dict(zip(GRID, values)) for values in itertools.product(*GRID.values())]
    with multiprocessing.get_context("spawn").Pool(WORKERS, initializer=_set_approaches, initargs=(approaches,)) as pool:
        summaries = pool.map(_candidate_summary, candidates)
    table = [{**chosen, **s} for chosen, s in zip(candidates, summaries)]
    best = min(table, key=lambda r: (round(r["stop_early"], 1), round(-r["stop_ok"], 1),
                                     round(r["distance_p95_mean"] + r["lateral_p95_mean"], 1),
                                     r["stop_early"], -r["stop_ok"], r["distance_p95_mean"] + r["lateral_p95_mean"],
                                     r["speed_p50_median"]))
    return {k: best[k] for k in GRID}, table


def _constant(default, text: str):
    """``--set``'s value in its default's type (a boolean by ``config.parse_bool``)."""
    from aircraft_docking_tracker.config import parse_bool  # noqa: PLC0415

    try:
        return parse_bool(text) if isinstance(default, bool) else type(default)(text)
    except ValueError as error:
        raise SystemExit(f"--set: {error}") from None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--approaches", type=int, default=20)
    parser.add_argument("--seeds", type=int, default=3, help="tracker seeds per approach")
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--cache", type=Path, default=None, help="keep the tracked runs here")
    parser.add_argument("--tune", action="store_true", help="seeds 100..: choose the constants (GRID)")
    parser.add_argument("--first-seed", type=int, default=None,
                        help="approaches from this seed (default 200, held out; 100 with --tune)")
    parser.add_argument("--set", action="append", default=[], help="guidance constant key=value")
    parser.add_argument("--tag", default="")
    parser.add_argument("--quick", action="store_true", help="4 approaches, 1 tracker seed (make bench --quick)")
    args = parser.parse_args()
    if args.quick:
        args.approaches, args.seeds, args.tag = 4, 1, args.tag or "quick"
    global WORKERS
    WORKERS = args.workers
    from aircraft_docking_tracker.docking.guidance import GuidanceConfig  # noqa: PLC0415

    overrides = {k: _constant(getattr(GuidanceConfig(), k), v) for k, v in (s.split("=", 1) for s in args.set)}
    seed0 = args.first_seed if args.first_seed is not None else TUNE_SEED0 if args.tune else HELD_OUT_SEED0
    cache = args.cache or Path(tempfile.mkdtemp(prefix="guidance_"))
    cache.mkdir(parents=True, exist_ok=True)
    started = time.time()
    jobs = [(seed0 + k, k, args.frames, args.seeds, str(cache)) for k in range(args.approaches)]
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        done = list(pool.imap_unordered(track_approach, jobs))
    paths = sorted(d["path"] for d in done)
    gear_config = {k: v for k, v in asdict(replace(GuidanceConfig(), **overrides)).items()
                   if k in GEAR_KEYS or k in ("stand_file", "aircraft_type")}
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        gear_paths = pool.map(measure_gears, [(p, gear_config) for p in paths])
    approaches = load(paths)
    for a, g in zip(approaches, gear_paths):
        a["gears"] = np.load(g)
        a["gear_seconds"] = np.load(Path(g).with_name(Path(g).stem + "_seconds.npy"))
    tracked = time.time() - started
    payload = {"seeds": args.seeds, "frames": args.frames, "first_seed": seed0, "tracking_s": tracked}
    if args.tune:
        chosen, table = tune(approaches)
        payload.update({"chosen": chosen, "grid": table})
        print("chosen", chosen)
    config = replace(GuidanceConfig(), **overrides)
    rows = evaluate(approaches, config)
    exact = summary(evaluate(approaches, config, exact_survey=True))
    payload.update({"exact_survey": {k: exact[k] for k in ("lateral_p95_pooled", "distance_p95_pooled",
                                                            "runs_distance_met", "runs_lateral_met", "stop_ok")},
                    "survey": {a["seed"]: a["survey"] for a in approaches}})
    payload.update({"config": asdict(config), "summary": summary(rows),
                    "rows": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
                    "tracker_ms_per_frame": float(np.median(np.concatenate(
                        [a["seconds"][:, 1:].ravel() for a in approaches])) * 1e3)})
    measured = np.concatenate([a["gear_seconds"][np.isfinite(a["gears"]["symmetry"])] for a in approaches]) * 1e3
    payload.update({"gear_ms_median": float(np.median(measured)), "gear_ms_p95": float(np.percentile(measured, 95))})
    stem = "guidance" + ("_tune" if args.tune else "") + (f"_{args.tag}" if args.tag else "")
    (HERE / "results" / f"{stem}.json").write_text(json.dumps(payload, indent=1))
    (HERE / "results" / f"{stem}.md").write_text("\n".join(markdown(payload, approaches)) + "\n")
    plot(approaches, config, HERE / "plots" / f"{stem}.png")
    print("\n".join(markdown(payload, approaches)))
    return 0


def markdown(payload: dict, approaches: list[dict]) -> list[str]:
    s = payload["summary"]
    near = [a["truth"][:, 0] <= NEAR_M for a in approaches]
    drawn_offset = float(np.median([np.median(a["drawn"][n] - a["truth"][n, 0]) for a, n in zip(approaches, near)]))
    x = payload["exact_survey"]
    predicted = [a["survey"]["predicted95_m"] for a in approaches]
    realised = [abs(a["survey"]["error_m"]) for a in approaches]
    md = [f"## Docking guidance (issue 15): {len(approaches)} synthetic approaches of seeds {payload['first_seed']}.., "
          f"{payload['seeds']} tracker seeds, {payload['frames']} frames at 14 Hz", "",
          "Guidance constants: " + ", ".join(f"{k} {v}" for k, v in payload["config"].items()
                                             if k not in ("stand_file", "aircraft_type")), "",
          "| measure | target | measured (mean over runs / median / worst run) |", "|---|---|---|",
          f"| lateral and distance errors within the last 15 m, p95 of every frame of every run | <= 0.25 / 0.5 m | "
          f"{s['lateral_p95_pooled']:.3f} / {s['distance_p95_pooled']:.3f} m |",
          f"| the same on each stand's exact calibration (the method's own share; the survey's is the rest) | - | "
          f"{x['lateral_p95_pooled']:.3f} / {x['distance_p95_pooled']:.3f} m; per run met on {x['runs_lateral_met']} / "
          f"{x['runs_distance_met']} of {s['runs']} |",
          f"| the survey's error at the stop mark along the line (0.5 px clicks): the stands' own 95 % "
          "(from their marks' residuals) / realised | - | "
          f"median {np.median(predicted):.2f} / {np.median(realised):.2f} m, largest {np.max(predicted):.2f} / "
          f"{np.max(realised):.2f} m; beyond 3 sigma on {sum(r > 1.5 * p for r, p in zip(realised, predicted))} |",
          f"| lateral error within the last 15 m, p95 | <= 0.25 m | {s['lateral_p95_mean']:.2f} / "
          f"{s['lateral_p95_median']:.2f} / {s['lateral_p95_worst']:.2f} m (median error {s['lateral_p50_median']:.2f} m); "
          f"met on {s['runs_lateral_met']} of {s['runs']} runs |",
          f"| distance error within the last 15 m, p95 | <= 0.5 m | {s['distance_p95_mean']:.2f} / "
          f"{s['distance_p95_median']:.2f} / {s['distance_p95_worst']:.2f} m (median error {s['distance_p50_median']:.2f} m); "
          f"met on {s['runs_distance_met']} of {s['runs']} runs |",
          f"| the same against where the scene draws the nose wheel (diagnostic: {drawn_offset:+.2f} m from the truth, "
          "median over approaches) | - | median over runs "
          f"{s['distance_p95_drawn_median']:.2f} m; met on {s['runs_distance_drawn_met']} of {s['runs']} runs |",
          f"| STOP first shown with the nose within 0.5 m | >= 95 % | {100 * s['stop_ok']:.0f} % |",
          f"| STOP shown more than 1 m early | never | {100 * s['stop_early']:.0f} % of runs "
          f"(latest-placed first STOP {s['stop_at_worst_early']:.2f} m before the mark) |"
          if s["stop_at_worst_early"] is not None else "| STOP shown more than 1 m early | never | never shown |",
          f"| STOP never shown | - | {100 * s['stop_missed']:.0f} % of runs |",
          f"| runs with frames without a figure in the last 15 m (lost; their p95 is infinite, 20 m in the mean) | - | "
          f"{s['runs_without_figures']} of {s['runs']} |",
          f"| closing speed error within the last 15 m | - | {s['speed_p50_median']:.2f} m/s (median over runs of the "
          "median) |",
          f"| state shown right | - | {100 * s['state_accuracy']:.0f} % of frames (mean over runs) |",
          f"| time per frame | < 1 ms | guidance {s['ms_per_frame']:.3f} ms (median over runs of the mean), and on the "
          f"frames the nose wheel is looked for {payload['gear_ms_median']:.2f} ms more (median; p95 "
          f"{payload['gear_ms_p95']:.2f} ms), beside the tracker's {payload['tracker_ms_per_frame']:.1f} ms (the "
          "tracker's timed when the runs were cached, the nose wheel in this run) |", "",
          "| approach | camera h / d [m] | survey at the stop: error / 95 % [m] | run | lateral p50 / p95 [m] | "
          "distance p50 / p95 [m] | STOP at [m] |",
          "|---|---|---|---|---|---|---|"]
    options = {a["seed"]: a["options"] for a in approaches}
    for r in payload["rows"]:
        o = options[r["seed"]]
        survey = payload["survey"][r["seed"]]
        md.append(f"| {r['seed']} {o['weather']}/{o['occluder']} | {o['camera_height_m']:.1f} / "
                  f"{o['camera_distance_m']:.1f} | {survey['error_m']:+.2f} / {survey['predicted95_m']:.2f} | "
                  f"{r['run']} | {r['lateral_p50']:.2f} / {r['lateral_p95']:.2f} | "
                  f"{r['distance_p50']:.2f} / {r['distance_p95']:.2f} | {r['stop_at_m']:.2f} |")
    return md


def plot(approaches: list[dict], config, path: Path) -> None:
    """Errors over the true distance to go, every run (the last 60 m): ``evaluate``'s guidance plot."""
    from aircraft_docking_tracker.evaluation.plots import guidance_error_plot  # noqa: PLC0415

    runs = {}
    for a in approaches:
        for run in range(len(a["quads"])):
            rows = guide(a, run, config)["rows"]
            runs[f"{a['seed']}/{run}"] = {"true_distance_m": a["truth"][:, 0],
                                          "distance_error_m": rows["distance_m"] - a["truth"][:, 0],
                                          "lateral_error_m": rows["lateral_m"] - a["truth"][:, 1]}
    path.parent.mkdir(parents=True, exist_ok=True)
    guidance_error_plot(runs, path, f"Docking guidance, {len(runs)} runs: errors over the distance to go")


if __name__ == "__main__":
    sys.exit(main())
