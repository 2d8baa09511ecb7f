"""Benchmark of the association core (issues 6, 13): seed 003's tracker, each improvement, PyPI peers.

    python bench/association.py [--quick] [--no-peers] [--no-loso]

Side by side in one run, on the same prepared detections:

* sequences: MOT15 TUD-Campus (25 frames/s, SORT's det.txt) and the aerial airport-2 (scores cut at
  0.4) from ``../shared/data/mot``, and synthetic UAV scenes (``aircraft_docking_tracker.scenarios.uav``:
  ground truth turned into detections with misses, clutter and jitter by ``synthesize_detections``;
  one of them with hides up to 170 frames, seed 003's smoke and viaduct occlusions);
* trackers: the seed, each improvement switched on alone, our default, each choice of issue 13
  undone alone, and peers from PyPI at their documented defaults, run in their own venv
  ``bench/.venv-peers`` (``bench/requirements-peers.txt``) because their pins clash with ours:
  SORT, ByteTrack, OC-SORT, BoT-SORT (no camera-motion compensation) from ``trackers``, abewley's
  SORT (``sort-track``, its sort.py packaged), ``motpy``;
* measures: HOTA, DetA, AssA (``evaluation.mot_metrics``, TrackEval's algorithm; checked against
  TrackEval itself on our default's results), MOTA, IDF1, ID switches, MT / ML, FP / FN, frames/s
  of the tracker alone (detections in memory), the cost of one frame against the number of
  targets (10, 100, 1000 targets with as many detections);
* the defaults: a grid over the output-policy and re-acquisition knobs scored on every sequence,
  chosen leave-one-sequence-out (held-out scores reported, mean and worst).

Writes ``bench/results/association.json`` and ``.md`` and ``bench/plots/association_*.png``.
The same file, run with ``--peer-worker IN OUT`` (or ``--hota-worker``) by the peers' venv, runs one
peer (or TrackEval) there.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
PEER_VENV = HERE / ".venv-peers"
PEER_REQUIREMENTS = HERE / "requirements-peers.txt"
PEER_NO_DEPS = ["sort-track==0.0.8"]         # abewley's SORT; its scipy==1.9.3 pin cannot install on Python 3.11+
PEERS = ["SORT (trackers)", "ByteTrack (trackers)", "OC-SORT (trackers)", "BoT-SORT (trackers, no CMC)",
         "SORT (abewley)", "motpy"]
SORT_FAMILY = PEERS[:5]
SCALING_TARGETS = (10, 100, 1000)
#: Synthetic UAV scenes: name, difficulty, seed, longest planned hide [frames] (seed 003: 100-170-frame occlusions)
UAV_SCENES = (("uav-normal", 1, 3, 150), ("uav-hard", 2, 5, 150), ("uav-long-hides", 2, 11, 170))
OURS = "ours (default)"
AIRPORT_MIN_SCORE = 0.4
REPEATS = 3          # frames/s: the fastest of this many identical runs, ours and the peers' alike (1 in --quick)


# ================================================================================================
# Peer worker: runs inside bench/.venv-peers (numpy + the peer only)
# ================================================================================================
def peer_worker(in_path: str, out_path: str) -> None:
    """Track the detections in ``in_path`` (npz) with one peer; save ids, boxes and per-frame times."""
    data = np.load(in_path, allow_pickle=False)
    name, fps = str(data["tracker"]), float(data["fps"])
    frames, boxes, scores = data["frame"], data["boxes"], data["score"]
    n_frames = int(data["n_frames"])
    starts = np.searchsorted(frames, np.arange(1, n_frames + 2))
    best = None
    for _ in range(int(data["repeats"])):                 # timing: the fastest of a few identical runs
        step = _peer_stepper(name, fps)
        out_frame, out_id, out_box, times = [], [], [], []
        for k in range(n_frames):
            sl = slice(starts[k], starts[k + 1])
            b, s = boxes[sl], scores[sl]
            xyxy = np.concatenate([b[:, :2], b[:, :2] + b[:, 2:]], axis=1) if len(b) else np.zeros((0, 4))
            t0 = time.perf_counter()
            ids, out_xyxy = step(xyxy, s)
            times.append(time.perf_counter() - t0)
            out_frame += [k + 1] * len(ids)
            out_id += list(ids)
            out_box += [np.concatenate([o[:2], o[2:] - o[:2]]) for o in out_xyxy]
        if best is None or sum(times) < sum(best):
            best = times
    times = best
    np.savez(out_path, frame=np.array(out_frame, dtype=np.int64), id=np.array(out_id, dtype=np.int64),
             boxes=np.array(out_box, dtype=np.float64).reshape(-1, 4), times=np.array(times))


def hota_worker(in_path: str, out_path: str) -> None:
    """TrackEval's own HOTA (``trackeval.metrics.HOTA``, box IoU from its dataset class) of one result."""
    import json as json_  # noqa: PLC0415

    from trackeval.datasets._base_dataset import _BaseDataset  # noqa: PLC0415
    from trackeval.metrics import HOTA  # noqa: PLC0415

    data = np.load(in_path, allow_pickle=False)
    n_frames = int(data["n_frames"])
    gt_ids_all, hyp_ids_all = np.unique(data["gt_id"]), np.unique(data["hyp_id"])
    seq = dict(gt_ids=[], tracker_ids=[], similarity_scores=[], num_gt_dets=len(data["gt_id"]),
               num_tracker_dets=len(data["hyp_id"]), num_gt_ids=len(gt_ids_all), num_tracker_ids=len(hyp_ids_all))
    for k in range(1, n_frames + 1):
        g, h = data["gt_frame"] == k, data["hyp_frame"] == k
        seq["gt_ids"].append(np.searchsorted(gt_ids_all, data["gt_id"][g]))
        seq["tracker_ids"].append(np.searchsorted(hyp_ids_all, data["hyp_id"][h]))
        seq["similarity_scores"].append(_BaseDataset._calculate_box_ious(data["gt_box"][g], data["hyp_box"][h]))
    res = HOTA().eval_sequence(seq)
    Path(out_path).write_text(json_.dumps({k: 100 * float(np.mean(res[v])) for k, v in
                                           (("hota", "HOTA"), ("deta", "DetA"), ("assa", "AssA"))}))


