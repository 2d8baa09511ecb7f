"""``area_resize.resize_area`` gives OpenCV's INTER_AREA result to the last bit (the detector's pyramid levels, the
models trained on them)."""
import cv2
import numpy as np
import pytest

from multi_target_tracker.area_resize import area_weights, resize_area


def images(rng, height, width):
    noise = rng.integers(0, 256, (height, width), dtype=np.uint8)
    yield noise
    yield cv2.GaussianBlur(noise, (5, 5), 2.0)
    yield np.where(noise > 128, 255, 0).astype(np.uint8)          # hard edges: half-way sums
    yield np.full((height, width), 255, np.uint8)                   # saturation: weights summing to 1 +- rounding


def test_weights_cover_each_cell_once():
    indices, weights = area_weights(704, 313, 704 / 313)
    assert indices.shape == weights.shape == (313, 4)
    assert np.allclose(weights.sum(axis=1), 1.0, atol=1e-5)        # each destination cell is a mean
    covered = np.zeros(704)
    np.add.at(covered, indices.ravel(), weights.ravel() * (704 / 313))
    assert np.allclose(covered, 1.0, atol=1e-4)                     # each source pixel counted once in all


@pytest.mark.parametrize("source", [(544, 704), (480, 640), (610, 610), (37, 91)])
def test_the_scan_levels_equal_opencv(source):
    """The sizes the detector resizes to (texture level and contour level at each pyramid scale of the UAV set-up's
    48x24 window and the drone-view model's), every shrink among them through the new path."""
    rng = np.random.default_rng(7)
    height, width = source
    sizes = set()
    for window in ((48, 24), (32, 32), (24, 48)):
        scale = 1.0
        while scale < 8:
            level = (max(1, round(width * 32 / (window[0] * scale))), max(1, round(height * 32 / (window[1] * scale))))
            sizes |= {level, (2 * level[0], 2 * level[1])}
            scale *= 1.2
    for image in images(rng, height, width):
        for size in sorted(sizes):
            assert np.array_equal(resize_area(image, size), cv2.resize(image, size, interpolation=cv2.INTER_AREA)), size


def test_random_sizes_equal_opencv():
    """Random images and sizes: shrinks by any factor (whole numbers too), growths, one axis of each, one-pixel
    results, the same size."""
    rng = np.random.default_rng(11)
    for trial in range(400):
        height, width = (int(v) for v in rng.integers(1, 400, 2))
        image = list(images(rng, height, width))[trial % 4]
        kind = trial % 4
        if kind == 0:
            size = (int(rng.integers(1, width + 1)), int(rng.integers(1, height + 1)))
        elif kind == 1:
            size = (int(rng.integers(1, 2 * width + 1)), int(rng.integers(1, 2 * height + 1)))
        elif kind == 2:
            size = (max(1, width // int(rng.integers(1, 5))), max(1, height // int(rng.integers(1, 5))))
        else:
            size = (1, 1) if trial % 8 == 3 else (width, height)
        assert np.array_equal(resize_area(image, size), cv2.resize(image, size, interpolation=cv2.INTER_AREA)), \
            (width, height, size)


def test_a_given_transpose_gives_the_same_bits_and_a_wrong_one_is_not_used():
    """The detector passes each view's transpose (its other orientation) so that every level does not transpose the
    view again: the result is the same; a transpose of the wrong shape or layout is ignored, not read."""
    rng = np.random.default_rng(11)
    gray = cv2.GaussianBlur(rng.integers(0, 256, (123, 157), dtype=np.uint8), (3, 3), 1.0)
    want = cv2.resize(gray, (61, 47), interpolation=cv2.INTER_AREA)
    assert np.array_equal(resize_area(gray, (61, 47), np.ascontiguousarray(gray.T)), want)
    for wrong in (np.zeros((123, 157), np.uint8), gray.T, np.zeros((157, 124), np.uint8)):
        assert np.array_equal(resize_area(gray, (61, 47), wrong), want)
