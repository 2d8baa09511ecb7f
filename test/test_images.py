"""Image conversion for every encoding PRODUCT.md lists, padding, byte order, malformed input."""
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from aircraft_docking_tracker.images import (
    ENCODINGS, ImageConversionError, image_to_numpy, numpy_to_compressed, numpy_to_image, to_bgr8, to_mono8,
    to_mono8_or_bgr8)

RNG = np.random.default_rng(0)
BGR = RNG.integers(0, 256, size=(6, 8, 3), dtype=np.uint8)


def fake(array: np.ndarray, encoding: str, *, pad: int = 0, bigendian: bool = False):
    """A duck-typed Image with ``pad`` bytes of row padding, in either byte order."""
    array = np.asarray(array)
    height, width = array.shape[:2]
    raw = array.astype(array.dtype.newbyteorder(">" if bigendian else "<")).reshape(height, -1).view(np.uint8)
    rows = np.concatenate([raw, np.full((height, pad), 0xAB, np.uint8)], axis=1)
    return SimpleNamespace(height=height, width=width, encoding=encoding, is_bigendian=int(bigendian),
                           step=rows.shape[1], data=rows.tobytes())


@pytest.mark.parametrize("encoding, make", [
    ("bgr8", lambda: BGR), ("rgb8", lambda: BGR[:, :, ::-1]),
    ("bgra8", lambda: cv2.cvtColor(BGR, cv2.COLOR_BGR2BGRA)), ("rgba8", lambda: cv2.cvtColor(BGR, cv2.COLOR_BGR2RGBA)),
    ("bgr16", lambda: BGR.astype(np.uint16) << 8), ("rgb16", lambda: (BGR[:, :, ::-1].astype(np.uint16) << 8)),
])
@pytest.mark.parametrize("pad", [0, 5])
def test_colour_encodings_give_the_same_bgr(encoding, make, pad):
    np.testing.assert_array_equal(to_bgr8(fake(make(), encoding, pad=pad)), BGR)


def test_mono8_or_bgr8_keeps_a_grey_image_grey_and_a_colour_one_in_colour():
    """What the docking node tracks: grey stays (H, W) as to_mono8 gives it, colour comes as to_bgr8's BGR (its
    grey conversion is to_mono8's for 8-bit colour), a compressed image as to_bgr8 decodes it."""
    grey = RNG.integers(0, 256, size=(5, 7), dtype=np.uint8)
    np.testing.assert_array_equal(to_mono8_or_bgr8(fake(grey, "mono8")), grey)
    for encoding, make in (("bgr8", BGR), ("rgb8", BGR[:, :, ::-1])):
        frame = to_mono8_or_bgr8(fake(make, encoding, pad=3))
        np.testing.assert_array_equal(frame, BGR)
        np.testing.assert_array_equal(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), to_mono8(fake(make, encoding)))
    bayer = to_mono8_or_bgr8(fake(RNG.integers(0, 256, size=(6, 8), dtype=np.uint8), "bayer_rggb8"))
    assert bayer.shape == (6, 8, 3)
    compressed = numpy_to_compressed(BGR, "png")
    np.testing.assert_array_equal(to_mono8_or_bgr8(compressed), to_bgr8(compressed))


def test_an_odd_width_422_image_has_grey_but_no_colour():
    """4:2:2 packs two pixels per chroma pair: at an odd width its luma is still grey, its colour is a clear
    conversion error, not OpenCV's assertion (the fuzz test found it through the docking node)."""
    packed = RNG.integers(0, 256, size=(4, 5, 2), dtype=np.uint8)
    for encoding in ("yuv422", "yuv422_yuy2"):
        assert to_mono8(fake(packed, encoding)).shape == (4, 5)
        with pytest.raises(ImageConversionError, match="even width"):
            to_bgr8(fake(packed, encoding))
        with pytest.raises(ImageConversionError, match="even width"):
            to_mono8_or_bgr8(fake(packed, encoding))


def test_mono8_and_mono16_big_endian():
    grey = RNG.integers(0, 65536, size=(5, 7), dtype=np.uint16)
    for big in (False, True):
        msg = fake(grey, "mono16", pad=3, bigendian=big)
        np.testing.assert_array_equal(image_to_numpy(msg), grey)
        np.testing.assert_array_equal(to_mono8(msg), (grey >> 8).astype(np.uint8))
    mono = grey.astype(np.uint8)
    np.testing.assert_array_equal(to_mono8(fake(mono, "mono8", pad=1)), mono)