def trackeval_hota(python: Path, gt: np.ndarray, rows: np.ndarray, n_frames: int) -> dict:
    """HOTA, DetA, AssA of ``rows`` computed by TrackEval itself in the peers' venv (the check of our port)."""
    from aircraft_docking_tracker.io import motchallenge as mc  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.json"
        np.savez(src, n_frames=n_frames, gt_frame=gt["frame"], gt_id=gt["id"], gt_box=mc.boxes(gt),
                 hyp_frame=rows["frame"], hyp_id=rows["id"], hyp_box=mc.boxes(rows))
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        subprocess.run([str(python), __file__, "--hota-worker", str(src), str(dst)], check=True, env=env)
        return json.loads(dst.read_text())


def _peer_stepper(name: str, fps: float):
    """A function (xyxy, scores) -> (ids, xyxy) for one peer at its default settings."""
    if name == OURS:                                   # our default, run the same way for the speed duel
        sys.path.insert(0, str(REPO))
        from multi_target_tracker.association import MultiTargetTracker  # noqa: PLC0415

        tracker, frame = MultiTargetTracker(), [0]

        def step(xyxy, scores):
            frame[0] += 1
            result = tracker.step(frame[0] / fps, np.concatenate([xyxy[:, :2], xyxy[:, 2:] - xyxy[:, :2]], axis=1),
                                  scores)
            shown = result.tracks.visible()
            return list(shown.ids), list(np.concatenate([shown.boxes[:, :2], shown.boxes[:, :2] + shown.boxes[:, 2:]],
                                                        axis=1))
        return step
    if name == "SORT (abewley)":
        from sort import SortTracker  # noqa: PLC0415  (sort-track 0.0.8: abewley/sort's sort.py, defaults 1, 3, 0.3)

        tracker = SortTracker()

        def step(xyxy, scores):
            dets = np.concatenate([xyxy, scores[:, None], np.zeros((len(xyxy), 1))], axis=1) if len(xyxy) \
                else np.empty((0, 6))
            out = tracker.update(dets, None)                   # rows x1, y1, x2, y2, id, class, score
            return [int(r[4]) for r in out], [np.asarray(r[:4], dtype=np.float64) for r in out]
        return step
    if name == "motpy":
        from motpy import Detection, MultiObjectTracker  # noqa: PLC0415

        tracker = MultiObjectTracker(dt=1.0 / fps)
        id_map: dict[str, int] = {}

        def step(xyxy, scores):
            tracker.step([Detection(box=b, score=float(s)) for b, s in zip(xyxy, scores)])
            tracks = tracker.active_tracks(min_steps_alive=3)
            ids = [id_map.setdefault(t.id, len(id_map) + 1) for t in tracks]
            return ids, [np.asarray(t.box, dtype=np.float64) for t in tracks]
        return step

    import supervision as sv  # noqa: PLC0415
    import trackers  # noqa: PLC0415

    if name == "BoT-SORT (trackers, no CMC)":               # no images here: camera-motion compensation off
        tracker = trackers.BoTSORTTracker(frame_rate=fps, enable_cmc=False)
    else:
        cls = {"SORT (trackers)": trackers.SORTTracker, "ByteTrack (trackers)": trackers.ByteTrackTracker,
               "OC-SORT (trackers)": trackers.OCSORTTracker}[name]
        tracker = cls(frame_rate=fps)

    def step(xyxy, scores):
        det = sv.Detections(xyxy=xyxy.astype(np.float32).reshape(-1, 4), confidence=scores.astype(np.float32),
                            class_id=np.zeros(len(xyxy), dtype=int))
        res = tracker.update(det)
        keep = res.tracker_id >= 0
        return list(res.tracker_id[keep]), list(res.xyxy[keep])
    return step


