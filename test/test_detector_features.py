"""Seed 003 §2.1-2.2 features against hand-computed cases, and the fast scan against the reference."""
import cv2
import numpy as np
import pytest

from multi_target_tracker import features as F
from multi_target_tracker.cascade import Cascade, Stage


def test_lbp_code_hand_computed():
    # neighbours clockwise from the top-left are bits 0..7; bit set when neighbour >= centre
    g = np.array([[9, 1, 5],
                  [1, 5, 7],
                  [5, 0, 2]], np.uint8)
    # top-left 9>=5 (bit0), top 1 (no), top-right 5>=5 (bit2), right 7 (bit3), bottom-right 2 (no),
    # bottom 0 (no), bottom-left 5>=5 (bit6), left 1 (no)
    assert F.lbp_codes(g).tolist() == [[1 + 4 + 8 + 64]]
    flat = np.full((4, 5), 7, np.uint8)
    assert (F.lbp_codes(flat) == 255).all() and F.lbp_codes(flat).shape == (2, 3)


def test_lbp_histograms_count_each_block():
    codes = np.zeros((32, 32), np.uint8)
    codes[:16, 16:] = 3          # top-right block all code 3
    codes[20, 4] = 200           # one pixel of the bottom-left block
    v = F.lbp_histograms(codes)
    assert v.shape == (1024,) and v.sum() == 1024
    assert v[0] == 256 and v[256 + 3] == 256 and v[512 + 0] == 255 and v[512 + 200] == 1 and v[768] == 256


def test_potential_sequences_hand_computed():
    b = np.zeros((4, 4), np.uint8)
    b[0, 1] = 1   # top row: height 4 above the bottom axis, distance 2 from the left axis
    b[3, 1] = 1   # bottom row: height 1
    b[2, 3] = 1   # row 2: height 2, column 3: distance 4
    px, py = F.potential_sequences(b)
    assert px.tolist() == [0, 4 + 1, 0, 2]
    assert py.tolist() == [2, 0, 4, 2]


def test_scale_to_255_eqs_3_4():
    assert F.scale_to_255(np.array([0, 2, 4])).tolist() == [0.0, 127.5, 255.0]
    assert F.scale_to_255(np.zeros(3)).tolist() == [0.0, 0.0, 0.0]


def test_window_features_shape_and_parts_normalised():
    rng = np.random.default_rng(1)
    v = F.window_features(rng.integers(0, 255, (34, 34), dtype=np.uint8),
                          rng.integers(0, 255, (66, 66), dtype=np.uint8), 40.0)
    assert v.shape == (F.FUSED_DIM,)
    assert v[:1024].max() == 255.0 and v[1024:].max() == 255.0 and v.min() >= 0
    with pytest.raises(F.FeatureError):
        F.window_features(np.zeros((32, 32), np.uint8), np.zeros((66, 66), np.uint8), 40.0)


@pytest.mark.parametrize("potentials", ["swept", "from edge pixels"])
@pytest.mark.parametrize("stride", [2, 4, 8, 16])
def test_level_scan_equals_reference_window_by_window(stride, potentials, monkeypatch):
    # both ways of summing the contour potentials (the scan picks one by the level's share of edge words)
    monkeypatch.setattr(F, "SPARSE_EDGE_WORDS", -1.0 if potentials == "swept" else 1.0)
    rng = np.random.default_rng(stride)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (150, 190), dtype=np.uint8), (5, 5), 1.5)
    cv2.rectangle(frame, (40, 30), (90, 60), 230, -1)
    level = (121, 97)
    scan = F.LevelScan(frame, level, stride, "fused", 12.0)
    gl = cv2.resize(frame, level, interpolation=cv2.INTER_AREA)
    gc = cv2.resize(frame, (2 * level[0], 2 * level[1]), interpolation=cv2.INTER_AREA)
    windows = rng.choice(scan.n_windows, min(25, scan.n_windows), replace=False)
    vectors = scan.vectors(windows)
    origins = scan.window_origins(windows)           # the windows' top-left pixels: code position + 1
    assert np.array_equal(origins, scan.window_origins()[windows])
    assert scan.window_origins([]).shape == (0, 2) and scan.window_origins([]).dtype == origins.dtype
    for w, vec, origin in zip(windows, vectors, origins):
        y, x = divmod(int(w), scan.cols)
        y, x = y * stride, x * stride
        assert tuple(origin) == (x + 1, y + 1)
        ref = F.window_features(gl[y:y + 34, x:x + 34], gc[2 * y + 1:2 * y + 67, 2 * x + 1:2 * x + 67], 12.0)
        assert np.array_equal(F.quantised(ref), vec)
    # the compiled cascade loop over the level's tables = the cascade on the reference vectors
    every = scan.vectors(np.arange(scan.n_windows))
    for seed in range(3):
        stages = [_random_stage(np.random.default_rng(100 * stride + 10 * seed + k), every) for k in range(3)]
        cascade = Cascade((32, 32), "fused", 12.0, stages)
        # a scan for detection keeps only the planes of the codes the cascade reads
        kept = F.LevelScan(frame, level, stride, "fused", 12.0, cascade.packed().codes)
        assert len(kept.codes) < F.N_CODES and kept.blocks.shape[0] == len(kept.codes)
        for margin in (0.0, -0.5):
            idx, score = scan.evaluate(cascade.packed(), margin)
            ref_idx, ref_score = cascade.evaluate_vectors(every, margin)
            assert 0 < len(ref_idx) < scan.n_windows     # the stages reject some windows and keep some
            assert np.array_equal(idx, ref_idx) and score == pytest.approx(ref_score, abs=1e-9)
            kept_idx, kept_score = kept.evaluate(cascade.packed(), margin)
            assert np.array_equal(kept_idx, idx) and np.array_equal(kept_score, score)


