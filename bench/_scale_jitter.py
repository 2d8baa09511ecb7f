"""Diagnosis, not a benchmark (the leading _ keeps it out of make bench; issue 11, helper fast10): where the log-scale error of the docking track comes from.

Per run and frame, log(scale / truth) of X̂ at each stage of step 7 (the best particle, the weighted
estimate, after the motion correction, after the extent correction = the output), the particles' spread
of log scale, the extent's measured log scale; per run its mean (bias), frame-to-frame difference (jitter),
and the slow wander (the error minus its 9-frame moving mean is the fast part).

    nice -n 10 python bench/_scale_jitter.py [--sets 150,60] [--count N] [--seeds S] [--set k=v ...]
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import docking as bd  # noqa: E402
from aircraft_docking_tracker.docking import affine_group as ag  # noqa: E402
from aircraft_docking_tracker.docking import ispf  # noqa: E402

LOG: dict = {}


def _logscale(x):
    return float(np.log(ag.to_params(np.asarray(x)[None])[0, 2]))


def instrument():
    cls = ispf.AffineParticleFilter
    orig_est, orig_mot, orig_ext, orig_finish = cls._estimate, cls._motion_correction, cls._extent_correction, cls._finish

    def _estimate(self, states, scores, patches):
        out = orig_est(self, states, scores, patches)
        best = states[int(np.argmax(scores))]
        ls = np.log(ag.to_params(states)[:, 2])
        order = np.argsort(-scores)[:self.config.top_k]
        LOG["cur"].update(best=_logscale(best), est=_logscale(out[0]), spread=float(ls.std()),
                          spread_top=float(ls[order].std()), n=len(states))
        return out

    def _motion(self, estimate):
        step = orig_mot(self, estimate)
        LOG["cur"]["motion"] = _logscale(estimate @ step)
        return step

    def _extent(self, estimate):
        step = orig_ext(self, estimate)
        if step is not None:
            g = self.config.extent_gain
            LOG["cur"]["extent_meas"] = _logscale(estimate) + (_logscale(estimate @ step) - _logscale(estimate)) / g
        return step

    def _finish(self, states, scores, patches):
        LOG["cur"] = {}
        m = self.background.motion
        if m is not None:
            LOG["cur"]["m_scale"] = 0.5 * float(np.log(abs(np.linalg.det(m[:2, :2]))))
        r = orig_finish(self, states, scores, patches)
        LOG["cur"]["final"] = _logscale(r.state)
        LOG["cur"]["counts"] = dict(self.extent_counts)
        LOG["frames"][LOG["idx"]] = LOG["cur"]
        return r

    cls._estimate, cls._motion_correction, cls._extent_correction, cls._finish = _estimate, _motion, _extent, _finish
    from aircraft_docking_tracker.docking import tracker as tr  # noqa: PLC0415
    orig_start, orig_step = tr.DockingTracker.start, tr.DockingTracker.step

    def start(self, frame, where):
        LOG["starts"].append(LOG["idx"])
        return orig_start(self, frame, where)

    def step(self, frame, detections=None):
        LOG["idx"] += 1
        return orig_step(self, frame, detections)

    tr.DockingTracker.start, tr.DockingTracker.step = start, step


def run(seq, overrides, seed, start):
    LOG["frames"], LOG["starts"], LOG["idx"] = {}, [], 0
    out = bd.run_ours(seq, overrides, seed, start)
    frames = [LOG["frames"].get(i, {}) for i in range(len(seq["files"]))]
    return out, frames, LOG["starts"]


def analyse(seq, out, frames, starts):
    truth = np.log(ag.to_params(np.array([ag.from_quad(q) for q in seq["gt_quads"]]))[:, 2])
    ok = np.isfinite(out["quads"]).all(axis=(1, 2))
    est = np.full(len(truth), np.nan)
    est[ok] = np.log(ag.to_params(np.array([ag.from_quad(q) for q in out["quads"][ok]]))[:, 2])
    err = est - truth
    e = err[np.isfinite(err)]
    dd = np.diff(err)
    for i in starts:                # a restart is not jitter
        if 0 < i < len(err):
            dd[i - 1] = np.nan
    d = dd[np.isfinite(dd)]
    k = 9
    smooth = np.convolve(e, np.ones(k) / k, mode="same")
    fast = (e - smooth)[k:-k]
    res = {"restarts": len(starts) - 1, "absd": float(np.median(np.abs(d))), "bias": float(e.mean()), "abs_err": float(np.abs(e).mean()), "std": float(e.std()),
           "jitter": float(np.std(d)), "fast_std": float(fast.std()) if len(fast) else np.nan,
           "truth_step": float(np.std(np.diff(truth)))}
    # per-stage: frame-to-frame jitter of each stage's log scale relative to the truth
    n = len(truth)
    tr = truth
    for key in ("best", "est", "motion", "final", "extent_meas"):
        v = np.array([f.get(key, np.nan) for f in frames[:n]]) - tr
        m = np.isfinite(v)
        if m.sum() > 3:
            res[f"{key}_bias"] = float(np.nanmean(v))
            dv = np.diff(v)
            for i in starts:
                if 0 < i < len(dv) + 1:
                    dv[i - 1] = np.nan
            res[f"{key}_jit"] = float(np.nanstd(dv))   # diff over NaNs drops pairs
            res[f"{key}_absd"] = float(np.nanmedian(np.abs(dv)))
    res["spread"] = float(np.nanmean([f.get("spread", np.nan) for f in frames[:n]]))
    res["spread_top"] = float(np.nanmean([f.get("spread_top", np.nan) for f in frames[:n]]))
    res["extent_frac"] = float(np.mean([("extent_meas" in f) for f in frames[:n]]))
    # how much the final step changes the estimate's log scale, per frame
    res["est_to_final"] = float(np.nanmean(np.abs([f.get("final", np.nan) - f.get("est", np.nan) for f in frames[:n]])))
    return res


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--sets", default="150,60")
    p.add_argument("--count", type=int, default=0, help="scenes per set (0: all)")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--starts", default="box,polygon")
    p.add_argument("--set", nargs="*", default=[], help="overrides k=v (json values)")
    p.add_argument("--out", default="")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--min-move", type=float, default=0.0, help="experiment: target_motion's min_move (0: as is)")
    a = p.parse_args()
    overrides = {}
    for kv in a.set:
        k, v = kv.split("=", 1)
        try:
            overrides[k] = json.loads(v)
        except json.JSONDecodeError:
            overrides[k] = v
    instrument()
    if a.min_move > 0:
        import functools  # noqa: PLC0415
        from aircraft_docking_tracker.docking import static_background as sb  # noqa: PLC0415
        sb.target_motion = functools.partial(sb.target_motion, min_move=a.min_move)
    sets = {"150": (bd.TUNE_SEED0, 20, 150), "60": (bd.TUNE_FAST_SEED0, 10, bd.FAST_FRAMES)}
    rows = []
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="scale_jitter_") as tmp:
        for name in a.sets.split(","):
            seed0, count, frames = sets[name]
            for seq in bd.docking_sequences(Path(tmp), a.count or count, frames, seed0):
                for start in a.starts.split(","):
                    for s in range(a.seeds if start == "box" else 1):
                        out, fr, starts = run(seq, overrides, s, start)
                        auc = bd.score(seq, out)["success_auc"]
                        r = {"set": name, "scene": seq["name"].split()[1], "start": start, "seed": s, "auc": auc,
                             **analyse(seq, out, fr, starts)}
                        rows.append(r)
                        if not a.quiet:
                            print(f"{name} {r['scene']} {start[:3]} s{s} auc {auc:.3f} rs {r['restarts']} absd {r['absd']:.3f} bias {r['bias']:+.3f} "
                                  f"|e| {r['abs_err']:.3f} std {r['std']:.3f} jit {r['jitter']:.3f} fast {r['fast_std']:.3f} "
                                  f"| est_jit {r.get('est_jit', np.nan):.3f} mot_jit {r.get('motion_jit', np.nan):.3f} "
                                  f"fin_jit {r.get('final_jit', np.nan):.3f} ext_jit {r.get('extent_meas_jit', np.nan):.3f} "
                                  f"spread {r['spread']:.3f} ext {r['extent_frac']:.2f} [{time.time() - t0:.0f}s]", flush=True)
    summary(rows)
    if a.out:
        Path(a.out).write_text(json.dumps(rows, indent=0))


def summary(rows):
    for name in dict.fromkeys(r["set"] for r in rows):
        for start in dict.fromkeys(r["start"] for r in rows):
            rs = [r for r in rows if r["set"] == name and r["start"] == start]
            if not rs:
                continue
            auc = np.array([r["auc"] for r in rs])
            print(f"== {name} f {start}: n {len(rs)} >=0.5 {np.mean(auc >= 0.5):.0%} median {np.median(auc):.3f} "
                  f"mean {auc.mean():.3f} worst {auc.min():.3f}")
            keys = ["restarts", "absd", "est_absd", "best_absd", "final_absd", "bias", "abs_err", "std", "jitter", "fast_std", "truth_step", "spread", "spread_top", "extent_frac",
                    "best_jit", "est_jit", "motion_jit", "final_jit", "extent_meas_jit", "extent_meas_bias", "est_to_final"]
            print("   " + " ".join(f"{k}={np.nanmedian([r.get(k, np.nan) for r in rs]):.3f}" for k in keys))
            print(f"   |bias| median {np.median([abs(r['bias']) for r in rs]):.3f}")


if __name__ == "__main__":
    main()