# ================================================================================================
# The benchmark (our venv)
# ================================================================================================
def variants():
    """Our tracker's configurations: the seed, one improvement at a time, the default, and each
    choice of issue 13 undone alone."""
    from multi_target_tracker.association import AssociationConfig, seed_config  # noqa: PLC0415
    from multi_target_tracker.kalman import KalmanConfig  # noqa: PLC0415

    kalman = KalmanConfig()
    collapsing = KalmanConfig(missed_update="prediction")
    fixed_noise = KalmanConfig(acceleration_noise=400.0, acceleration_noise_per_px=0.0, measurement_noise=4.0,
                               measurement_noise_per_px=0.0)
    issue6_kalman = KalmanConfig(missed_update="prediction", acceleration_noise=50.0, acceleration_noise_per_px=12.0)
    seed_gate = dict(gate="mahalanobis")
    short = dict(seed_gate, confirm_length=4, tentative_max_misses=1)
    default = AssociationConfig()
    always_coast = dict(coast_output_frames=100000, coast_output_std=1e6)
    show = dict(coasting=True, backfill=False)           # the node's output: states 1 and 2
    return {
        "seed (§3 as written)": dict(show, config=seed_config(), kalman=issue6_kalman),
        "+ Mahalanobis gate": dict(show, config=seed_config(**seed_gate), kalman=issue6_kalman),
        "+ l_t 4, tentative drop": dict(show, config=seed_config(**short), kalman=issue6_kalman),
        "+ IoU cost": dict(show, config=seed_config(**short, iou_weight=3.0), kalman=issue6_kalman),
        "+ second pass (issue-6 default)": dict(show, config=seed_config(**short, iou_weight=3.0, second_pass=True),
                                                kalman=issue6_kalman),
        OURS: dict(show, config=default, kalman=kalman),
        "default, coasting always published": dict(show, config=AssociationConfig(**always_coast), kalman=kalman),
        "default, coasting never published": dict(show, config=AssociationConfig(coast_output_frames=0),
                                                  kalman=kalman),
        "default, collapsing covariance": dict(show, config=default, kalman=collapsing),
        "default, no first-frame activation": dict(show, config=AssociationConfig(confirm_first_frame=False),
                                                   kalman=kalman),
        "default + cascade": dict(show, config=AssociationConfig(cascade=True), kalman=kalman),
        "default + re-acquire radius": dict(show, config=AssociationConfig(reacquire_frames=60), kalman=kalman),
        "default, no angle term": dict(show, config=AssociationConfig(angle_weight=0.0), kalman=kalman),
        "default, fixed-size noise": dict(show, config=default, kalman=fixed_noise),
        "default, backfill (offline)": dict(config=default, kalman=kalman, coasting=True, backfill=True),
    }


def load_sequences(quick: bool) -> dict:
    """name -> dict(det rows, gt rows, fps, n_frames). MOT rows (``motchallenge.MOT_ROW_DTYPE``)."""
    from aircraft_docking_tracker.io import motchallenge as mc  # noqa: PLC0415

    data = Path(os.environ.get("ADT_SHARED_DATA", REPO.parent / "shared" / "data")) / "mot"
    seqs = {}
    # The prepared detections every tracker gets: TUD-Campus as SORT used it (25 frames/s, all rows),
    # airport-2 cut at score 0.4 (its file keeps detections down to 0.05 on purpose).
    for name, fps, cut in (("TUD-Campus", 25.0, None), ("airport-2", 30.0, AIRPORT_MIN_SCORE)):
        folder = data / name
        if not (folder / "det.txt").is_file():
            print(f"[association bench] {folder} absent: skipped", file=sys.stderr)
            continue
        info = mc.read_seqinfo(folder)
        det, gt = mc.read_detections(folder / "det.txt", cut), mc.read_ground_truth(folder / "gt.txt")
        n = int(max(det["frame"].max(), gt["frame"].max(), info.get("seqLength", 0)))
        seqs[name] = dict(det=det, gt=gt, fps=info.get("frameRate", fps), n_frames=n,
                          source=str(folder) + ("" if cut is None else f", scores >= {cut}"))
    seqs.update(synthetic_uav(quick))
    return seqs


def synthetic_uav(quick: bool, scenes=UAV_SCENES) -> dict:
    """UAV scenes (issue 3's generator): visible ground truth -> detections with misses, clutter, jitter."""
    from aircraft_docking_tracker.scenarios.uav import UavScene, UavSceneConfig, synthesize_detections  # noqa: PLC0415
    from aircraft_docking_tracker.io import motchallenge as mc  # noqa: PLC0415

    out = {}
    frames = 100 if quick else 400
    for name, difficulty, seed, hide in scenes:
        cfg = UavSceneConfig(frames=frames, difficulty=difficulty, max_hide_frames=hide)
        scene = UavScene(cfg, seed=seed)
        rng = np.random.default_rng(seed)
        det_rows, gt_rows = [], []
        for f in scene.frames():
            k = f.index + 1
            gt = f.ground_truth[f.ground_truth["state"] == 1]           # hidden vehicles are not scored
            det = synthesize_detections(f.ground_truth, rng, miss_rate=0.1, clutter_rate=1.0, jitter_px=1.5,
                                        frame_size=(cfg.width, cfg.height), hidden_below=cfg.hidden_below)
            gt_rows.append(mc.make_rows(k, gt["id"], np.stack([gt["x"], gt["y"], gt["w"], gt["h"]], 1)))
            det_rows.append(mc.make_rows(k, -np.ones(len(det)), np.stack([det["x"], det["y"], det["w"], det["h"]], 1),
                                         det["score"]))
        out[name] = dict(det=np.concatenate(det_rows), gt=np.concatenate(gt_rows), fps=cfg.fps, n_frames=frames,
                         source=f"UavScene(difficulty={difficulty}, seed={seed}, max_hide_frames={hide}), miss 0.1, "
                                f"clutter 1/frame, "
                                f"jitter 1.5 px")
    return out