@pytest.mark.parametrize("shape", [(130, 97), (97, 130), (70, 70), (66, 81), (65, 64), (3, 9)])
@pytest.mark.parametrize("step", [2, 8, 16, 32])
def test_potentials_from_edge_pixels_equal_the_sweeps(shape, step):
    """The sparse path gives the sweeps' potentials to the bit, from blank to full images (rim pixels, whose rows and
    columns lie before the first window, included), on shapes that are no multiple of a word."""
    rng = np.random.default_rng(step * 1000 + shape[0])
    n = F.CONTOUR_SIZE
    rows, cols = max(0, (shape[0] - 4 - n) // step + 1), max(0, (shape[1] - 4 - n) // step + 1)
    for density in (0.0, 0.002, 0.05, 0.5, 1.0):
        b = (rng.random(shape) < density).astype(np.uint8)
        px, py = F._edge_potentials(b, step, rows, cols, n)
        want_px, want_py = F._swept_potentials(b, step, rows, cols, n)
        assert px.shape == want_px.shape == (rows, shape[1]) and py.shape == want_py.shape == (shape[0], cols)
        assert np.array_equal(px, want_px) and np.array_equal(py, want_py)
        if rows and cols and density == 1.0:
            assert px.max() == n * (n + 1) // 2 and py.max() == n * (n + 1) // 2   # a full window's potential
    assert F._edge_words(np.zeros((7, 9), np.uint8)) == 0 and F._edge_words(np.ones((2, 8), np.uint8)) == 2


def test_level_scan_of_some_windows_and_of_levels_resized_already():
    """evaluate(windows=...) keeps the full scan's passing windows among them, in their order; a scan of the two levels
    resized already is the scan of the frame; a contour level not twice the texture level, or a window index outside
    the level, is refused."""
    rng = np.random.default_rng(8)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (150, 190), dtype=np.uint8), (5, 5), 1.5)
    scan = F.LevelScan(frame, (121, 97), 4, "fused", 12.0)
    every = scan.vectors(np.arange(scan.n_windows))
    cascade = Cascade((32, 32), "fused", 12.0, [_random_stage(rng, every)])
    idx, score = scan.evaluate(cascade.packed())
    chosen = rng.permutation(scan.n_windows)[:scan.n_windows // 2]
    some_idx, some_score = scan.evaluate(cascade.packed(), windows=chosen)
    wanted = [w for w in chosen if w in set(idx.tolist())]
    assert 0 < len(wanted) < len(chosen) and np.array_equal(some_idx, wanted)
    assert np.array_equal(some_score, score[np.searchsorted(idx, wanted)])
    texture = cv2.resize(frame, (121, 97), interpolation=cv2.INTER_AREA)
    contour = cv2.resize(frame, (242, 194), interpolation=cv2.INTER_AREA)
    again = F.LevelScan.of_levels(texture, contour, 4, "fused", 12.0)
    assert np.array_equal(again.evaluate(cascade.packed())[0], idx)
    with pytest.raises(F.FeatureError, match="twice"):
        F.LevelScan.of_levels(texture, contour[:-2], 4, "fused", 12.0)
    with pytest.raises(F.FeatureError, match="window indices"):
        scan.evaluate(cascade.packed(), windows=[0, scan.n_windows])


def test_level_scan_refuses_what_its_kept_code_planes_cannot_give():
    """A scan keeping some codes' planes refuses a cascade reading another code, and the full training vectors;
    codes outside 0..255, repeated or unsorted are refused when it is built."""
    rng = np.random.default_rng(3)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (150, 190), dtype=np.uint8), (5, 5), 1.5)
    every = F.LevelScan(frame, (121, 97), 4, "fused", 12.0).vectors(np.arange(10))
    cascade = Cascade((32, 32), "fused", 12.0, [_random_stage(rng, every)])
    codes = cascade.packed().codes
    scan = F.LevelScan(frame, (121, 97), 4, "fused", 12.0, codes[1:])
    with pytest.raises(F.FeatureError, match=f"codes \\[{codes[0]}\\]"):
        scan.evaluate(cascade.packed())
    with pytest.raises(F.FeatureError, match="every code"):
        scan.vectors(np.arange(3))
    for bad in ([-1, 3], [3, 256], [5, 5], [7, 2]):
        with pytest.raises(F.FeatureError, match="distinct sorted"):
            F.LevelScan(frame, (121, 97), 4, "fused", 12.0, bad)


