"""Boosted cascade of decision stumps on the seed 003 features (pure: numpy only).

Seed 003 §2.2 trains "an AdaBoost cascade classifier" on the 1152-d fused vector; this is the
Viola-Jones form of it (Viola & Jones 2001/2004):

* a *stump* looks at one normalised feature ``v'_k`` (eqs. 3-4) and answers ``left`` when
  ``v'_k < t`` and ``right`` when ``v'_k >= t`` (``t`` an integer 1..255);
* a *stage* adds its stumps and passes a window when the sum reaches the stage threshold, chosen
  on the training positives so that the stage keeps ``hit_rate`` of them; stumps are added until
  the stage passes at most ``false_alarm_rate`` of the current negatives;
* the *cascade* passes a window only when every stage does; each new stage trains on negatives
  that all the earlier stages passed (bootstrapping: ``mine_negatives`` finds them).

Boosting: Gentle AdaBoost (Friedman, Hastie & Tibshirani 2000: leaf = weighted mean label,
weights ``*= exp(-y h)``; OpenCV's traincascade default) or discrete AdaBoost (Freund & Schapire
1997, as Viola-Jones: leaves ``+-alpha``, ``alpha = 1/2 ln((1-e)/e)``). Training samples are the
floored normalised vectors (uint8): for an integer ``t``, ``floor(v') >= t`` iff ``v' >= t``, so the
trained stumps are exact on the real-valued features the detector computes.

The model file is JSON (never pickle): window size, feature set, edge threshold, stages.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from aircraft_docking_tracker.config import param
from multi_target_tracker.features import FEATURE_SETS, FUSED_DIM, PackedStages, feature_range

MODEL_FORMAT = "aircraft_docking_tracker/boosted-cascade"
MODEL_VERSION = 1
#: Largest |stump leaf| or |stage threshold| a model may hold (trained values are below 100).
MAX_STAGE_VALUE = 1e6
#: Model sanity defaults (``DetectorConfig.max_model_stumps`` / ``min_model_window`` override them):
#: the shipped models have 280-1200 stumps and windows of 14-64 px.
MAX_STUMPS = 20000
MIN_WINDOW = 8
MAX_WINDOW = 4096


class CascadeError(ValueError):
    """A model file or training input that cannot be used."""


@dataclass
class CascadeTrainConfig:
    """Cascade training constants (Viola-Jones; the seed trains on 3000 positives, 5000 negatives)."""

    feature_set: str = param("fused", "features the stumps may use (seed: fused)", choices=FEATURE_SETS)
    stages: int = param(12, "maximum number of stages", low=1, high=50)
    hit_rate: float = param(0.995, "minimum fraction of training positives each stage keeps", low=0.5, high=1.0)
    false_alarm_rate: float = param(0.5, "a stage is complete once it passes at most this fraction of "
                                    "its negatives", low=0.01, high=0.99)
    max_stumps: int = param(60, "maximum stumps per stage", low=1, high=1000)
    negatives: int = param(5000, "negatives per stage (seed: 5000)", low=10, high=200000)
    boost: str = param("gentle", "boosting variant: gentle (OpenCV default) or discrete (Viola-Jones)",
                       choices=("gentle", "discrete"))
    min_weight_fraction: float = param(0.0, "ignore samples whose weight is below this fraction of the "
                                       "mean when searching a stump (0: use all)", low=0.0, high=1.0)


@dataclass
class Stage:
    """One boosted stage: stumps ``(feature, threshold, left, right)`` and the stage threshold."""

    features: np.ndarray
    thresholds: np.ndarray
    left: np.ndarray
    right: np.ndarray
    threshold: float

    def score(self, passes: np.ndarray) -> np.ndarray:
        """Stage sums from ``passes`` (n samples x k stumps: ``v'_feature >= t`` per stump)."""
        return np.where(passes, self.right[None, :], self.left[None, :]).sum(axis=1)

    def to_dict(self) -> dict:
        return {"threshold": float(self.threshold), "features": [int(f) for f in self.features],
                "thresholds": [int(t) for t in self.thresholds], "left": [float(v) for v in self.left],
                "right": [float(v) for v in self.right]}

    @classmethod
    def from_dict(cls, d: dict) -> "Stage":
        """A stage from its JSON form; refuses what the window loop cannot run on: non-integer or
        out-of-range stump thresholds (features are 0..255), non-finite or absurd sums (|v| > 1e6)."""
        try:
            arrays = [np.asarray(d[k], np.float64).reshape(-1) for k in ("features", "thresholds", "left", "right")]
            threshold = float(d["threshold"])
        except (OverflowError, ValueError, TypeError) as exc:
            raise CascadeError(f"a stage holds something that is not a list of numbers ({exc})") from None
        n = len(arrays[0])
        if not all(len(a) == n for a in arrays) or n == 0:
            raise CascadeError("a stage needs equally many features, thresholds, left and right values")
        if not all(np.isfinite(a).all() for a in arrays) or not math.isfinite(threshold):
            raise CascadeError("a stage holds a value that is not a finite number")
        features, thresholds, left, right = arrays
        if (features != np.round(features)).any() or features.min() < 0 or features.max() >= FUSED_DIM:
            raise CascadeError(f"feature index outside 0..{FUSED_DIM - 1}")
        if (thresholds != np.round(thresholds)).any() or thresholds.min() < 0 or thresholds.max() > 256:
            raise CascadeError("a stump threshold outside 0..256 (features are 0..255)")
        if max(np.abs(left).max(), np.abs(right).max(), abs(threshold)) > MAX_STAGE_VALUE:
            raise CascadeError(f"a stump value or stage threshold beyond +-{MAX_STAGE_VALUE:g}")
        return cls(features.astype(np.int64), thresholds.astype(np.int64), left, right, threshold)


@dataclass
class Cascade:
    """A trained cascade: window size (w, h) in pixels at scale 1, feature set, stages."""

    window: tuple[int, int]
    feature_set: str
    edge_threshold: float
    stages: list[Stage] = field(default_factory=list)
    rotate90: bool = False          # also look for the object turned by 90 degrees (trained that way)
    info: dict = field(default_factory=dict)

    def evaluate(self, passes: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray], n: int,
                 last_stage_margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Run the cascade on ``n`` samples; ``passes(features, thresholds, idx)`` tests ``v' >= t`` for
        every stump of a stage on samples ``idx`` (an ``len(idx) x k`` boolean array).

        Returns ``(idx, score)`` of the samples that pass: score = last stage sum - its threshold,
        which must reach ``last_stage_margin`` (0 is the trained cascade; below 0 widens a PR curve).
        """
        idx = np.arange(n)
        score = np.zeros(n)
        for k, stage in enumerate(self.stages):
            total = stage.score(passes(stage.features, stage.thresholds, idx))
            score = total - stage.threshold
            keep = score >= (last_stage_margin if k == len(self.stages) - 1 else 0.0)
            idx, score = idx[keep], score[keep]
            if len(idx) == 0:
                break
        return idx, score

    def evaluate_vectors(self, x: np.ndarray, last_stage_margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`evaluate` on rows of floored normalised vectors (uint8, N x 1152)."""
        x = np.asarray(x)
        if x.ndim != 2 or x.shape[1] != FUSED_DIM:
            raise CascadeError(f"expected N x {FUSED_DIM} feature vectors, got {x.shape}")
        return self.evaluate(lambda f, t, idx: x[idx[:, None], f[None, :]] >= t[None, :], len(x), last_stage_margin)

    def packed(self) -> PackedStages:
        """The stages as :class:`PackedStages` (cached; rebuilt when stages were added)."""
        cached = self.__dict__.get("_packed")
        if cached is None or cached[0] != len(self.stages):
            cached = (len(self.stages), PackedStages.of(self.stages))
            self.__dict__["_packed"] = cached
        return cached[1]

    @property
    def n_stumps(self) -> int:
        return sum(len(s.features) for s in self.stages)

    def used_features(self) -> np.ndarray:
        return np.unique(np.concatenate([s.features for s in self.stages])) if self.stages else np.zeros(0, int)

    # --- safe model file (JSON)
    def to_dict(self) -> dict:
        return {"format": MODEL_FORMAT, "version": MODEL_VERSION, "window": [int(v) for v in self.window],
                "feature_set": self.feature_set, "edge_threshold": float(self.edge_threshold),
                "rotate90": bool(self.rotate90), "info": self.info,
                "stages": [s.to_dict() for s in self.stages]}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), separators=(",", ":")))

    @classmethod
    def from_dict(cls, d: dict, max_stumps: int = MAX_STUMPS, min_window: int = MIN_WINDOW) -> "Cascade":
        """A cascade from its JSON form, refusing models that would run unbounded: more than
        ``max_stumps`` stumps, a window side below ``min_window`` or above ``MAX_WINDOW`` px."""
        if not isinstance(d, dict) or d.get("format") != MODEL_FORMAT:
            raise CascadeError(f"not a {MODEL_FORMAT} model")
        if d.get("version") != MODEL_VERSION:
            raise CascadeError(f"model version {d.get('version')} unsupported (expected {MODEL_VERSION})")
        try:
            window = tuple(int(v) for v in d["window"])
            edge_threshold = float(d["edge_threshold"])
        except (OverflowError, ValueError) as exc:
            raise CascadeError(f"bad window size or edge threshold ({exc})") from None
        if len(window) != 2 or min(window) < max(4, min_window) or max(window) > MAX_WINDOW:
            raise CascadeError(f"bad window size {window} (sides must be {max(4, min_window)}..{MAX_WINDOW} px)")
        if not math.isfinite(edge_threshold):
            raise CascadeError("edge_threshold is not a finite number")
        if d["feature_set"] not in FEATURE_SETS:
            raise CascadeError(f"unknown feature set {d['feature_set']!r}")
        if not isinstance(d["stages"], list):
            raise CascadeError("stages must be a list")
        n_stumps = sum(len(s.get("features", ())) if isinstance(s, dict) else 0 for s in d["stages"])
        if n_stumps > max_stumps:
            raise CascadeError(f"model has {n_stumps} stumps, more than max_model_stumps={max_stumps}")
        stages = [Stage.from_dict(s) for s in d["stages"]]
        allowed = set(feature_range(d["feature_set"]).tolist())
        if any(int(f) not in allowed for s in stages for f in s.features):
            raise CascadeError(f"a stump uses a feature outside the {d['feature_set']} set")
        return cls(window, d["feature_set"], edge_threshold, stages, bool(d.get("rotate90", False)),
                   dict(d.get("info", {})))

    @classmethod
    def load(cls, path: str | Path, max_stumps: int = MAX_STUMPS, min_window: int = MIN_WINDOW) -> "Cascade":
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
            raise CascadeError(f"cannot read cascade model {path}: {exc}") from exc
        try:
            return cls.from_dict(data, max_stumps, min_window)
        except CascadeError as exc:
            raise CascadeError(f"{path}: {exc}") from None
        except (KeyError, TypeError, AttributeError) as exc:
            raise CascadeError(f"{path}: malformed cascade model ({type(exc).__name__}: {exc})") from exc


