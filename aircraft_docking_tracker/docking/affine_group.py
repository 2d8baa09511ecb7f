"""The 2-D affine group G = Aff(2) and its Lie algebra g (seed 000 §2.1, eqs. 1, 2 and 5). Pure.

A state is a 3x3 matrix ``X = [[a11 a12 tx], [a21 a22 ty], [0 0 1]]`` that maps *template
coordinates* to image coordinates. The template is the unit square centred on the origin,
``u, v in [-1/2, 1/2]``, corners in the agreed order top-left, top-right, bottom-right,
bottom-left; so an axis-aligned box ``x, y, w, h`` (top-left corner, pixels) is
``X = [[w, 0, x + w/2], [0, h, y + h/2], [0, 0, 1]]``. Image coordinates are continuous with
pixel ``i`` covering ``[i, i+1)`` (so a box's corners are its quadrilateral's corners).

Noise and self-tuning offsets act on the right, ``X · exp(dΩ)`` (eq. 3): they are expressed in
the object's own frame, so a translation of 0.1 is a tenth of the object's width whatever its
size in the image.

``exp``/``log`` (eq. 2) are computed in closed form, vectorised over stacks of matrices: the
seed writes them as power series, which converge only near the identity (and its log series is
printed with ``(I - X)`` where ``(X - I)`` is meant). For a 2x2 block ``B`` with eigenvalues
``λ±`` any analytic ``f(B) = a I + b (B - m I)`` with ``a = (f(λ+) + f(λ-))/2``,
``b = (f(λ+) - f(λ-)) / (λ+ - λ-)`` (Sylvester); the affine exponential is
``[[e^B, V t], [0, 1]]`` with ``V = φ(B)``, ``φ(λ) = (e^λ - 1)/λ``. Tests compare with
``scipy.linalg.expm``/``logm``.

Named parameters (the chart used for the state row): the polar decomposition ``A = R(θ) S``
with ``S`` symmetric positive definite and ``log S = s E1 + α E2 + φ E4`` (2x2 parts), so
``scale = e^s = sqrt(det A)`` (pixels per template unit, ``sqrt(w h)`` for a box),
``aspect = e^{2α}`` (``w / h`` for a box), ``rotation = θ`` (radians, counter-clockwise in
image axes x right / y down, i.e. E3's sense) and ``skew = φ``.
"""
from __future__ import annotations

import cmath
import math

import cv2
import numba
import numpy as np

from ..geometry import quad_to_box

#: Lie algebra basis E1..E6 (seed eq. 5): scale, aspect, rotation, skew, x, y.
BASIS = np.array([
    [[1, 0, 0], [0, 1, 0], [0, 0, 0]],
    [[1, 0, 0], [0, -1, 0], [0, 0, 0]],
    [[0, -1, 0], [1, 0, 0], [0, 0, 0]],
    [[0, 1, 0], [1, 0, 0], [0, 0, 0]],
    [[0, 0, 1], [0, 0, 0], [0, 0, 0]],
    [[0, 0, 0], [0, 0, 1], [0, 0, 0]],
], dtype=float)

#: Template corners (u, v) in the agreed polygon order: TL, TR, BR, BL.
UNIT_CORNERS = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])


class AffineError(ValueError):
    """A matrix or parameter vector that is not a valid affine-group element."""


# --------------------------------------------------------------------------- algebra <-> matrices
def hat(w: np.ndarray) -> np.ndarray:
    """Coordinates ``w`` (..., 6) -> algebra element ``Σ w_i E_i`` (..., 3, 3) (eq. 3's dΩ)."""
    return np.tensordot(np.asarray(w, dtype=float), BASIS, axes=([-1], [0]))


def vee(x: np.ndarray) -> np.ndarray:
    """Algebra element (..., 3, 3) -> coordinates (..., 6) in the basis E1..E6 (inverse of hat)."""
    x = np.asarray(x, dtype=float)
    a11, a12, a21, a22 = x[..., 0, 0], x[..., 0, 1], x[..., 1, 0], x[..., 1, 1]
    return np.stack([(a11 + a22) / 2, (a11 - a22) / 2, (a21 - a12) / 2, (a21 + a12) / 2,
                     x[..., 0, 2], x[..., 1, 2]], axis=-1)