@pytest.mark.parametrize("stride", [2, 4, 8, 16])
def test_level_scan_block_histograms_are_every_blocks_code_counts(stride):
    """The block sweep (``_code_planes``) gives each 16x16 block's code histogram, at every block position of the
    level, and each window's largest bin of its four blocks (eq. 3's maximum); keeping some codes' planes keeps
    those planes and the same maxima (over all 256 codes)."""
    rng = np.random.default_rng(10 + stride)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (130, 170), dtype=np.uint8), (3, 3), 1.0)
    frame[20:50, 30:90] = 200                    # a flat patch: many equal codes, bins near their largest
    level = (103, 87)
    scan = F.LevelScan(frame, level, stride, "lbp", 12.0)
    codes = F.lbp_codes(cv2.resize(frame, level, interpolation=cv2.INTER_AREA))
    planes, by, bx = scan.blocks.shape
    assert planes == F.N_CODES and by > 16 // stride and bx > 16 // stride
    for y in range(by):
        for x in range(bx):
            patch = codes[y * stride:y * stride + F.BLOCK, x * stride:x * stride + F.BLOCK]
            assert np.array_equal(scan.blocks[:, y, x], np.bincount(patch.ravel(), minlength=F.N_CODES))
    per = F.BLOCK // stride
    for w in range(scan.n_windows):
        r, c = divmod(w, scan.cols)
        tops = [scan.blocks[:, r + dy, c + dx].max() for dy in (0, per) for dx in (0, per)]
        assert scan.m_lbp[w] == max(tops)
    rare = np.flatnonzero(np.bincount(codes.ravel(), minlength=F.N_CODES) < 3)[:5]  # maxima not among the kept codes
    kept = F.LevelScan(frame, level, stride, "lbp", 12.0, rare)
    assert np.array_equal(kept.blocks, scan.blocks[rare]) and np.array_equal(kept.m_lbp, scan.m_lbp)


def test_level_scan_cascade_with_thresholds_outside_the_feature_range():
    """Stump thresholds below 0 and above 255 (a hand-made or foreign model): the compiled loop's integer test
    decides them as the cascade does on the normalised vectors (always / never passing)."""
    rng = np.random.default_rng(5)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (150, 190), dtype=np.uint8), (5, 5), 1.5)
    scan = F.LevelScan(frame, (121, 97), 4, "fused", 12.0)
    assert scan.m_lbp.min() > 0 and scan.m_contour.min() > 0     # every window has texture and edges
    every = scan.vectors(np.arange(scan.n_windows))
    stage = _random_stage(rng, every)
    extreme = np.array([-10**6, -3, 0, 255, 256, 300, 10**6, 2**40])
    stage.thresholds[:len(extreme)] = extreme
    for margin in (0.0, -0.5, -3.0):
        idx, score = scan.evaluate(Cascade((32, 32), "fused", 12.0, [stage]).packed(), margin)
        ref_idx, ref_score = Cascade((32, 32), "fused", 12.0, [stage]).evaluate_vectors(every, margin)
        assert np.array_equal(idx, ref_idx) and score == pytest.approx(ref_score, abs=1e-9)
        if margin == 0.0:
            assert 0 < len(ref_idx) < scan.n_windows                 # the stage keeps some windows, not all


@pytest.mark.parametrize("feature_set", ["lbp", "contour"])
def test_level_scan_cascade_of_one_feature_set_equals_the_cascade_on_its_vectors(feature_set):
    """The compiled loop with one set of tables left empty (LBP-only and contour-only models, seed 003's Table 1),
    on a level with a single column of windows and on a wider one."""
    rng = np.random.default_rng(7)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (150, 190), dtype=np.uint8), (5, 5), 1.5)
    for level in ((36, 97), (121, 97)):
        scan = F.LevelScan(frame, level, 4, feature_set, 12.0)
        every = scan.vectors(np.arange(scan.n_windows))
        used = F.feature_range(feature_set)
        varied = used[every[:, used].std(axis=0) > 0]
        for seed in range(3):
            stages = []
            for k in range(2):
                r = np.random.default_rng(10 * seed + k)
                features = r.choice(varied, 8, replace=False)
                thresholds = np.maximum(1, np.median(every[:, features], axis=0).astype(int) + 1)
                left, right = -r.random(8), r.random(8)
                stages.append(Stage(features, thresholds, left, right, float((left + right).sum() / 2)))
            cascade = Cascade((32, 32), feature_set, 12.0, stages)
            idx, score = scan.evaluate(cascade.packed(), 0.0)
            ref_idx, ref_score = cascade.evaluate_vectors(every, 0.0)
            assert np.array_equal(idx, ref_idx) and score == pytest.approx(ref_score, abs=1e-9)


