"""``sensor_msgs/Image`` and ``CompressedImage`` to and from numpy, without cv_bridge.

Reading works on any object with the Image fields (height, width, encoding, is_bigendian, step,
data), so the conversion is testable without ROS; only :func:`numpy_to_image` and
:func:`numpy_to_compressed` build ROS messages. Every failure raises :class:`ImageConversionError`
with the reason: unknown encoding, zero size, a ``step`` shorter than a row, data shorter than
``step * height``, an undecodable compressed payload.

Encodings: ``mono8 mono16 bgr8 rgb8 bgra8 rgba8 bgr16 rgb16 bgra16 rgba16``, ``8UC1..4``,
``8SC1``, ``16UC1..4``, ``16SC1``, ``32SC1``, ``32FC1..4``, ``64FC1``, the packed 4:2:2 formats
``yuv422``/``uyvy`` (UYVY) and ``yuv422_yuy2``/``yuyv`` (YUYV), and Bayer ``bayer_{rggb,bggr,
gbrg,grbg}{8,16}``. Bayer pattern names follow ROS (the colour of the top-left pixels); OpenCV
names its codes after the second row, hence the mapping below (the same one cv_bridge uses).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


class ImageConversionError(ValueError):
    """An image message that cannot be converted; the message says why."""


@dataclass(frozen=True)
class _Layout:
    dtype: str  # numpy dtype (native order; the message's byte order is handled separately)
    channels: int
    to_bgr: int | None = None  # cv2 conversion code to BGR (None: already BGR / grey)
    to_gray: int | None = None  # cv2 conversion code to single-channel grey


_BAYER_TO_BGR = {"rggb": cv2.COLOR_BayerBG2BGR, "bggr": cv2.COLOR_BayerRG2BGR,
                 "gbrg": cv2.COLOR_BayerGR2BGR, "grbg": cv2.COLOR_BayerGB2BGR}
_BAYER_TO_GRAY = {"rggb": cv2.COLOR_BayerBG2GRAY, "bggr": cv2.COLOR_BayerRG2GRAY,
                  "gbrg": cv2.COLOR_BayerGR2GRAY, "grbg": cv2.COLOR_BayerGB2GRAY}


def _layouts() -> dict[str, _Layout]:
    table = {
        "mono8": _Layout("u1", 1), "mono16": _Layout("u2", 1),
        "bgr8": _Layout("u1", 3, None, cv2.COLOR_BGR2GRAY), "rgb8": _Layout("u1", 3, cv2.COLOR_RGB2BGR, cv2.COLOR_RGB2GRAY),
        "bgra8": _Layout("u1", 4, cv2.COLOR_BGRA2BGR, cv2.COLOR_BGRA2GRAY),
        "rgba8": _Layout("u1", 4, cv2.COLOR_RGBA2BGR, cv2.COLOR_RGBA2GRAY),
        "bgr16": _Layout("u2", 3, None, cv2.COLOR_BGR2GRAY), "rgb16": _Layout("u2", 3, cv2.COLOR_RGB2BGR, cv2.COLOR_RGB2GRAY),
        "bgra16": _Layout("u2", 4, cv2.COLOR_BGRA2BGR, cv2.COLOR_BGRA2GRAY),
        "rgba16": _Layout("u2", 4, cv2.COLOR_RGBA2BGR, cv2.COLOR_RGBA2GRAY),
        "yuv422": _Layout("u1", 2, cv2.COLOR_YUV2BGR_UYVY, cv2.COLOR_YUV2GRAY_UYVY),
        "uyvy": _Layout("u1", 2, cv2.COLOR_YUV2BGR_UYVY, cv2.COLOR_YUV2GRAY_UYVY),
        "yuv422_yuy2": _Layout("u1", 2, cv2.COLOR_YUV2BGR_YUY2, cv2.COLOR_YUV2GRAY_YUY2),
        "yuyv": _Layout("u1", 2, cv2.COLOR_YUV2BGR_YUY2, cv2.COLOR_YUV2GRAY_YUY2),
    }
    for pattern in _BAYER_TO_BGR:
        for bits, dtype in (("8", "u1"), ("16", "u2")):
            table[f"bayer_{pattern}{bits}"] = _Layout(dtype, 1, _BAYER_TO_BGR[pattern], _BAYER_TO_GRAY[pattern])
    for depth, dtype in (("8U", "u1"), ("8S", "i1"), ("16U", "u2"), ("16S", "i2"), ("32S", "i4"),
                         ("32F", "f4"), ("64F", "f8")):
        for channels in (1, 2, 3, 4):
            table[f"{depth}C{channels}"] = _Layout(dtype, channels)
    return table


LAYOUTS = _layouts()
ENCODINGS = tuple(sorted(LAYOUTS))


def _layout(encoding: str) -> _Layout:
    try:
        return LAYOUTS[encoding]
    except KeyError:
        raise ImageConversionError(f"unknown image encoding {encoding!r}") from None


def is_compressed(msg) -> bool:
    return hasattr(msg, "format") and not hasattr(msg, "encoding")


def image_to_numpy(msg) -> np.ndarray:
    """The pixels of an Image as an (H, W) or (H, W, C) array in the encoding's own channel order.

    Row padding (``step``) is dropped, multi-byte samples come out in native byte order, and the
    result never aliases the message buffer. CompressedImage messages are decoded (to BGR/grey).
    """
    if is_compressed(msg):
        return _decode_compressed(msg)
    layout = _layout(msg.encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise ImageConversionError(f"image has zero size ({width}x{height})")
    item = np.dtype(layout.dtype).itemsize
    row_bytes = width * layout.channels * item
    if step < row_bytes:
        raise ImageConversionError(f"step {step} is shorter than one row of {width} {msg.encoding} pixels ({row_bytes} bytes)")
    buffer = _as_bytes(msg.data)
    if len(buffer) < step * (height - 1) + row_bytes:
        raise ImageConversionError(
            f"data has {len(buffer)} bytes, a {width}x{height} {msg.encoding} image with step {step} needs {step * height}")
    dtype = np.dtype(layout.dtype).newbyteorder(">" if msg.is_bigendian else "<")
    rows = np.frombuffer(buffer, dtype=np.uint8, count=step * (height - 1) + row_bytes)
    rows = np.lib.stride_tricks.as_strided(rows, shape=(height, row_bytes), strides=(step, 1))
    pixels = np.ascontiguousarray(rows).view(dtype).reshape(height, width, layout.channels)
    pixels = pixels.astype(dtype.newbyteorder("="), copy=False)
    return pixels[:, :, 0] if layout.channels == 1 else pixels


def _as_bytes(data) -> memoryview:
    try:
        return memoryview(data).cast("B")
    except TypeError:  # a plain list of ints
        return memoryview(bytes(data))


def _scale_to_8bit(array: np.ndarray) -> np.ndarray:
    if array.dtype == np.uint8:
        return array
    if array.dtype == np.uint16:
        return (array >> 8).astype(np.uint8)
    if array.dtype.kind == "f":
        finite = np.nan_to_num(array, nan=0.0, posinf=1.0, neginf=0.0)
        return np.clip(finite * 255.0, 0, 255).astype(np.uint8)
    return cv2.normalize(array.astype(np.float32), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def to_bgr8(msg) -> np.ndarray:
    """Any supported Image / CompressedImage as an (H, W, 3) uint8 BGR array."""
    if is_compressed(msg):
        image = _decode_compressed(msg)
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image
    layout = _layout(msg.encoding)
    pixels = image_to_numpy(msg)
    if layout.to_bgr is not None:
        if msg.encoding.startswith("bayer_") and pixels.dtype != np.uint8:
            pixels = _scale_to_8bit(pixels)
        return np.ascontiguousarray(_scale_to_8bit(cv2.cvtColor(pixels, layout.to_bgr)))
    pixels = _scale_to_8bit(pixels)
    if pixels.ndim == 2:
        return cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)
    if pixels.shape[2] == 3:
        return pixels
    if pixels.shape[2] == 4:
        return cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
    raise ImageConversionError(f"cannot show {msg.encoding} ({pixels.shape[2]} channels) as BGR")


def to_mono8(msg) -> np.ndarray:
    """Any supported Image / CompressedImage as an (H, W) uint8 grey array."""
    if is_compressed(msg):
        image = _decode_compressed(msg)
        return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    layout = _layout(msg.encoding)
    pixels = image_to_numpy(msg)
    if pixels.ndim == 2 and layout.to_gray is None:
        return _scale_to_8bit(pixels)
    if layout.to_gray is not None:
        if pixels.dtype != np.uint8:
            pixels = _scale_to_8bit(pixels)
        return cv2.cvtColor(pixels, layout.to_gray)
    return cv2.cvtColor(to_bgr8(msg), cv2.COLOR_BGR2GRAY)


def _decode_compressed(msg) -> np.ndarray:
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if data.size == 0:
        raise ImageConversionError("compressed image has no data")
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ImageConversionError(f"compressed image ({msg.format or 'no format'}) could not be decoded")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return _scale_to_8bit(image)


def numpy_to_image(array: np.ndarray, encoding: str, header=None):
    """A ``sensor_msgs/Image`` holding ``array`` (no padding, little-endian)."""
    from sensor_msgs.msg import Image  # noqa: PLC0415

    layout = _layout(encoding)
    array = np.asarray(array)
    expected_ndim = 2 if layout.channels == 1 else 3
    if array.ndim == 3 and layout.channels == 1 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim != expected_ndim or (expected_ndim == 3 and array.shape[2] != layout.channels):
        raise ImageConversionError(f"array of shape {array.shape} does not fit encoding {encoding} ({layout.channels} channels)")
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise ImageConversionError(f"array of shape {array.shape} has zero size")
    if array.dtype != np.dtype(layout.dtype):
        raise ImageConversionError(f"array of dtype {array.dtype} does not fit encoding {encoding} ({layout.dtype})")
    array = np.ascontiguousarray(array, dtype=np.dtype(layout.dtype).newbyteorder("<"))
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(array.shape[0]), int(array.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(array.shape[1] * layout.channels * array.dtype.itemsize)
    msg.data = array.tobytes()
    return msg


def numpy_to_compressed(array: np.ndarray, fmt: str = "jpeg", header=None, quality: int = 90):
    """A ``sensor_msgs/CompressedImage`` (jpeg or png) of a BGR or grey uint8 array."""
    from sensor_msgs.msg import CompressedImage  # noqa: PLC0415

    ext = {"jpeg": ".jpg", "jpg": ".jpg", "png": ".png"}.get(fmt.lower())
    if ext is None:
        raise ImageConversionError(f"compressed format must be jpeg or png, not {fmt!r}")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if ext == ".jpg" else []
    ok, encoded = cv2.imencode(ext, np.asarray(array), params)
    if not ok:
        raise ImageConversionError(f"OpenCV could not encode a {array.shape} array as {fmt}")
    msg = CompressedImage()
    if header is not None:
        msg.header = header
    msg.format = "jpeg" if ext == ".jpg" else "png"
    msg.data = encoded.tobytes()
    return msg