EXP, LOG, PHI = 0, 1, 2    # the analytic functions f of ``_matrix_function``: exp, log, φ(λ) = (e^λ - 1)/λ


@numba.njit(cache=True, nogil=True)
def _expm1(z):
    """e^z - 1 for complex z without cancellation near 0 (numpy's formula)."""
    half = math.sin(z.imag / 2)
    return complex(math.expm1(z.real) * math.cos(z.imag) - 2.0 * half * half, math.exp(z.real) * math.sin(z.imag))


@numba.njit(cache=True, nogil=True)
def _f(kind, z):
    if kind == EXP:
        return cmath.exp(z)
    if kind == LOG:
        return cmath.log(z)
    return 1.0 + z / 2 if abs(z) < 1e-8 else _expm1(z) / z


@numba.njit(cache=True, nogil=True)
def _df(kind, z):
    if kind == EXP:
        return cmath.exp(z)
    if kind == LOG:
        return 1.0 / z
    return 0.5 + z / 3 if abs(z) < 1e-4 else (z * cmath.exp(z) - _expm1(z)) / (z * z)


@numba.njit(cache=True, nogil=True)
def _sylvester(b00, b01, b10, b11, kind):
    """``f(B)`` of one real 2x2 matrix by Sylvester's formula: ``a I + b N``, N = B - m I (``df`` for λ+ ≈ λ-)."""
    m = (b00 + b11) / 2
    n00, n11 = b00 - m, b11 - m
    r = cmath.sqrt(complex(n00 * n00 + b01 * b10, 0.0))          # N @ N = q I (N traceless), r = sqrt(q)
    if abs(r) < 1e-5:
        a, b = _f(kind, complex(m, 0.0)).real, _df(kind, complex(m, 0.0)).real
    else:
        fp, fm = _f(kind, m + r), _f(kind, m - r)
        a, b = ((fp + fm) / 2).real, ((fp - fm) / (2 * r)).real
    return a + b * n00, b * b01, b * b10, a + b * n11


@numba.njit(cache=True, nogil=True)
def _matrices(B, kind):
    out = np.empty_like(B)
    for i in range(B.shape[0]):
        out[i, 0, 0], out[i, 0, 1], out[i, 1, 0], out[i, 1, 1] = _sylvester(B[i, 0, 0], B[i, 0, 1], B[i, 1, 0],
                                                                            B[i, 1, 1], kind)
    return out


@numba.njit(cache=True, nogil=True)
def _affine_exp_or_log(x, log):
    """exp (``log`` False) or log of each affine matrix of the stack: the 2x2 block ``B`` -> ``f(B)``, and with
    ``V = φ(algebra block)`` the translation ``t -> V t`` (exp) or ``V^-1 t`` (log)."""
    out = np.zeros_like(x)
    for i in range(x.shape[0]):
        b00, b01, b10, b11 = x[i, 0, 0], x[i, 0, 1], x[i, 1, 0], x[i, 1, 1]
        f00, f01, f10, f11 = _sylvester(b00, b01, b10, b11, LOG if log else EXP)
        if log:
            b00, b01, b10, b11 = f00, f01, f10, f11
        v00, v01, v10, v11 = _sylvester(b00, b01, b10, b11, PHI)
        tx, ty = x[i, 0, 2], x[i, 1, 2]
        if log:
            det = v00 * v11 - v01 * v10
            v00, v01, v10, v11 = v11 / det, -v01 / det, -v10 / det, v00 / det
        out[i, 0, 0], out[i, 0, 1], out[i, 1, 0], out[i, 1, 1] = f00, f01, f10, f11
        out[i, 0, 2], out[i, 1, 2] = v00 * tx + v01 * ty, v10 * tx + v11 * ty
        out[i, 2, 2] = 0.0 if log else 1.0
    return out


