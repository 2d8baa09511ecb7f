"""Benchmark of the docking tracker (issue 4): ISPF, the plain PF and OpenCV's trackers, side by side.

    python bench/docking.py [--quick] [--no-peers]

In one run, on the same frames, one core (BLAS, OpenMP and OpenCV threads set to 1):

* sequences: OTB Car4, Car1 and TinyTLP CarChase2 (``../shared/data/sot``) and synthetic docking
  scenes (``aircraft_docking_tracker.scenarios.docking``: an aircraft taxiing onto its stand,
  growing 4-6x and turning) at 640x480 and 1280x720;
* trackers: ISPF (the defaults), two ablations (self-tuning of all six directions as Li et al.; the
  seed's own update rule ``Ŝ > μ_B + σ_B``), the plain particle filter with the same observation
  model at fixed counts, OpenCV's ``TrackerMIL`` (main cv2), and ``TrackerCSRT`` / ``TrackerKCF``
  from ``opencv-contrib-python-headless`` run in their own venv ``bench/.venv-contrib`` (the two
  OpenCV wheels cannot share one environment);
* measures: OTB success AUC and precision at 20 px of the axis-aligned boxes against the
  axis-aligned ground truth (``evaluation.sot_metrics``; for the synthetic scenes also the polygon
  IoU AUC of our quadrilaterals against the true ones), frames/s of the tracker alone (reading and
  decoding frames excluded, for every tracker alike), particles per frame (mean, max).

Writes ``bench/results/docking.json`` and ``.md`` and ``bench/plots/docking_*.png``. The same file,
run with ``--peer-worker IN OUT`` by the contrib venv, runs one OpenCV tracker (numpy + cv2 only).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
CONTRIB_VENV = HERE / ".venv-contrib"
CONTRIB_PACKAGES = ["numpy", "opencv-contrib-python-headless<5"]
CONTRIB_PEERS = ("CSRT", "KCF")


# ================================================================================================
# OpenCV trackers (also the peer worker, inside bench/.venv-contrib: numpy + cv2 only)
# ================================================================================================
def run_opencv_tracker(name: str, files: list[str], init: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (N, 4) and per-frame update seconds of OpenCV's tracker ``name`` (MIL, CSRT, KCF).

    A frame the tracker reports as failed keeps its last box (OTB's protocol: one box per frame).
    """
    cv2.setNumThreads(1)
    tracker = getattr(cv2, f"Tracker{name}").create()
    box = tuple(int(round(v)) for v in init)
    boxes, times = [list(init)], [0.0]
    tracker.init(cv2.imread(files[0], cv2.IMREAD_COLOR), box)
    last = list(init)
    for path in files[1:]:
        frame = cv2.imread(path, cv2.IMREAD_COLOR)
        t0 = time.perf_counter()
        ok, found = tracker.update(frame)
        times.append(time.perf_counter() - t0)
        if ok:
            last = [float(v) for v in found]
        boxes.append(last)
    return np.array(boxes, dtype=np.float64), np.array(times)


def peer_worker(in_path: str, out_path: str) -> None:
    job = json.loads(Path(in_path).read_text())
    boxes, times = run_opencv_tracker(job["tracker"], job["files"], job["init"])
    np.savez(out_path, boxes=boxes, times=times)


# ================================================================================================
# Sequences
# ================================================================================================
def real_sequences(data: Path, max_frames: int | None) -> list[dict]:
    from aircraft_docking_tracker.scenarios.datasets import list_frames, read_sot_boxes  # noqa: PLC0415

    out = []
    for name in ("Car4", "Car1", "CarChase2"):
        folder = data / "sot" / name
        if not folder.is_dir():
            print(f"bench/docking: {folder} absent, skipped", file=sys.stderr)
            continue
        files = [str(p) for p in list_frames(folder)][:max_frames]
        gt = read_sot_boxes(folder / "groundtruth_rect.txt")[0][:len(files)]
        h, w = cv2.imread(files[0], cv2.IMREAD_GRAYSCALE).shape
        out.append({"name": name, "files": files, "gt_boxes": gt, "gt_quads": None, "size": [w, h]})
    return out


