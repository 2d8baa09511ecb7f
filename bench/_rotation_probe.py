"""Diagnosis, not a benchmark (the leading _ keeps it out of make bench; issue 11, helper rot12): what each source
says about the docking track's rotation (and centre), frame by frame, against the truth.

Per frame of a tuning approach (150 frames, seeds 100+k), in the bench's live-like loop (stand rules, the cascade's
rows every frame), tracker seed 0: the truth's rotation, X̂'s, the best particle's and the top-k estimate's (step 7),
the shape prior's running axis, this frame's silhouette axis measured around X̂ and around the true state (with its
centre and sides in the true state's frame), the measured motion's rotation, and the appearance model's scores of
X̂, of X̂ turned about its centre to the truth's rotation, of X̂ moved to the truth's centre, of the true state and of
X̂ turned by -5 / +5 deg. Writes the JSON and prints, per run over phases 0.4-1.0, each source's median error.

    python bench/_rotation_probe.py K[,K...] polygon|box|detector ['{"learn_rotation": "silhouette"}'] [out.json]
"""
import json
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import docking as bd  # noqa: E402
from aircraft_docking_tracker.config import load_yaml_parameters, package_config_dir  # noqa: E402
from aircraft_docking_tracker.docking import affine_group as ag  # noqa: E402
from aircraft_docking_tracker.docking import ispf  # noqa: E402
from aircraft_docking_tracker.docking.static_background import foreground_extent, half_turn  # noqa: E402
from aircraft_docking_tracker.docking.tracker import DockingConfig  # noqa: E402
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: E402
from aircraft_docking_tracker.sot_track import track  # noqa: E402

STATE = {"i": 0, "truth": None}
LOG = []
_orig_estimate = ispf.AffineParticleFilter._estimate
_orig_finish = ispf.AffineParticleFilter._finish


def rot(X):
    return float(ag.to_params(X[None])[0, 4])


def _estimate(self, states, scores, patches):
    out = _orig_estimate(self, states, scores, patches)
    b = int(np.argmax(scores))
    self._probe = {"best": rot(states[b]), "topk": rot(out[0]), "n": len(states)}
    return out


def _finish(self, states, scores, patches):
    res = _orig_finish(self, states, scores, patches)
    i = STATE["i"]
    truth = STATE["truth"][i]
    pt = ag.to_params(truth[None])[0]
    est = res.state
    pe = ag.to_params(est[None])[0]
    rec = {"i": i, "truth": float(pt[4]), "est": float(pe[4]), **getattr(self, "_probe", {}),
           "prior": None if self._prior_rotation is None else float(self._prior_rotation),
           "score": res.score, "updated": res.updated}
    fg = self.background.foreground
    rec["still"] = bool(self.background.target_still) if fg is not None else None
    if fg is not None:
        for name, st in (("sil_est", est), ("sil_truth", truth)):
            ext = foreground_extent(fg, st, self.background.scale)
            if ext is None:
                ext = foreground_extent(fg, st, self.background.scale, extent=2.4)
            if ext is not None:
                u = float(np.arctan2(st[1, 0], st[0, 0]))
                t = half_turn(ext.axis_angle)
                if abs(t) > np.pi / 4:
                    t -= np.sign(t) * np.pi / 2
                rec[name] = u + t
                rec[name + "_el"] = float(ext.elongation)
                rec[name + "_plaus"] = bool(ispf._plausible(ext))
                rec[name + "_cv"], rec[name + "_cu"] = float(ext.centre_v), float(ext.centre_u)
                rec[name + "_h"], rec[name + "_w"] = float(ext.height), float(ext.width)
    # appearance preference: X̂ re-rotated to the truth's rotation, about its centre
    p2 = pe.copy()
    p2[4] = pt[4]
    cand = np.array([est, ag.from_params(p2[None])[0], truth])
    # also X̂ rotated by +-5 deg
    for d in (-5, 5):
        p3 = pe.copy()
        p3[4] += np.deg2rad(d)
        cand = np.concatenate([cand, ag.from_params(p3[None])])
    pc = pe.copy()
    pc[:2] = pt[:2]
    cand = np.concatenate([cand, ag.from_params(pc[None])])
    s, _ = self._score(cand)
    rec["s_est"], rec["s_rot"], rec["s_truth"], rec["s_m5"], rec["s_p5"], rec["s_cen"] = [float(v) for v in s]
    # the velocity's (measured motion) rotation
    M = self.background.motion if self.config.motion_gain > 0 else None
    rec["motion_rot"] = None if M is None else float(np.arctan2(M[1, 0], M[0, 0]))
    LOG.append(rec)
    return res


