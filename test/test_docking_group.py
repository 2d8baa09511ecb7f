"""Affine group maths (seed 000 eqs. 1-5): exp/log, composition, parameters, quadrilaterals, warping."""
import cv2
import numpy as np
import pytest
import scipy.linalg

from aircraft_docking_tracker.docking import affine_group as ag


@pytest.fixture
def algebra():
    rng = np.random.default_rng(3)
    w = rng.normal(size=(64, 6)) * np.array([0.4, 0.3, 1.2, 0.3, 20.0, 20.0])
    w[0] = 0.0                                       # the identity
    w[1] = [1e-9, 0, 0, 0, 1, 0]                     # nearly repeated eigenvalues
    w[2] = [0.2, 0, 0, 0.2, 1, 2]                    # real distinct eigenvalues
    w[3] = [1e-6, 2e-6, 3e-6, 0, 5, -3]              # eigenvalues within 1e-5: the derivative branch
    w[4] = [3e-5, 0, 4e-5, 0, 1, 1]                  # complex pair near 0: (e^z - 1)/z without cancellation
    return ag.hat(w)


def test_basis_is_the_seeds():
    assert np.array_equal(ag.BASIS[2], [[0, -1, 0], [1, 0, 0], [0, 0, 0]])     # E3 rotation
    assert np.array_equal(ag.BASIS[3], [[0, 1, 0], [1, 0, 0], [0, 0, 0]])      # E4 skew
    w = np.arange(1.0, 7.0)
    assert np.allclose(ag.vee(ag.hat(w)), w)


def test_exp_matches_scipy_and_log_inverts_it(algebra):
    X = ag.expm(algebra)
    ref = np.stack([scipy.linalg.expm(x) for x in algebra])
    assert np.abs(X - ref).max() < 1e-9
    assert np.abs(ag.logm(X) - algebra).max() < 1e-9                   # log ∘ exp = id
    assert np.abs(ag.expm(ag.logm(X)) - X).max() < 1e-9                 # exp ∘ log = id
    assert np.abs(ag.logm(X[5]) - scipy.linalg.logm(X[5]).real).max() < 1e-8


def test_composition_and_inverse(algebra):
    X = ag.expm(algebra)
    # one-parameter subgroup: exp(s x) exp(t x) = exp((s + t) x)
    assert np.allclose(ag.expm(0.3 * algebra) @ ag.expm(0.7 * algebra), X, atol=1e-9)
    assert np.allclose(ag.expm(-algebra) @ X, np.eye(3), atol=1e-9)
    assert np.allclose(ag.inverse(X[7]) @ X[7], np.eye(3))
    # AR velocity (eq. 4) of a pure translation is that translation
    a, b = ag.from_box(10, 10, 20, 20), ag.from_box(14, 10, 20, 20)
    assert np.allclose(ag.log_coords(ag.inverse(a) @ b), [0, 0, 0, 0, 0.2, 0])


def test_log_refuses_mirrors():
    with pytest.raises(ag.AffineError):
        ag.logm(np.diag([-1.0, 1.0, 1.0]))


def test_box_params_quad_round_trip():
    X = ag.from_box(10, 20, 30, 40)
    assert np.allclose(ag.to_quad(X), [[10, 20], [40, 20], [40, 60], [10, 60]])
    cx, cy, scale, aspect, rot, skew = ag.to_params(X)
    assert (cx, cy) == (25, 40) and np.isclose(scale, np.sqrt(1200)) and np.isclose(aspect, 0.75)
    assert np.isclose(rot, 0) and np.isclose(skew, 0)
    rng = np.random.default_rng(0)
    p = np.column_stack([rng.uniform(0, 500, 50), rng.uniform(0, 500, 50), rng.uniform(5, 300, 50),
                         rng.uniform(0.2, 5, 50), rng.uniform(-3, 3, 50), rng.uniform(-0.5, 0.5, 50)])
    Xs = ag.from_params(p)
    assert np.allclose(ag.to_params(Xs), p, atol=1e-9)
    for Xi in Xs[:10]:
        assert np.allclose(ag.from_quad(ag.to_quad(Xi)), Xi, atol=1e-9)
    assert np.allclose(ag.to_box(X), [10, 20, 30, 40])
    rotated = ag.from_params([0, 0, 10, 1, np.pi / 4, 0])
    assert np.isclose(ag.to_params(rotated)[4], np.pi / 4)
    assert np.allclose(ag.to_box(rotated)[2:], [10 * np.sqrt(2)] * 2)


def test_bad_boxes_and_quads_are_refused():
    with pytest.raises(ag.AffineError):
        ag.from_box(0, 0, -3, 4)
    with pytest.raises(ag.AffineError):
        ag.from_quad(np.zeros((4, 2)))
    with pytest.raises(ag.AffineError):
        ag.from_quad([[0, 0], [1, 0], [1, 1]])


def test_warp_samples_the_template_of_every_particle_in_one_call():
    image = np.add.outer(np.arange(120.0), 1000 * np.arange(100.0)).astype(np.float32)  # value = y + 1000 x
    X = np.stack([ag.from_box(10, 20, 40, 30), ag.from_box(50, 5, 20, 60)])
    patches = ag.warp_patches(image, X, (8, 6))
    assert patches.shape == (2, 6, 8)
    # pixel (r, c) of patch 0 samples the centre of its sub-cell: x = 10 + (c + .5) * 5 - .5
    c, r = 3, 2
    assert np.isclose(patches[0, r, c], (20 + (r + 0.5) * 5 - 0.5) + 1000 * (10 + (c + 0.5) * 5 - 0.5), atol=0.5)
    # the same sampling from pyramid level 1 agrees up to the pyramid's smoothing
    smooth = cv2.GaussianBlur(image, (0, 0), 2)
    lvl = ag.warp_patches(cv2.pyrDown(smooth), X, (8, 6), level=1)
    assert np.abs(lvl - ag.warp_patches(smooth, X, (8, 6))).max() < 0.02 * np.abs(image).max()
    # very large sets are split across calls (cv2.remap's row limit) without changing the result
    many = np.repeat(X[:1], 1200, axis=0)
    big = ag.warp_patches(image, many, (32, 32))
    assert big.shape == (1200, 32, 32) and np.allclose(big[-1], big[0])
