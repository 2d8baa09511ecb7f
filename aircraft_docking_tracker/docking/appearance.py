"""Observation model ``o(X)``, similarity ``Sim`` and the online learned estimator (seed 000 §2.2). Pure.

The seed uses ``Sim(o(X))`` and "the online learned estimator" without defining them; they come
from Li, Tan, Chen & Huang (IEEE TIP 2012), whose exact forms are not restated in the seed. The
choices made here, in that paper's spirit, are:

1. **Observation** ``o(X)``: the grey template patch (``template_width`` x ``template_height``,
   default 32x32 as in IVT) warped out of the frame by ``X``, each patch normalised to zero mean
   and unit variance (robust to the light changes of an apron and of OTB Car4).
2. **Appearance model**: an incremental PCA subspace with a forgetting factor (IVT: Ross, Lim,
   Lin & Yang, IJCV 2008, "sequential Karhunen-Loeve" with mean update), fed in batches of
   ``batch_size`` accepted results (only those the filter's conditional update admits, step 8).
3. **Similarity**: ``Sim = 1 - mean_i ρ(e_i)`` of the reconstruction residual ``e`` of the
   patch in that subspace, ``ρ(e) = e² / (e² + σ²)`` (Geman-McClure, the robust error of IVT's
   occlusion-aware variant); so ``Sim ∈ (0, 1]``, 1 = perfectly explained.
4. **Estimator** (the self-tuning step): a ridge regression from the patch appearance (the
   patch averaged down to ``feature_size``², normalised, plus a bias) to the Lie-algebra offset
   ``δ`` with ``X_true = X · exp(δ)`` (Tuzel, Porikli & Meer, CVPR 2008, "learning on Lie
   groups"). It is trained on random perturbations ``X̂ · exp(-δ)``, ``δ ~ N(0, (spread Σ_g))``,
   of the accepted estimate, as sufficient statistics with a forgetting factor, so it keeps
   learning online at every conditional update.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..config import param


class AppearanceError(ValueError):
    """Patches of the wrong shape or a model used before it was started."""


@dataclass
class AppearanceConfig:
    """Observation model constants (IVT's values where IVT gives them)."""

    template_width: int = param(32, "template patch width [px] (IVT: 32)", low=8, high=96)
    template_height: int = param(32, "template patch height [px] (IVT: 32)", low=8, high=96)
    max_basis: int = param(16, "eigenbasis vectors kept by the incremental PCA (IVT: 16)", low=0, high=64)
    batch_size: int = param(5, "accepted patches per incremental PCA update (IVT: 5)", low=1, high=50)
    forgetting: float = param(0.95, "incremental PCA forgetting factor f (IVT: 0.95)", low=0.5, high=1.0)
    robust_sigma: float = param(0.7, "Geman-McClure scale σ of the residual of normalised patches",
                                low=0.05, high=5.0)
    anchor_weight: float = param(0.0, "weight β of the anchor term: Sim = (1-β) Sim_subspace + β Sim_anchor, "
                                 "Sim_anchor the same robust score against the first frame's patch alone "
                                 "(never updated, so the model cannot learn a drift away from it); 0: the "
                                 "subspace alone (the seed's)", low=0.0, high=1.0)
    feature_size: int = param(8, "side of the estimator's feature patch [px]", low=4, high=32)
    ridge: float = param(30.0, "estimator ridge penalty λ", low=1e-6, high=1e4)
    train_samples: int = param(300, "estimator training perturbations at start", low=12, high=2000)
    update_samples: int = param(24, "estimator training perturbations per model update", low=0, high=500)
    train_spread: float = param(1.0, "estimator perturbations' std as a multiple of Σ_g", low=0.1, high=10.0)
    estimator_forgetting: float = param(0.95, "forgetting factor of the estimator's statistics",
                                        low=0.5, high=1.0)


def normalize(patches: np.ndarray) -> np.ndarray:
    """(N, h, w) patches -> (N, h*w) rows of zero mean and unit variance (choice 1)."""
    y = np.asarray(patches, dtype=np.float32).reshape(len(patches), -1)
    y = y - y.mean(axis=1, keepdims=True)
    return y / (y.std(axis=1, keepdims=True) + 1e-3)


class IncrementalSubspace:
    """Incremental PCA with mean update and forgetting (Ross et al. 2008, Algorithm "sklm")."""

    def __init__(self, dim: int, max_basis: int, forgetting: float):
        self.dim, self.max_basis, self.forgetting = dim, max_basis, forgetting
        self.mean = np.zeros(dim, dtype=np.float32)
        self.basis = np.zeros((dim, 0), dtype=np.float32)
        self.singular = np.zeros(0, dtype=np.float32)
        self.count = 0.0

    def update(self, data: np.ndarray) -> None:
        """Add rows ``data`` (m, dim): new mean, then SVD of the small R matrix (IVT eqs.)."""
        data = np.asarray(data, dtype=np.float64)
        m = len(data)
        if self.count == 0:
            self.mean = data.mean(axis=0).astype(np.float32)
            self.count = float(m)
            if m > 1 and self.max_basis:
                _, s, vt = np.linalg.svd(data - self.mean, full_matrices=False)
                self._keep(vt.T, s)
            return
        f, n = self.forgetting, self.count
        mean_b = data.mean(axis=0)
        mean_new = (f * n * self.mean + m * mean_b) / (f * n + m)
        b_hat = np.vstack([data - mean_b, np.sqrt(n * m / (n + m)) * (mean_b - self.mean)]).T  # dim x (m+1)
        U = self.basis.astype(np.float64)
        proj = U.T @ b_hat
        resid = b_hat - U @ proj
        b_tilde, _ = np.linalg.qr(resid)
        k = U.shape[1]
        R = np.zeros((k + b_tilde.shape[1], k + b_hat.shape[1]))
        R[:k, :k] = f * np.diag(self.singular)
        R[:k, k:] = proj
        R[k:, k:] = b_tilde.T @ resid
        u_r, s_r, _ = np.linalg.svd(R, full_matrices=False)
        self._keep(np.hstack([U, b_tilde]) @ u_r, s_r)
        self.mean = mean_new.astype(np.float32)
        self.count = f * n + m

    def _keep(self, basis: np.ndarray, singular: np.ndarray) -> None:
        k = min(self.max_basis, int(np.sum(singular > 1e-6 * max(singular.max(initial=0), 1e-12))))
        self.basis = basis[:, :k].astype(np.float32)
        self.singular = singular[:k].astype(np.float32)

    def residual(self, y: np.ndarray) -> np.ndarray:
        """Reconstruction residual (N, dim) of rows ``y`` in the affine subspace mean + span(basis)."""
        d = y - self.mean
        return d - (d @ self.basis) @ self.basis.T


class ObservationModel:
    """``o(X)`` features, ``Sim`` and the model update (choices 1-3 of the module docstring)."""

    def __init__(self, config: AppearanceConfig):
        self.config = config
        self.size = (config.template_width, config.template_height)
        self.subspace = IncrementalSubspace(config.template_width * config.template_height,
                                            config.max_basis, config.forgetting)
        self._pending: list[np.ndarray] = []
        self.anchor = np.zeros(config.template_width * config.template_height, dtype=np.float32)
        self.anchor_weight = config.anchor_weight      # β; the filter may change it per frame (moving_anchor_weight)

    @property
    def started(self) -> bool:
        return self.subspace.count > 0

    def _check(self, patches: np.ndarray) -> np.ndarray:
        patches = np.asarray(patches)
        w, h = self.size
        if patches.ndim != 3 or patches.shape[1:] != (h, w):
            raise AppearanceError(f"patches must be (N, {h}, {w}), got {patches.shape}")
        return patches

    def start(self, patches: np.ndarray) -> None:
        """Initialise the subspace from the first frame's patch(es)."""
        y = normalize(self._check(patches))
        self.subspace.update(y)
        self.anchor = y.mean(axis=0)
        self._pending.clear()

    def similarity(self, patches: np.ndarray) -> np.ndarray:
        """``Sim(o(X))`` per patch: ``1 - mean ρ(e)`` (choice 3), in (0, 1]."""
        if not self.started:
            raise AppearanceError("observation model used before start()")
        y = normalize(self._check(patches))
        s2 = np.float32(self.config.robust_sigma ** 2)
        e2 = self.subspace.residual(y) ** 2
        sim = 1.0 - (e2 / (e2 + s2)).mean(axis=1)
        beta = self.anchor_weight
        if beta > 0:
            sim = (1 - beta) * sim + beta * self.anchor_similarity(y, normalized=True)
        return sim

    def anchor_similarity(self, patches: np.ndarray, normalized: bool = False) -> np.ndarray:
        """``Sim_anchor``: the robust score of each patch against the first frame's patch alone."""
        if not self.started:
            raise AppearanceError("observation model used before start()")
        y = patches if normalized else normalize(self._check(patches))
        e2 = (y - self.anchor) ** 2
        s2 = np.float32(self.config.robust_sigma ** 2)
        return 1.0 - (e2 / (e2 + s2)).mean(axis=1)

    def add(self, patch: np.ndarray) -> bool:
        """Queue an accepted patch (step 8); update the subspace every ``batch_size``. True if updated."""
        self._pending.append(normalize(self._check(patch[None]))[0])
        if len(self._pending) < self.config.batch_size:
            return False
        self.subspace.update(np.stack(self._pending))
        self._pending.clear()
        return True


class PoseEstimator:
    """Online ridge regression: patch appearance -> Lie-algebra offset δ (choice 4)."""

    def __init__(self, config: AppearanceConfig):
        self.config = config
        d = config.feature_size ** 2 + 1
        self.gram = np.zeros((d, d))
        self.cross = np.zeros((d, 6))
        self.weights = np.zeros((d, 6))
        self.sum_sq = np.zeros(6)
        self.count = 0.0
        self.gain = np.zeros(6)

    def features(self, patches: np.ndarray) -> np.ndarray:
        """Patches (N, h, w) -> rows (N, feature_size² + 1): area-averaged, normalised, bias 1."""
        n, h, w = patches.shape
        fs = self.config.feature_size
        small = _area_matrix(fs, h) @ patches @ _area_matrix(fs, w).T
        return np.hstack([normalize(small), np.ones((n, 1), np.float32)])

    def train(self, patches: np.ndarray, offsets: np.ndarray, forget: bool = True) -> None:
        """Add training pairs (patch at ``X̂·exp(-δ)``, ``δ``) and re-solve the ridge system.

        Each output dimension is then shrunk by its adjusted R² on the (forgetting) training set,
        so a direction the appearance does not reveal (say, a 3 % scale change of a low-contrast
        patch) is not "corrected" by noise: the gain is 0 for no skill, 1 for a perfect fit.
        """
        phi = self.features(patches).astype(np.float64)
        f = self.config.estimator_forgetting if forget else 1.0
        self.gram = f * self.gram + phi.T @ phi
        self.cross = f * self.cross + phi.T @ offsets
        self.sum_sq = f * self.sum_sq + (offsets ** 2).sum(axis=0)
        self.count = f * self.count + len(offsets)
        reg = self.config.ridge * np.eye(len(self.gram))
        reg[-1, -1] = 1e-9                                        # do not shrink the bias
        self.weights = np.linalg.solve(self.gram + reg, self.cross)
        sse = self.sum_sq - 2 * np.einsum("ij,ij->j", self.weights, self.cross) \
            + np.einsum("ij,ik,kj->j", self.weights, self.gram, self.weights)
        r2 = 1.0 - sse / np.maximum(self.sum_sq, 1e-12)
        p = len(self.gram) - 1
        dof = max(self.count - p - 1, 1.0)
        self.gain = np.clip(1.0 - (1.0 - r2) * (self.count - 1) / dof, 0.0, 1.0)

    def predict(self, patches: np.ndarray) -> np.ndarray:
        """Offsets δ (N, 6) in algebra coordinates such that ``X · exp(δ)`` is the optimum."""
        return (self.features(patches) @ self.weights.astype(np.float32)) * self.gain.astype(np.float32)


@functools.lru_cache(maxsize=16)
def _area_matrix(out_size: int, in_size: int) -> np.ndarray:
    """(out, in) matrix averaging ``in`` samples into ``out`` equal bins (area interpolation)."""
    edges = np.linspace(0.0, in_size, out_size + 1)
    lo, hi = edges[:-1, None], edges[1:, None]
    pix = np.arange(in_size)[None, :]
    overlap = np.clip(np.minimum(hi, pix + 1) - np.maximum(lo, pix), 0.0, None)
    return (overlap / overlap.sum(axis=1, keepdims=True)).astype(np.float32)