ispf.AffineParticleFilter._estimate = _estimate
ispf.AffineParticleFilter._finish = _finish


def main():
    ks = [int(v) for v in sys.argv[1].split(",")]
    start = sys.argv[2]
    overrides = json.loads(sys.argv[3]) if len(sys.argv) > 3 else {}
    out = sys.argv[4] if len(sys.argv) > 4 else f"rotation_probe_{start}.json"
    allrec = {}
    stand = load_yaml_parameters(package_config_dir() / "stand_camera.yaml", "docking_tracker")
    for k in ks:
        scene = DockingScene(DockingSceneConfig(width=640, height=480, frames=150, **bd.scene_options(k)), seed=100 + k)
        frames = list(scene.frames())
        quads = np.array([f.quad for f in frames])
        imgs = [f.image if f.image.ndim == 2 else cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY)
                for f in frames]
        STATE["truth"] = np.array([ag.from_quad(q) for q in quads])
        tables = [bd.detector().detect(im) for im in imgs]

        def gen():
            for i, im in enumerate(imgs):
                STATE["i"] = i
                yield im
        LOG.clear()
        config = DockingConfig(**{**stand, **overrides, "seed": 0})
        lo, hi = quads[0].min(0), quads[0].max(0)
        init = quads[0] if start == "polygon" else np.r_[lo, hi - lo] if start == "box" else None
        run = track(gen(), init, config, len(imgs), progress=False, detections=tables)
        errs = bd.frame_errors(run.quads, quads)
        allrec[k] = {"log": list(LOG), "iou": errs["iou"].tolist(), "dv": np.nan_to_num(errs["dv"]).tolist()}
        print(k, "mean IoU", errs["iou"].mean(), flush=True)
    with open(out, "w") as fh:
        json.dump(allrec, fh)
    summary(allrec)


def err(a, t):
    """Signed rotation error [deg] of angle a against t, modulo 180 deg (NaN when not measured)."""
    return np.nan if a is None else float(np.rad2deg((a - t + np.pi / 2) % np.pi - np.pi / 2))


def summary(runs: dict) -> None:
    """Per run, phases 0.4-1.0: median signed (|abs|) error of each source, median scores, mean IoU, median dv."""
    keys = ("est", "best", "prior", "sil_est", "sil_truth")
    print("scene | " + " ".join(keys) + " [deg, signed (abs)] | s_est s_rot s_truth s_cen | mean IoU, dv")
    for k, r in runs.items():
        late = [x for x in r["log"] if x["i"] >= 0.4 * len(r["iou"])]
        cells = []
        for key in keys:
            e = np.array([err(x.get(key), x["truth"]) for x in late], float)
            cells.append(f"{np.nanmedian(e):+5.1f}({np.nanmedian(np.abs(e)):4.1f})" if np.isfinite(e).any() else "  -  ")
        scores = " ".join(f"{np.median([x[s] for x in late]):.3f}" for s in ("s_est", "s_rot", "s_truth", "s_cen"))
        n0 = int(0.4 * len(r["iou"]))
        print(f"{100 + int(k)} | " + " ".join(cells) + f" | {scores} | {np.mean(r['iou'][n0:]):.3f}, "
              f"{np.median(r['dv'][n0:]):+.3f}")


if __name__ == "__main__":
    main()