# --------------------------------------------------------------------------- training
def _stump_search(idx_flat: np.ndarray, n_feat: int, w: np.ndarray, y: np.ndarray, boost: str):
    """Best stump over all (feature, integer threshold) pairs by weighted 256-bin histograms.

    Returns ``(column, t, left, right)`` with ``column`` an index into the candidate features.
    """
    reps = idx_flat.size // len(w)
    sw = np.bincount(idx_flat, weights=np.repeat(w, reps), minlength=n_feat * 256).reshape(n_feat, 256)
    swy = np.bincount(idx_flat, weights=np.repeat(w * y, reps), minlength=n_feat * 256).reshape(n_feat, 256)
    # left side of threshold t (1..255) = bins 0..t-1
    lw = np.cumsum(sw, axis=1)[:, :-1]
    lwy = np.cumsum(swy, axis=1)[:, :-1]
    tw, twy = sw.sum(axis=1, keepdims=True), swy.sum(axis=1, keepdims=True)
    rw, rwy = tw - lw, twy - lwy
    eps = 1e-12
    if boost == "gentle":
        gain = lwy ** 2 / np.maximum(lw, eps) + rwy ** 2 / np.maximum(rw, eps)   # weighted squared-error drop
        col, t0 = np.unravel_index(int(np.argmax(gain)), gain.shape)
        left = lwy[col, t0] / max(lw[col, t0], eps)
        right = rwy[col, t0] / max(rw[col, t0], eps)
        return int(col), int(t0) + 1, float(left), float(right)
    # discrete: error of "positive iff v' >= t" = positives on the left + negatives on the right
    pos_left = (lw + lwy) / 2
    neg_right = (rw - rwy) / 2
    err = (pos_left + neg_right) / np.maximum(tw, eps)
    err = np.minimum(err, 1 - err)  # either polarity
    col, t0 = np.unravel_index(int(np.argmin(err)), err.shape)
    e = float(np.clip(err[col, t0], 1e-10, 0.5 - 1e-10))
    alpha = 0.5 * math.log((1 - e) / e)
    polarity = 1.0 if (pos_left[col, t0] + neg_right[col, t0]) / max(tw[col, 0], eps) <= 0.5 else -1.0
    return int(col), int(t0) + 1, -polarity * alpha, polarity * alpha