def test_float_depth_with_nan_is_finite():
    depth = np.array([[0.5, np.nan], [np.inf, 0.25]], np.float32)
    out = to_mono8(fake(depth, "32FC1"))
    assert out.dtype == np.uint8 and out[0, 0] == 127 and out[0, 1] == 0


@pytest.mark.parametrize("encoding, cv_code", [("yuv422", cv2.COLOR_YUV2BGR_UYVY), ("uyvy", cv2.COLOR_YUV2BGR_UYVY),
                                               ("yuv422_yuy2", cv2.COLOR_YUV2BGR_YUY2), ("yuyv", cv2.COLOR_YUV2BGR_YUY2)])
def test_yuv422_variants(encoding, cv_code):
    packed = RNG.integers(16, 235, size=(4, 6, 2), dtype=np.uint8)
    np.testing.assert_array_equal(to_bgr8(fake(packed, encoding, pad=4)), cv2.cvtColor(packed, cv_code))


def test_yuv_uyvy_of_grey_is_grey():
    uyvy = np.zeros((2, 4, 2), np.uint8)
    uyvy[:, :, 0], uyvy[:, :, 1] = 128, 200  # U/V neutral, luma 200
    bgr = to_bgr8(fake(uyvy, "yuv422"))
    assert np.all(np.abs(bgr.astype(int) - bgr[..., :1].astype(int)) <= 1)


@pytest.mark.parametrize("pattern, offsets", [("rggb", (0, 0)), ("bggr", (1, 1)), ("gbrg", (1, 0)), ("grbg", (0, 1))])
def test_bayer_pattern_of_a_red_scene_decodes_to_red(pattern, offsets):
    """A flat red scene: only the R photosites of the mosaic are lit, wherever the pattern puts them."""
    mosaic = np.zeros((8, 8), np.uint8)
    row, col = offsets
    mosaic[row::2, col::2] = 200
    bgr = to_bgr8(fake(mosaic, f"bayer_{pattern}8"))
    centre = bgr[2:6, 2:6].reshape(-1, 3).mean(axis=0)
    assert centre[2] > 150 and centre[0] < 30 and centre[1] < 30, (pattern, centre)
    mosaic16 = mosaic.astype(np.uint16) << 8
    np.testing.assert_array_equal(to_bgr8(fake(mosaic16, f"bayer_{pattern}16")), bgr)


def test_every_listed_encoding_is_known():
    for name in ("mono8", "mono16", "bgr8", "rgb8", "bgra8", "rgba8", "yuv422", "yuv422_yuy2",
                 "bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8", "bayer_rggb16", "32FC1", "16UC1"):
        assert name in ENCODINGS


@pytest.mark.parametrize("change, reason", [
    ({"encoding": "bgr9"}, "unknown image encoding"),
    ({"height": 0}, "zero size"),
    ({"step": 4}, "shorter than one row"),
    ({"data": b"\x00" * 10}, "needs"),
])
def test_malformed_images_raise_one_clear_error(change, reason):
    msg = fake(BGR, "bgr8")
    for key, value in change.items():
        setattr(msg, key, value)
    with pytest.raises(ImageConversionError, match=reason):
        to_bgr8(msg)


def test_round_trip_through_real_messages():
    msg = numpy_to_image(BGR, "bgr8")
    assert (msg.step, msg.encoding, msg.is_bigendian) == (24, "bgr8", 0)
    np.testing.assert_array_equal(image_to_numpy(msg), BGR)
    grey16 = RNG.integers(0, 65536, size=(3, 4), dtype=np.uint16)
    np.testing.assert_array_equal(image_to_numpy(numpy_to_image(grey16, "mono16")), grey16)
    with pytest.raises(ImageConversionError, match="does not fit"):
        numpy_to_image(BGR, "mono8")


def test_compressed_round_trip_and_garbage():
    png = numpy_to_compressed(BGR, "png")
    np.testing.assert_array_equal(to_bgr8(png), BGR)
    np.testing.assert_array_equal(to_mono8(png), cv2.cvtColor(BGR, cv2.COLOR_BGR2GRAY))
    png.data = b"not an image"
    with pytest.raises(ImageConversionError, match="could not be decoded"):
        to_bgr8(png)