def _matrix_function(B: np.ndarray, kind: int) -> np.ndarray:
    """``f(B)`` (f = EXP, LOG or PHI) for one real 2x2 matrix or a stack (..., 2, 2) (compiled, one loop)."""
    B = np.asarray(B, dtype=float)
    return _matrices(np.ascontiguousarray(B.reshape(-1, 2, 2)), kind).reshape(B.shape)


def expm(x: np.ndarray) -> np.ndarray:
    """exp: g -> G (eq. 2) for one algebra element or a stack (..., 3, 3), in closed form:
    ``[[e^B, φ(B) t], [0, 1]]``."""
    x = np.asarray(x, dtype=float)
    return _affine_exp_or_log(np.ascontiguousarray(x.reshape(-1, 3, 3)), False).reshape(x.shape)


def logm(X: np.ndarray) -> np.ndarray:
    """log: G -> g (eq. 2), principal branch, for one matrix or a stack (..., 3, 3).

    Raises AffineError for matrices without a real logarithm (det <= 0, reflections, rotations
    by π), which no state reached from the identity by this filter can be.
    """
    X = np.asarray(X, dtype=float)
    A = X[..., :2, :2]
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    if np.any(~(det > 0)):
        raise AffineError("affine matrix with non-positive determinant has no real logarithm")
    return _affine_exp_or_log(np.ascontiguousarray(X.reshape(-1, 3, 3)), True).reshape(X.shape)


def exp_coords(w: np.ndarray) -> np.ndarray:
    """``exp(Σ w_i E_i)`` for coordinates (..., 6)."""
    return expm(hat(w))


def log_coords(X: np.ndarray) -> np.ndarray:
    """Coordinates (..., 6) of ``log X``."""
    return vee(logm(X))


def inverse(X: np.ndarray) -> np.ndarray:
    """Group inverse of one matrix or a stack."""
    return np.linalg.inv(np.asarray(X, dtype=float))


# --------------------------------------------------------------------------- named parameters
PARAMETER_NAMES = ("cx", "cy", "scale", "aspect", "rotation", "skew")


def from_box(x: float, y: float, w: float, h: float) -> np.ndarray:
    """The state of an axis-aligned box (x, y = top-left corner, pixels)."""
    if not (w > 0 and h > 0) or not np.all(np.isfinite([x, y, w, h])):
        raise AffineError(f"box needs finite x, y and positive w, h, got {x, y, w, h}")
    return np.array([[w, 0.0, x + w / 2], [0.0, h, y + h / 2], [0.0, 0.0, 1.0]])


def to_params(X: np.ndarray) -> np.ndarray:
    """State (..., 3, 3) -> (cx, cy, scale, aspect, rotation, skew) via the polar decomposition."""
    X = np.asarray(X, dtype=float)
    A = X[..., :2, :2]
    theta = np.arctan2(A[..., 1, 0] - A[..., 0, 1], A[..., 0, 0] + A[..., 1, 1])
    c, s = np.cos(theta), np.sin(theta)
    Rt = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)
    S = Rt @ A
    S = (S + np.swapaxes(S, -1, -2)) / 2
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] ** 2
    if np.any(~(det > 0)) or np.any(~(S[..., 0, 0] > 0)):
        raise AffineError("affine matrix is not orientation preserving")
    L = _matrix_function(S, LOG)
    s_log, alpha, phi = (L[..., 0, 0] + L[..., 1, 1]) / 2, (L[..., 0, 0] - L[..., 1, 1]) / 2, L[..., 0, 1]
    return np.stack([X[..., 0, 2], X[..., 1, 2], np.exp(s_log), np.exp(2 * alpha), theta, phi], axis=-1)