def docking_sequences(tmp: Path, specs: list[tuple[int, int, int, int]]) -> list[dict]:
    """Render synthetic docking scenes (seed, width, height, frames) to PNG files once."""
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: PLC0415

    out = []
    for seed, width, height, frames in specs:
        scene = DockingScene(DockingSceneConfig(width=width, height=height, frames=frames), seed=seed)
        folder = tmp / f"docking{seed}_{width}x{height}"
        folder.mkdir(parents=True, exist_ok=True)
        files, quads = [], []
        for frame in scene.frames():
            path = folder / f"{frame.index:05d}.png"
            cv2.imwrite(str(path), frame.image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
            files.append(str(path))
            quads.append(frame.quad)
        quads = np.array(quads, dtype=np.float64)
        lo, hi = quads.min(axis=1), quads.max(axis=1)
        out.append({"name": f"docking seed {seed} {width}x{height}", "files": files,
                    "gt_boxes": np.concatenate([lo, hi - lo], axis=1), "gt_quads": quads, "size": [width, height]})
    return out


# ================================================================================================
# Trackers
# ================================================================================================
def ours(label: str, **overrides):
    return {"label": label, "kind": "ours", "overrides": overrides}


def run_ours(seq: dict, overrides: dict, seed: int = 0) -> dict:
    from aircraft_docking_tracker.docking import DockingConfig  # noqa: PLC0415
    from aircraft_docking_tracker.sot_track import track  # noqa: PLC0415

    config = DockingConfig(**overrides, seed=seed)
    init = seq["gt_quads"][0] if seq["gt_quads"] is not None else seq["gt_boxes"][0]
    frames = (cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in seq["files"])
    run = track(frames, init, config, len(seq["files"]), progress=False)
    return {"boxes": run.boxes, "quads": run.quads, "times": run.step_seconds, "particles": run.particles}


def run_peer(seq: dict, name: str, tmp: Path) -> dict | None:
    init = [float(v) for v in seq["gt_boxes"][0]]
    if name == "MIL":
        boxes, times = run_opencv_tracker("MIL", seq["files"], init)
        return {"boxes": boxes, "times": times}
    python = CONTRIB_VENV / "bin" / "python"
    if not python.exists():
        return None
    job, result = tmp / f"job_{name}.json", tmp / f"result_{name}.npz"
    job.write_text(json.dumps({"tracker": name, "files": seq["files"], "init": init}))
    proc = subprocess.run([str(python), __file__, "--peer-worker", str(job), str(result)],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ""})
    if proc.returncode != 0:
        print(f"bench/docking: {name} failed: {proc.stderr[-500:]}", file=sys.stderr)
        return None
    with np.load(result, allow_pickle=False) as data:
        return {"boxes": data["boxes"], "times": data["times"]}