def run_ours(seq: dict, variant: dict, repeats: int = 1) -> tuple[np.ndarray, float]:
    """Results rows and the seconds the core spent (the fastest of ``repeats`` identical runs)."""
    seconds = []
    for _ in range(repeats):
        rows, spent = _run_ours_once(seq, variant)
        seconds.append(spent)
    return rows, min(seconds)


def _run_ours_once(seq: dict, variant: dict) -> tuple[np.ndarray, float]:
    from multi_target_tracker.association import MultiTargetTracker  # noqa: PLC0415
    from multi_target_tracker.mot_track import track_sequence  # noqa: PLC0415

    tracker = MultiTargetTracker(variant["config"], variant["kalman"])
    times = []
    step = tracker.step

    def timed_step(*args, **kwargs):                  # time the core's frame, as the peers' update is timed
        t0 = time.perf_counter()
        result = step(*args, **kwargs)
        times.append(time.perf_counter() - t0)
        return result
    tracker.step = timed_step
    rows, _ = track_sequence(seq["det"], seq["fps"], tracker, seq["n_frames"], include_coasting=variant["coasting"],
                             backfill=variant["backfill"])
    return rows, float(np.sum(times))


# ------------------------------------------------------------------------------------------------
# Leave-one-sequence-out choice of the defaults
# ------------------------------------------------------------------------------------------------
#: The grid searched: the knobs of the output policy (item 2), of re-acquisition (item 4) and the
#: ones the earlier benchmark found sensitive. Everything else stays at its dataclass default
#: (coast_output_std 0.1 and confirm_length 2 were better on every sequence in a first sweep).
#: kalman.missed_update is 'none' (growing gates, item 4 of issue 13) throughout: a first grid that
#: also offered 'prediction' picked it on the others for TUD-Campus, where it is knife-edge
#: (HOTA 45-54 for neighbouring noise values, against 51-55 with 'none'), held-out HOTA 45.9.
LOSO_GRID = {
    "max_misses": (20, 40, 80),
    "mahalanobis_gate": (6.0, 9.21, 13.8),
    "coast_output_frames": (1, 2, 3),
    "kalman.noise": ((0.0, 2.0), (0.0, 3.0), (20.0, 2.0), (50.0, 3.0), (100.0, 0.0)),  # acceleration_noise, _per_px
}


def grid_configs(grid: dict = LOSO_GRID) -> list[dict]:
    """Every combination of the grid, as flat dicts of the knobs."""
    import itertools  # noqa: PLC0415

    keys = list(grid)
    return [dict(zip(keys, values)) for values in itertools.product(*grid.values())]


def configs_of(knobs: dict):
    """(AssociationConfig, KalmanConfig) of one grid point."""
    from multi_target_tracker.association import AssociationConfig  # noqa: PLC0415
    from multi_target_tracker.kalman import KalmanConfig  # noqa: PLC0415

    assoc = {k: v for k, v in knobs.items() if not k.startswith("kalman.")}
    an, anp = knobs.get("kalman.noise", (KalmanConfig.acceleration_noise, KalmanConfig.acceleration_noise_per_px))
    kalman = KalmanConfig(missed_update=knobs.get("kalman.missed_update", "none"), acceleration_noise=an,
                          acceleration_noise_per_px=anp)
    return AssociationConfig(**assoc), kalman


def loso_objective(rows: dict, names) -> float:
    """What the choice maximises on the training sequences: mean HOTA plus mean MOTA (points)."""
    return float(np.mean([rows[n]["hota"] for n in names]) + np.mean([rows[n]["mota"] for n in names]))


def leave_one_sequence_out(seqs: dict, progress: bool = True) -> dict:
    """Score every grid point on every sequence; for each held-out sequence choose the point that is
    best on the others and report its score on the held-out one. Returns the held-out rows, the
    choice per fold and the choice on all sequences (the defaults)."""
    from tqdm import tqdm  # noqa: PLC0415

    points = grid_configs()
    table = []
    for knobs in tqdm(points, desc="leave-one-sequence-out grid", unit="config", disable=not progress):
        config, kalman = configs_of(knobs)
        variant = dict(config=config, kalman=kalman, coasting=True, backfill=False)
        table.append({name: metrics_row(seq["gt"], run_ours(seq, variant)[0], 1.0, seq["n_frames"])
                      for name, seq in seqs.items()})
    names = list(seqs)
    held_out, chosen = {}, {}
    for out in names:
        train = [n for n in names if n != out]
        best = max(range(len(points)), key=lambda k: loso_objective(table[k], train))
        held_out[out] = {k: v for k, v in table[best][out].items() if k != "fps"}
        chosen[out] = points[best]
    # The three synthetic UAV scenes share a generator: a stricter check leaves a whole domain out
    # (TUD-Campus, airport-2, or every UAV scene at once) and scores the choice on its sequences.
    domains: dict = {}
    for n in names:
        domains.setdefault("synthetic UAV" if n.startswith("uav") else n, []).append(n)
    held_out_domain, chosen_domain = {}, {}
    for domain, members in domains.items():
        train = [n for n in names if n not in members]
        if not train:
            continue
        best = max(range(len(points)), key=lambda k: loso_objective(table[k], train))
        chosen_domain[domain] = points[best]
        for n in members:
            held_out_domain[n] = {k: v for k, v in table[best][n].items() if k != "fps"}
    best_all = max(range(len(points)), key=lambda k: loso_objective(table[k], names))
    return dict(grid={k: list(v) for k, v in LOSO_GRID.items()}, held_out=held_out, chosen=chosen,
                held_out_domain=held_out_domain, chosen_domain=chosen_domain,
                all_sequences=points[best_all], all_sequences_scores=table[best_all])