def train_stage(xp: np.ndarray, xn: np.ndarray, cfg: CascadeTrainConfig,
                progress: Callable[[str], None] | None = None) -> tuple[Stage, float, float]:
    """Boost one stage on positives ``xp`` and negatives ``xn`` (uint8 N x 1152 floored vectors).

    Returns ``(stage, hit_rate, false_alarm_rate)`` measured on the training samples.
    """
    cand = feature_range(cfg.feature_set)
    x = np.vstack([xp, xn])[:, cand]
    y = np.concatenate([np.ones(len(xp)), -np.ones(len(xn))])
    w = np.where(y > 0, 0.5 / len(xp), 0.5 / len(xn))
    idx_flat = (np.arange(len(cand), dtype=np.int32)[None, :] * 256 + x).ravel()
    h_total = np.zeros(len(y))
    stumps: list[tuple[int, int, float, float]] = []
    thr, hit, far = 0.0, 1.0, 1.0
    while len(stumps) < cfg.max_stumps:
        col, t, left, right = _stump_search(idx_flat, len(cand), w, y, cfg.boost)
        h = np.where(x[:, col] >= t, right, left)
        h_total += h
        w = w * np.exp(-y * h)
        w /= w.sum()
        stumps.append((int(cand[col]), t, left, right))
        sp, sn = h_total[y > 0], h_total[y < 0]
        k = int(math.floor((1.0 - cfg.hit_rate) * len(sp)))
        thr = float(np.sort(sp)[k]) - 1e-9
        hit, far = float(np.mean(sp >= thr)), float(np.mean(sn >= thr))
        if far <= cfg.false_alarm_rate:
            break
    f, t, lo, hi = (np.asarray(v) for v in zip(*stumps))
    stage = Stage(f.astype(np.int64), t.astype(np.int64), lo.astype(np.float64), hi.astype(np.float64), thr)
    return stage, hit, far