def ensure_contrib_venv() -> bool:
    python = CONTRIB_VENV / "bin" / "python"
    if python.exists():
        return True
    print("bench/docking: creating bench/.venv-contrib (opencv-contrib-python-headless) ...", file=sys.stderr)
    try:
        subprocess.run(["python3", "-m", "venv", str(CONTRIB_VENV)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", *CONTRIB_PACKAGES], check=True)
    except (subprocess.CalledProcessError, OSError) as exc:
        print(f"bench/docking: no contrib venv ({exc}); CSRT and KCF skipped", file=sys.stderr)
        return False
    return True


# ================================================================================================
# The run
# ================================================================================================
def score(seq: dict, out: dict) -> dict:
    from aircraft_docking_tracker.evaluation.sot_metrics import score_sequence  # noqa: PLC0415
    from aircraft_docking_tracker.evaluation.speed import fps  # noqa: PLC0415

    s = score_sequence(out["boxes"], seq["gt_boxes"])
    row = {"success_auc": s["success_auc"], "precision": s["precision"], "fps": fps(out["times"][1:]),
           "success_curve": s["success_curve"], "frames": len(out["boxes"])}
    if "particles" in out:
        row["particles_mean"] = float(np.mean(out["particles"][1:]))
        row["particles_max"] = int(np.max(out["particles"][1:]))
    if "quads" in out and seq["gt_quads"] is not None:
        row["quad_success_auc"] = score_sequence(out["quads"], seq["gt_quads"])["success_auc"]
    return row


def score_seeds(seq: dict, overrides: dict, seeds: int) -> dict:
    """Our tracker over ``seeds`` random seeds: mean scores, the AUC's spread and each seed's AUC."""
    rows = [score(seq, run_ours(seq, overrides, seed)) for seed in range(seeds)]
    row = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k not in ("success_curve", "particles_max")}
    row["particles_max"] = int(max(r["particles_max"] for r in rows))
    row["frames"] = rows[0]["frames"]
    row["success_curve"] = np.mean([r["success_curve"] for r in rows], axis=0).tolist()
    row["success_auc_std"] = float(np.std([r["success_auc"] for r in rows]))
    row["success_auc_seeds"] = [r["success_auc"] for r in rows]
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="first 100 frames of each sequence, fewer trackers")
    parser.add_argument("--no-peers", action="store_true", help="skip CSRT/KCF (no contrib venv)")
    parser.add_argument("--seeds", type=int, default=None, help="random seeds per particle filter (default 3, quick 1)")
    parser.add_argument("--data", type=Path, default=Path(os.environ.get("ADT_SHARED_DATA", REPO.parent / "shared" / "data")))
    parser.add_argument("--peer-worker", nargs=2, metavar=("IN", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.peer_worker:
        peer_worker(*args.peer_worker)
        return 0
    sys.path.insert(0, str(REPO))
    cv2.setNumThreads(1)
    quick = args.quick
    seeds = args.seeds or (1 if quick else 3)
    trackers = [ours("ISPF"), ours("PF 100", method="pf", pf_particles=100), ours("PF 300", method="pf", pf_particles=300)]
    if not quick:
        trackers += [ours("PF 600", method="pf", pf_particles=600),
                     ours("ISPF, tune all 6 (Li et al.)", tune_dims="all"),
                     ours("ISPF, seed update rule", update_rule="background")]
    peers = ["MIL"] + ([] if args.no_peers or not ensure_contrib_venv() else list(CONTRIB_PEERS))
    labels = [t["label"] for t in trackers] + peers
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench_docking_") as tmp_name:
        tmp = Path(tmp_name)
        n = 100 if quick else None
        sequences = real_sequences(args.data, n)
        sequences += docking_sequences(tmp, [(0, 640, 480, 100 if quick else 300)] + (
            [] if quick else [(1, 640, 480, 300)]) + [(2, 1280, 720, 60 if quick else 200)])
        for seq in sequences:
            results[seq["name"]] = {"size": seq["size"], "trackers": {}}
            for tr in trackers:
                row = score_seeds(seq, tr["overrides"], seeds)
                results[seq["name"]]["trackers"][tr["label"]] = row
                print(f"{seq['name']:28s} {tr['label']:30s} AUC {row['success_auc']:.3f}±{row['success_auc_std']:.3f} "
                      f"P@20 {row['precision']:.3f} {row['fps']:7.1f} fps  particles {row.get('particles_mean', 0):.0f}",
                      flush=True)
            for name in peers:
                out = run_peer(seq, name, tmp)
                if out is None:
                    continue
                row = score(seq, out)
                results[seq["name"]]["trackers"][name] = row
                print(f"{seq['name']:28s} {name:30s} AUC {row['success_auc']:.3f} P@20 {row['precision']:.3f} "
                      f"{row['fps']:7.1f} fps", flush=True)
    summary = summarise(results, labels)
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "plots").mkdir(exist_ok=True)
    payload = {"quick": quick, "threads": 1, "seeds": seeds, "summary": summary, "sequences": results,
               "machine": {"cpus": os.cpu_count()}, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    (HERE / "results" / "docking.json").write_text(json.dumps(payload, indent=1))
    (HERE / "results" / "docking.md").write_text(markdown(results, summary, labels, quick, seeds))
    plot(results, labels)
    print((HERE / "results" / "docking.md").read_text())
    return 0


def summarise(results: dict, labels: list[str]) -> dict:
    """Mean AUC / P@20 over sequences, fps per resolution, and the issue's ratios."""
    out: dict = {"mean": {}}
    for label in labels:
        rows = [seq["trackers"][label] for seq in results.values() if label in seq["trackers"]]
        if rows:
            out["mean"][label] = {"success_auc": float(np.mean([r["success_auc"] for r in rows])),
                                  "precision": float(np.mean([r["precision"] for r in rows])),
                                  "fps": float(np.mean([r["fps"] for r in rows])), "sequences": len(rows)}
    ratios = {}
    for name, seq in results.items():
        t = seq["trackers"]
        entry = {}
        for pf in ("PF 100", "PF 300", "PF 600"):
            if pf in t and "ISPF" in t:
                entry[f"ISPF AUC - {pf} AUC"] = t["ISPF"]["success_auc"] - t[pf]["success_auc"]
                entry[f"ISPF particles / {pf}"] = t["ISPF"]["particles_mean"] / t[pf]["particles_mean"]
        if "CSRT" in t and "ISPF" in t:
            entry["ISPF fps / CSRT fps"] = t["ISPF"]["fps"] / t["CSRT"]["fps"]
        ratios[name] = entry
    out["ratios"] = ratios
    if "CSRT" in out["mean"] and "ISPF" in out["mean"]:
        common = [s for s in results.values() if "CSRT" in s["trackers"]]
        out["ISPF vs CSRT"] = {
            "mean AUC ISPF": float(np.mean([s["trackers"]["ISPF"]["success_auc"] for s in common])),
            "mean AUC CSRT": float(np.mean([s["trackers"]["CSRT"]["success_auc"] for s in common])),
            "fps ratio (per-sequence mean)": float(np.mean([s["trackers"]["ISPF"]["fps"] / s["trackers"]["CSRT"]["fps"]
                                                            for s in common]))}
    return out


def markdown(results: dict, summary: dict, labels: list[str], quick: bool, seeds: int) -> str:
    lines = ["## Docking tracker (issue 4): ISPF vs plain PF vs OpenCV trackers", "",
             f"{'Quick run (first 100 frames of each real sequence, short synthetic scenes).' if quick else 'Full run.'} "
             "One core for every tracker (BLAS/OpenMP/OpenCV threads = 1); frames/s of the tracker's update "
             "alone (frame decoding excluded for all). Success AUC and precision at 20 px: axis-aligned boxes "
             "against axis-aligned ground truth (OTB protocol); 'quad AUC': our quadrilaterals against the "
             "true ones (polygon IoU, synthetic scenes). Particles: per frame, mean / max. "
             f"Our filters: mean over {seeds} random seed(s), ± the AUC's standard deviation across seeds; "
             "OpenCV's trackers are deterministic.", ""]
    lines += ["| sequence | size | tracker | success AUC | P@20 | frames/s | particles mean / max | quad AUC |",
              "|---|---|---|---:|---:|---:|---:|---:|"]
    for name, seq in results.items():
        for label in labels:
            r = seq["trackers"].get(label)
            if r is None:
                continue
            parts = f"{r['particles_mean']:.0f} / {r['particles_max']}" if "particles_mean" in r else ""
            quad = f"{r['quad_success_auc']:.3f}" if "quad_success_auc" in r else ""
            spread = f" ± {r['success_auc_std']:.3f}" if "success_auc_std" in r else ""
            lines.append(f"| {name} | {seq['size'][0]}x{seq['size'][1]} | {label} | {r['success_auc']:.3f}{spread} | "
                         f"{r['precision']:.3f} | {r['fps']:.1f} | {parts} | {quad} |")
    lines += ["", "Mean over the sequences each tracker ran on:", "",
              "| tracker | mean success AUC | mean P@20 | mean frames/s | sequences |", "|---|---:|---:|---:|---:|"]
    for label, m in summary["mean"].items():
        lines.append(f"| {label} | {m['success_auc']:.3f} | {m['precision']:.3f} | {m['fps']:.1f} | {m['sequences']} |")
    lines += ["", "Ratios per sequence (the issue's targets: ISPF AUC >= PF AUC with <= 1/4 of its particles; "
              "ISPF >= 2x CSRT's frames/s):", "", "| sequence | ratio | value |", "|---|---|---:|"]
    for name, entry in summary["ratios"].items():
        for k, v in entry.items():
            lines.append(f"| {name} | {k} | {v:+.3f} |" if "AUC -" in k else f"| {name} | {k} | {v:.2f} |")
    if "ISPF vs CSRT" in summary:
        c = summary["ISPF vs CSRT"]
        lines += ["", f"ISPF vs CSRT over the same sequences: mean AUC {c['mean AUC ISPF']:.3f} vs "
                  f"{c['mean AUC CSRT']:.3f}; ISPF's frames/s / CSRT's (mean of per-sequence ratios) "
                  f"{c['fps ratio (per-sequence mean)']:.1f}x."]
    return "\n".join(lines) + "\n"


def plot(results: dict, labels: list[str]) -> None:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from aircraft_docking_tracker.evaluation.sot_metrics import SUCCESS_THRESHOLDS  # noqa: PLC0415
    from aircraft_docking_tracker.evaluation.plots import grouped_bars  # noqa: PLC0415

    names = list(results)
    cols = min(3, len(names))
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        for label in labels:
            r = results[name]["trackers"].get(label)
            if r is not None:
                ax.plot(SUCCESS_THRESHOLDS, r["success_curve"], label=f"{label} [{r['success_auc']:.3f}]")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("overlap threshold")
        ax.set_ylabel("success rate")
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=6, loc="lower left")
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(HERE / "plots" / "docking_success.png", dpi=90)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 4))
    grouped_bars(ax, names, {label: [results[n]["trackers"].get(label, {}).get("fps", 0.0) for n in names]
                             for label in labels}, rotation=20, fontsize=7, ha="right")
    ax.set_ylabel("frames/s (one core, tracker only)")
    ax.set_yscale("log")
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(HERE / "plots" / "docking_fps.png", dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