def ensure_peer_venv() -> Path | None:
    python = PEER_VENV / "bin" / "python"
    if not python.exists():
        print("[association bench] creating bench/.venv-peers (bench/requirements-peers.txt)...", file=sys.stderr)
        try:
            subprocess.run([sys.executable, "-m", "venv", str(PEER_VENV)], check=True)
            subprocess.run([str(python), "-m", "pip", "install", "-q", "-r", str(PEER_REQUIREMENTS)], check=True)
            subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", *PEER_NO_DEPS], check=True)
        except (subprocess.CalledProcessError, OSError) as exc:
            print(f"[association bench] peers unavailable: {exc}", file=sys.stderr)
            return None
    return python


def run_peer(python: Path, name: str, det: np.ndarray, fps: float, n_frames: int,
             repeats: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Run one peer in its venv; returns (MOT rows, per-frame seconds)."""
    from aircraft_docking_tracker.io import motchallenge as mc  # noqa: PLC0415

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, tracker=name, fps=fps, n_frames=n_frames, repeats=repeats, frame=det["frame"].astype(np.int64),
                 boxes=mc.boxes(det), score=det["score"])
        env = dict(os.environ) if name == OURS else {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        subprocess.run([str(sys.executable if name == OURS else python), __file__, "--peer-worker", str(src),
                        str(dst)], check=True, env=env)
        res = np.load(dst, allow_pickle=False)
        rows = np.concatenate([mc.make_rows(int(f), [i], b) for f, i, b in zip(res["frame"], res["id"], res["boxes"])]) \
            if len(res["frame"]) else mc.make_rows(1, [], np.zeros((0, 4)))
        return rows, res["times"]


def scaling_scene(n: int, frames: int = 8, seed: int = 0) -> np.ndarray:
    """n targets spread over a square with room for them, constant velocities, jittered detections."""
    from aircraft_docking_tracker.io import motchallenge as mc  # noqa: PLC0415

    rng = np.random.default_rng(seed)
    side = 60.0 * np.sqrt(n) + 200
    pos = rng.uniform(0, side, (n, 2))
    vel = rng.normal(0, 1.0, (n, 2))
    rows = []
    for k in range(1, frames + 1):
        centre = pos + k * vel + rng.normal(0, 0.5, (n, 2))
        rows.append(mc.make_rows(k, -np.ones(n), np.concatenate([centre - 10, np.full((n, 2), 20.0)], 1),
                                 np.full(n, 0.9)))
    return np.concatenate(rows)


def scaling(variant_list: dict, python: Path | None, quick: bool) -> dict:
    """Milliseconds per frame (median of the last frames) against the number of targets."""
    from multi_target_tracker.association import MultiTargetTracker  # noqa: PLC0415
    from aircraft_docking_tracker.io import motchallenge as mc  # noqa: PLC0415

    frames = 6 if quick else 10
    out: dict = {}
    for n in SCALING_TARGETS:
        det = scaling_scene(n, frames)
        for name in ("seed (§3 as written)", OURS):
            v = variant_list[name]
            tracker = MultiTargetTracker(v["config"], v["kalman"])
            times = []
            for k, rows in mc.frames(det, 1, frames):
                t0 = time.perf_counter()
                tracker.step(k / 25.0, mc.boxes(rows), rows["score"])
                times.append(time.perf_counter() - t0)
            out.setdefault(name, {})[n] = 1e3 * float(np.median(times[2:]))
        if python is not None:
            for peer in PEERS:
                if peer == "motpy" and n > 100:
                    continue                                  # pure-Python per-track loops: minutes at 1000
                _, times = run_peer(python, peer, det, 25.0, frames)
                out.setdefault(peer, {})[n] = 1e3 * float(np.median(times[2:]))
    return out


def speed_duel(seq: dict, python: Path | None, rounds: int) -> dict:
    """Frames/s of our default and the SORT-family peers, timed in alternation ``rounds`` times.

    The machine is shared, so each tracker's best round is kept and the trackers take turns, so
    that a busy spell hits them alike; every one runs in a fresh worker process of the same shape
    (ours in our venv), timed around its per-frame call. Returns name -> frames/s.
    """
    best: dict[str, float] = {}
    repeats = max(1, 400 // seq["n_frames"])            # short sequences: several runs per turn, fastest kept
    for _ in range(rounds):
        for peer in [OURS] + ([] if python is None else SORT_FAMILY):
            _, times = run_peer(python, peer, seq["det"], seq["fps"], seq["n_frames"], repeats)
            best[peer] = max(best.get(peer, 0.0), seq["n_frames"] / float(times.sum()))
    return best


#: Spread over random scenes: hard scenes with long hides, seeds used nowhere else (not in the choice of defaults).
SPREAD_SEEDS = (21, 22, 23, 24, 25)
SPREAD_PEERS = ["SORT (trackers)", "ByteTrack (trackers)", "BoT-SORT (trackers, no CMC)"]


def seed_spread(python: Path | None, quick: bool) -> dict:
    """HOTA, MOTA, re-acquisitions of our default and the strongest peers over fresh UAV scenes."""
    seqs = synthetic_uav(quick, [(f"seed {k}", 2, k, 170) for k in (SPREAD_SEEDS[:2] if quick else SPREAD_SEEDS)])
    ours = variants()
    out: dict = {}
    for seq_name, seq in seqs.items():
        for name in [OURS] + (SPREAD_PEERS if python is not None else []):
            if name == OURS:
                rows, seconds = run_ours(seq, ours[OURS])
            else:
                rows, times = run_peer(python, name, seq["det"], seq["fps"], seq["n_frames"])
                seconds = float(times.sum())
            out.setdefault(name, {})[seq_name] = metrics_row(seq["gt"], rows, seconds, seq["n_frames"])
    return out


LONG_HIDE = 25     # frames (1 s at 25 frames/s): a gap in a target's annotation this long counts as a hide


def metrics_row(gt, rows, seconds, n_frames) -> dict:
    from aircraft_docking_tracker.evaluation.mot_metrics import evaluator_of_rows, reacquisitions  # noqa: PLC0415

    evaluator = evaluator_of_rows(gt, rows)
    s = evaluator.result()
    hides, kept = reacquisitions(evaluator.accumulator, LONG_HIDE)
    cont = [c.longest_continuous / max(c.frames_present, 1) for c in s.continuity]
    return dict(hota=100 * s.hota, deta=100 * s.deta, assa=100 * s.assa, mota=100 * s.mota, idf1=100 * s.idf1, motp=100 * s.motp, idsw=s.num_switches,
                frag=s.num_fragmentations, mt=s.mostly_tracked, ml=s.mostly_lost, fp=s.num_false_positives,
                fn=s.num_misses, gt_targets=s.num_unique_objects, fps=n_frames / max(seconds, 1e-9),
                continuity=100 * float(np.mean(cont)) if cont else float("nan"), hides=hides, reacquired=kept)


def summary(results: dict, names: list[str]) -> dict:
    """Per tracker: mean and worst over the sequences, and the HOTA gap to the best peer per sequence."""
    seqs = list(results)
    best_peer = {s: max((results[s][p]["hota"] for p in PEERS if p in results[s]), default=float("nan"))
                 for s in seqs}
    out = {}
    for name in names:
        rows = [results[s][name] for s in seqs if name in results[s]]
        gaps = [results[s][name]["hota"] - best_peer[s] for s in seqs if name in results[s]]
        out[name] = dict(hota=float(np.mean([r["hota"] for r in rows])), mota=float(np.mean([r["mota"] for r in rows])),
                         idf1=float(np.mean([r["idf1"] for r in rows])),
                         worst_hota=float(min(r["hota"] for r in rows)), worst_mota=float(min(r["mota"] for r in rows)),
                         worst_gap=float(min(gaps)) if gaps else float("nan"))
    return out


def _best_peer(results: dict, seq: str, metric: str) -> float:
    """The best peer's score on ``seq`` (NaN when no peer ran)."""
    return max((results[seq][p][metric] for p in PEERS if p in results[seq]), default=float("nan"))


def _knobs(chosen: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in chosen.items())


def _held_out_cells(seq: str, r: dict) -> str:
    """The first cells of a held-out row: sequence, HOTA, MOTA, IDF1 (ends with '|')."""
    return f"| {seq} | {r['hota']:.1f} | {r['mota']:.1f} | {r['idf1']:.1f} |"


def _mean_worst_row(held_out: dict) -> str:
    h = [r["hota"] for r in held_out.values()]
    m = [r["mota"] for r in held_out.values()]
    return f"| **mean / worst** | {np.mean(h):.1f} / {min(h):.1f} | {np.mean(m):.1f} / {min(m):.1f} | | | | |"


def write_markdown(path: Path, results: dict, scale: dict, meta: dict, speed: dict, loso: dict | None = None,
                   spread: dict | None = None) -> None:
    lines = ["# Association benchmark (issues 6, 13)", "",
             f"Run {meta['date']} on {meta['machine']}; {'quick' if meta['quick'] else 'full'} mode. Every tracker "
             "gets the same prepared detections (TUD-Campus at 25 frames/s; airport-2 cut at score "
             f"{AIRPORT_MIN_SCORE}; synthetic UAV scenes). HOTA, DetA, AssA (TrackEval's algorithm, "
             "evaluation.mot_metrics), MOTA, IDF1, continuity in percent; continuity = seed 003 Fig. 4, mean over "
             "ground-truth targets of (longest run tracked under one id) / (frames present); fps = tracker alone, "
             "detections in memory. Peers at their documented defaults; 'SORT (abewley)' is PyPI sort-track 0.0.8, "
             "abewley/sort's sort.py packaged (max_age 1, min_hits 3, IoU 0.3); BoT-SORT without camera-motion "
             "compensation (no images).", ""]
    names = list(next(iter(results.values())))
    summ = summary(results, names)
    lines += ["## Summary over the sequences", "",
              "gap = HOTA minus the best peer's HOTA on that sequence; worst = the lowest over the sequences.", "",
              "| tracker | mean HOTA | mean MOTA | mean IDF1 | worst HOTA | worst MOTA | worst gap to best peer |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in summ.items():
        lines.append(f"| {name} | {r['hota']:.1f} | {r['mota']:.1f} | {r['idf1']:.1f} | {r['worst_hota']:.1f} | "
                     f"{r['worst_mota']:.1f} | {r['worst_gap']:+.1f} |")
    lines.append("")
    if loso:
        lines += ["## Defaults by leave-one-sequence-out (held-out scores)", "",
                  "For each sequence, the grid point best on the other sequences (mean HOTA + mean MOTA) is scored on "
                  "the held-out one. Grid: " + ", ".join(f"{k} {v}" for k, v in loso["grid"].items()) + ".", "",
                  "| held-out sequence | HOTA | MOTA | IDF1 | best peer HOTA | best peer MOTA | chosen on the others |",
                  "|---|---:|---:|---:|---:|---:|---|"]
        for seq, r in loso["held_out"].items():
            lines.append(f"{_held_out_cells(seq, r)} {_best_peer(results, seq, 'hota'):.1f} | "
                         f"{_best_peer(results, seq, 'mota'):.1f} | {_knobs(loso['chosen'][seq])} |")
        lines += [_mean_worst_row(loso["held_out"]),
                  "", "Chosen on all sequences (the defaults): " + _knobs(loso["all_sequences"]) + ".", ""]
        if loso.get("held_out_domain"):
            lines += ["Stricter: leave one *domain* out (TUD-Campus; airport-2; all three synthetic UAV scenes at "
                      "once), chosen on the other domains:", "",
                      "| held-out sequence | HOTA | MOTA | IDF1 | best peer HOTA | gap | chosen on the other domains |",
                      "|---|---:|---:|---:|---:|---:|---|"]
            for seq, r in loso["held_out_domain"].items():
                bh = _best_peer(results, seq, "hota")
                domain = "synthetic UAV" if seq.startswith("uav") else seq
                lines.append(f"{_held_out_cells(seq, r)} {bh:.1f} | {r['hota'] - bh:+.1f} | "
                             f"{_knobs(loso['chosen_domain'][domain])} |")
            lines += [_mean_worst_row(loso["held_out_domain"]), ""]
    if spread:
        seeds = ", ".join(next(iter(spread.values())))
        lines += [f"## Spread over fresh UAV scenes (difficulty 2, hides up to 170 frames; {seeds})",
                  "", "Scenes used nowhere else. Mean ± standard deviation over the seeds, and the worst seed.", "",
                  "| tracker | HOTA | worst HOTA | MOTA | worst MOTA | IDSW (sum) | re-acquired after long hides |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for name, by_seed in spread.items():
            h = np.array([r["hota"] for r in by_seed.values()])
            m = np.array([r["mota"] for r in by_seed.values()])
            lines.append(f"| {name} | {h.mean():.1f} ± {h.std():.1f} | {h.min():.1f} | {m.mean():.1f} ± {m.std():.1f} | "
                         f"{m.min():.1f} | {sum(r['idsw'] for r in by_seed.values())} | "
                         f"{sum(r['reacquired'] for r in by_seed.values())}/{sum(r['hides'] for r in by_seed.values())} |")
        lines.append("")
    checks = {s: r[OURS]["trackeval"] for s, r in results.items() if "trackeval" in r.get(OURS, {})}
    if checks:
        lines += ["HOTA port check, ours (default): " + "; ".join(
            f"{s} {results[s][OURS]['hota']:.3f} (TrackEval {c['hota']:.3f})" for s, c in checks.items()) + ".", ""]
    for seq, rows in results.items():
        lines += [f"## {seq}", "", f"Source: {meta['sources'][seq]}", "",
                  "| tracker | HOTA | DetA | AssA | MOTA | IDF1 | IDSW | MT | ML | FP | FN | continuity | "
                  f"re-acquired after ≥ {LONG_HIDE}-frame hides | frames/s |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for name, r in rows.items():
            lines.append(f"| {name} | {r['hota']:.1f} | {r['deta']:.1f} | {r['assa']:.1f} | {r['mota']:.1f} | "
                         f"{r['idf1']:.1f} | {r['idsw']} | {r['mt']} | {r['ml']} | "
                         f"{r['fp']} | {r['fn']} | {r['continuity']:.1f} | {r['reacquired']}/{r['hides']} | {r['fps']:.0f} |")
        lines.append("")
    lines += ["## Frames/s, SORT family, timed in alternation (best of the rounds)", "",
              "| sequence | " + " | ".join(next(iter(speed.values()), {})) + " |",
              "|---|" + "---:|" * len(next(iter(speed.values()), {}))]
    for seq, by_name in speed.items():
        lines.append(f"| {seq} | " + " | ".join(f"{v:.0f}" for v in by_name.values()) + " |")
    lines += ["", "## Cost of one frame against the number of targets (ms, as many detections as targets)", "",
              "| tracker | " + " | ".join(str(n) for n in SCALING_TARGETS) + " |",
              "|---|" + "---:|" * len(SCALING_TARGETS)]
    for name, by_n in scale.items():
        lines.append(f"| {name} | " + " | ".join(f"{by_n[n]:.2f}" if n in by_n else "–" for n in SCALING_TARGETS) + " |")
    lines.append("")
    path.write_text("\n".join(lines))


#: Our rows in the accuracy plot (beside every peer): the default and each issue-13 choice undone.
PLOTTED = [OURS, "+ second pass (issue-6 default)", "default, coasting always published",
           "default, collapsing covariance", "default, no first-frame activation"]


def plot(results: dict, scale: dict) -> None:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from aircraft_docking_tracker.evaluation.plots import grouped_bars  # noqa: PLC0415

    plots = HERE / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    seqs = list(results)
    names = [n for n in PLOTTED + PEERS if n in next(iter(results.values()))]
    fig, axes = plt.subplots(1, 2, figsize=(18, 5), sharey=False)
    colors = plt.cm.tab20(np.linspace(0, 1, 20))
    for ax, key in zip(axes, ("hota", "mota")):
        grouped_bars(ax, seqs, {name: [results[s].get(name, {}).get(key, np.nan) for s in seqs] for name in names},
                     colors)
        ax.set_title({"hota": "HOTA", "mota": "MOTA (clipped at -20)"}[key])
        ax.set_ylim(-20 if key == "mota" else 0, 100)
        ax.axhline(0, color="k", lw=0.5)
    axes[1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(plots / "association_accuracy.png", dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for name, by_n in scale.items():
        ns = sorted(by_n)
        ax.loglog(ns, [by_n[n] for n in ns], "o-", label=name)
    ax.axhline(50, color="r", ls="--", lw=0.8, label="50 ms")
    ax.set_xlabel("targets (= detections) per frame")
    ax.set_ylabel("ms per frame")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(plots / "association_scaling.png", dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="shorter synthetic scenes and scaling runs (~1-2 min)")
    parser.add_argument("--no-peers", action="store_true", help="skip the PyPI peers")
    parser.add_argument("--no-loso", action="store_true", help="skip the leave-one-sequence-out grid (~5 min)")
    parser.add_argument("--peer-worker", nargs=2, metavar=("IN", "OUT"), help=argparse.SUPPRESS)
    parser.add_argument("--hota-worker", nargs=2, metavar=("IN", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.peer_worker:
        peer_worker(*args.peer_worker)
        return 0
    if args.hota_worker:
        hota_worker(*args.hota_worker)
        return 0
    sys.path.insert(0, str(REPO))
    from tqdm import tqdm  # noqa: PLC0415

    seqs = load_sequences(args.quick)
    ours = variants()
    python = None if args.no_peers else ensure_peer_venv()
    results: dict = {}
    repeats = 1 if args.quick else REPEATS
    jobs = [(s, n) for s in seqs for n in ours] + ([(s, p) for s in seqs for p in PEERS] if python else [])
    for seq_name, name in tqdm(jobs, desc="association bench", unit="run"):
        seq = seqs[seq_name]
        if name in ours:
            rows, seconds = run_ours(seq, ours[name], repeats)
        else:
            rows, times = run_peer(python, name, seq["det"], seq["fps"], seq["n_frames"], repeats)
            seconds = float(times.sum())
        results.setdefault(seq_name, {})[name] = metrics_row(seq["gt"], rows, seconds, seq["n_frames"])
        if python is not None and name == OURS:            # our HOTA port against TrackEval's own code
            results[seq_name][name]["trackeval"] = trackeval_hota(python, seq["gt"], rows, seq["n_frames"])
    loso = None if args.no_loso or args.quick else leave_one_sequence_out(seqs)
    spread = seed_spread(python, args.quick)
    scale = scaling(ours, python, args.quick)
    speed = {name: speed_duel(seqs[name], python, 2 if args.quick else 5)
             for name in ("TUD-Campus", "airport-2") if name in seqs}
    meta = dict(date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), machine=f"{os.cpu_count()} cores",
                quick=args.quick, sources={k: v["source"] for k, v in seqs.items()},
                variants={k: dict(config=vars(v["config"]), kalman=vars(v["kalman"]), coasting=v["coasting"],
                                  backfill=v["backfill"]) for k, v in ours.items()})
    out = HERE / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "association.json").write_text(json.dumps(dict(meta=meta, sequences=results, scaling_ms=scale,
                                                           frames_per_s_duel=speed, leave_one_sequence_out=loso,
                                                           seed_spread=spread),
                                                      indent=1, default=str))
    write_markdown(out / "association.md", results, scale, meta, speed, loso, spread)
    plot(results, scale)
    print((out / "association.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