def train_cascade(xp: np.ndarray, mine_negatives: Callable[[Cascade, int], np.ndarray], cfg: CascadeTrainConfig,
                  window: tuple[int, int], edge_threshold: float, rotate90: bool = False,
                  progress: Callable[[str], None] | None = None,
                  on_stage: Callable[[Cascade], None] | None = None) -> Cascade:
    """Train stage after stage; ``mine_negatives(cascade, n)`` returns up to ``n`` negative vectors that
    the cascade so far passes (bootstrapping). Stops at ``cfg.stages`` or when negatives run out.
    ``on_stage(cascade)`` is called after every stage (e.g. to save a usable model early)."""
    xp = np.asarray(xp, np.uint8)
    if xp.ndim != 2 or xp.shape[1] != FUSED_DIM or len(xp) < 2:
        raise CascadeError(f"need at least 2 positive vectors of {FUSED_DIM} values, got {xp.shape}")
    say = progress or (lambda msg: None)
    cascade = Cascade(tuple(window), cfg.feature_set, edge_threshold, [], rotate90,
                      {"train": asdict(cfg), "positives": int(len(xp))})
    overall_far = 1.0
    for k in range(cfg.stages):
        xn = np.asarray(mine_negatives(cascade, cfg.negatives), np.uint8)
        if len(xn) < max(10, cfg.negatives // 100):
            say(f"stage {k + 1}: only {len(xn)} negatives pass the cascade; stopping")
            break
        kept, _ = cascade.evaluate_vectors(xp)
        xp_k = xp[kept]
        say(f"stage {k + 1}: {len(xn)} negatives mined; boosting")
        stage, hit, far = train_stage(xp_k, xn, cfg)
        cascade.stages.append(stage)
        overall_far *= far
        say(f"stage {k + 1}/{cfg.stages}: {len(stage.features)} stumps, positives {len(xp_k)}, "
            f"negatives {len(xn)}, hit {hit:.4f}, false alarms {far:.4f} (cascade ~{overall_far:.2e})")
        cascade.info["stage_count"] = len(cascade.stages)
        if on_stage is not None:
            on_stage(cascade)
    cascade.info["stage_count"] = len(cascade.stages)
    return cascade