def from_params(p: np.ndarray) -> np.ndarray:
    """(cx, cy, scale, aspect, rotation, skew) (..., 6) -> state (..., 3, 3); inverse of to_params."""
    p = np.asarray(p, dtype=float)
    cx, cy, scale, aspect, theta, phi = np.moveaxis(p, -1, 0)
    if np.any(~(scale > 0)) or np.any(~(aspect > 0)):
        raise AffineError("scale and aspect must be positive")
    w = np.stack([np.log(scale), np.log(aspect) / 2, np.zeros_like(theta), phi,
                  np.zeros_like(theta), np.zeros_like(theta)], -1)
    S = exp_coords(w)
    R = exp_coords(np.stack([np.zeros_like(theta)] * 2 + [theta] + [np.zeros_like(theta)] * 3, -1))
    X = R @ S
    X[..., 0, 2], X[..., 1, 2] = cx, cy
    return X


# --------------------------------------------------------------------------- quadrilaterals, boxes
def to_quad(X: np.ndarray) -> np.ndarray:
    """State (..., 3, 3) -> its image quadrilateral (..., 4, 2): TL, TR, BR, BL of the template."""
    X = np.asarray(X, dtype=float)
    return np.einsum("...ij,kj->...ki", X[..., :2, :2], UNIT_CORNERS) + X[..., None, :2, 2]


def from_quad(quad: np.ndarray) -> np.ndarray:
    """Least-squares affine state mapping the template corners onto ``quad`` (4, 2)."""
    quad = np.asarray(quad, dtype=float)
    if quad.shape != (4, 2) or not np.all(np.isfinite(quad)):
        raise AffineError(f"quadrilateral must be 4 finite (x, y) points, got shape {quad.shape}")
    design = np.hstack([UNIT_CORNERS, np.ones((4, 1))])
    sol, *_ = np.linalg.lstsq(design, quad, rcond=None)       # (3, 2)
    X = np.eye(3)
    X[:2, :] = sol.T
    if np.linalg.det(X[:2, :2]) <= 0:
        raise AffineError("quadrilateral is degenerate or mirrored")
    return X


def to_box(X: np.ndarray) -> np.ndarray:
    """Axis-aligned bounding box (..., 4) x, y, w, h of the state's quadrilateral."""
    return quad_to_box(to_quad(X))


# --------------------------------------------------------------------------- warping
def template_grid(width: int, height: int) -> np.ndarray:
    """Homogeneous template coordinates (3, height*width) of a width x height patch's pixel centres."""
    u = (np.arange(width) + 0.5) / width - 0.5
    v = (np.arange(height) + 0.5) / height - 0.5
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)]).astype(np.float32)


def warp_patches(image: np.ndarray, X: np.ndarray, size: tuple[int, int], level: int = 0,
                 grid: np.ndarray | None = None) -> np.ndarray:
    """Sample the template patch of every state out of one image with ONE ``cv2.remap`` call.

    image: 2-D (grey) array, pyramid level ``level`` of the frame (``cv2.pyrDown`` applied
    ``level`` times), X: (N, 3, 3) states in full-resolution coordinates, size: (width, height)
    of the patch. Returns (N, height, width) float32, bilinear, borders replicated.
    """
    X = np.asarray(X, dtype=float).reshape(-1, 3, 3)
    w, h = size
    if grid is None:
        grid = template_grid(w, h)
    # edge coordinates of the level: (x / 2^level) - 0.5 for pixel centres, folded into the matrices
    A = (X[:, :2, :] / (2 ** level)).astype(np.float32)
    A[:, :, 2] -= 0.5
    maps = A @ grid.astype(np.float32, copy=False)                  # (N, 2, h*w)
    map_x = maps[:, 0].reshape(len(X) * h, w)
    map_y = maps[:, 1].reshape(len(X) * h, w)
    if len(X) * h < _REMAP_MAX_ROWS:
        out = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    else:  # cv2.remap refuses maps of SHRT_MAX rows or more: a few calls for very large sets
        step = (_REMAP_MAX_ROWS // h) * h
        out = np.vstack([cv2.remap(image, map_x[i:i + step], map_y[i:i + step], cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_REPLICATE) for i in range(0, len(map_x), step)])
    return out.reshape(len(X), h, w).astype(np.float32, copy=False)


_REMAP_MAX_ROWS = 32000