def _random_stage(rng, vectors):
    """A stage of 12 stumps over texture, P_x and P_y features, split at each feature's median so
    that it passes some windows and rejects others."""
    varied = np.flatnonzero(vectors.std(axis=0) > 0)
    texture, contour = varied[varied < 1024], varied[varied >= 1024]
    features = np.concatenate([rng.choice(texture, 6, replace=False), rng.choice(contour, 6, replace=False)])
    thresholds = np.maximum(1, np.median(vectors[:, features], axis=0).astype(int) + 1)
    left, right = -rng.random(len(features)), rng.random(len(features))
    return Stage(features, thresholds, left, right, float((left + right).sum() / 2))


def test_features_never_import_the_cascade():
    """One direction only: cascade -> features (the features module must not import cascade, even for types); the
    package modules it does import (its resize) are leaves that import none."""
    import ast
    import importlib
    from pathlib import Path

    def package_imports(path):
        tree = ast.parse(Path(path).read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | \
            {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        return {m for m in imported if m and m.startswith("multi_target_tracker")}

    imported = package_imports(F.__file__)
    assert "multi_target_tracker.cascade" not in imported
    for module in imported:
        assert not package_imports(importlib.import_module(module).__file__), module


@pytest.mark.parametrize("threshold", [0.0, 0.5, 39.9, 40.0, 40.5, 254.5, 255.0, 300.0])
def test_contour_image_is_the_thresholded_absolute_laplacian(threshold):
    """The saturating OpenCV path (thresholds below 255) and the plain one give |Laplacian| > threshold exactly."""
    rng = np.random.default_rng(int(threshold * 10))
    for gray in (rng.integers(0, 256, (40, 60), dtype=np.uint8),
                 cv2.GaussianBlur(rng.integers(0, 256, (40, 60), dtype=np.uint8), (0, 0), 1.5)):
        lap = cv2.Laplacian(gray, cv2.CV_16S, ksize=1)
        assert np.array_equal(F.contour_image(gray, threshold), (np.abs(lap) > threshold).astype(np.uint8))


@pytest.mark.parametrize("threshold", [0.0, 0.5, 39.9, 40.0, 40.5, 254.5, 255.0, 300.0, 1019.0, 1019.5])
def test_compiled_inner_contour_image_is_the_contour_image_without_its_rim(threshold):
    """The scan's one-pass kernel gives contour_image's pixels exactly, its outermost pixels cleared; a 0/255
    checkerboard reaches the Laplacian's extremes (+-1020), which its int16 sums must hold."""
    rng = np.random.default_rng(int(threshold * 10) + 1)
    checkerboard = (255 * (np.indices((20, 30)).sum(axis=0) % 2)).astype(np.uint8)
    for gray in (rng.integers(0, 256, (41, 67), dtype=np.uint8),
                 cv2.GaussianBlur(rng.integers(0, 256, (40, 60), dtype=np.uint8), (0, 0), 1.5),
                 checkerboard,
                 np.asfortranarray(rng.integers(0, 256, (3, 9), dtype=np.uint8))):
        want = F.contour_image(gray, threshold)
        want[0, :] = want[-1, :] = 0
        want[:, 0] = want[:, -1] = 0
        assert np.array_equal(F._inner_contour_image(gray, float(threshold)), want)


def test_lbp_codes_match_eight_shifted_comparisons():
    """The compiled LBP kernel against the definition (neighbour k sets bit k when >= the centre)."""
    rng = np.random.default_rng(5)
    neighbours = ((-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1))
    for gray in (rng.integers(0, 256, (37, 53), dtype=np.uint8), rng.integers(100, 103, (20, 9), dtype=np.uint8),
                 np.asfortranarray(rng.integers(0, 256, (12, 30), dtype=np.uint8))):
        h, w = gray.shape
        want = np.zeros((h - 2, w - 2), np.uint8)
        for bit, (dy, dx) in enumerate(neighbours):
            want |= (gray[1 + dy:h - 1 + dy, 1 + dx:w - 1 + dx] >= gray[1:-1, 1:-1]).astype(np.uint8) << bit
        assert np.array_equal(F.lbp_codes(gray), want)
