"""``sensor_msgs/Image`` and ``CompressedImage`` to and from numpy, without cv_bridge.

Reading works on any object with the Image fields (height, width, encoding, is_bigendian, step,
data), so the conversion is testable without ROS; only :func:`numpy_to_image` and
:func:`numpy_to_compressed` build ROS messages. Every failure raises :class:`ImageConversionError`
with the reason: unknown encoding, zero size, a ``step`` shorter than a row, data shorter than
``step * height``, an undecodable compressed payload, and an image larger than ``max_pixels``
(width x height; default :data:`MAX_PIXELS`, a node's ``node.max_image_pixels``). Larger frames are
refused, not downscaled: the outputs' pixel coordinates stay those of the input. A compressed
image's size is read from its PNG / JPEG / BMP header *before* decoding, so a small file that
would decode to 20000x20000 (a decompression bomb) costs nothing; other formats are refused.

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


#: Largest image (width x height pixels) converted by default: 10 MP holds 4K UHD (3840x2160) and
#: DCI 4K (4096x2160). An 8000x8000 frame took the detector 45 s; a 20000x20000 PNG 6 GB.
MAX_PIXELS = 10_000_000


def _check_size(width: int, height: int, max_pixels: int | None, what: str = "image") -> None:
    if max_pixels and width * height > max_pixels:
        raise ImageConversionError(f"{what} {width}x{height} exceeds max_image_pixels={max_pixels}")


_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _check_png_chunks(data: bytes) -> None:
    """Every chunk of a PNG must fit in the data: OpenCV's reader allocates what a chunk's length
    field claims (a flipped bit in a 1 kB file cost 512 MB) before libpng checks anything."""
    pos, end = 8, len(data)
    while pos + 8 <= end:
        length = int.from_bytes(data[pos:pos + 4], "big")
        kind = data[pos + 4:pos + 8]
        if pos + 12 + length > end:
            raise ImageConversionError(f"compressed png is corrupt or truncated: chunk {kind!r} claims {length} "
                                       f"bytes, {max(0, end - pos - 12)} remain")
        pos += 12 + length
        if kind == b"IEND":
            return


def compressed_dimensions(data: bytes) -> tuple[str, int, int] | None:
    """``(format, width, height)`` read from a PNG, JPEG or BMP header without decoding, else None."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24 and data[12:16] == b"IHDR":
        return "png", int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if data[:2] == b"BM" and len(data) >= 26:
        width = int.from_bytes(data[18:22], "little", signed=True)
        height = int.from_bytes(data[22:26], "little", signed=True)
        return "bmp", abs(width), abs(height)
    if data[:2] == b"\xff\xd8":
        pos = 2
        while pos + 4 <= len(data):
            if data[pos] != 0xFF:
                return None
            marker = data[pos + 1]
            if marker == 0xFF:                       # fill byte
                pos += 1
                continue
            if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:   # markers without a length
                pos += 2
                continue
            if marker in (0xD9, 0xDA):               # end of image / start of scan before any frame header
                return None
            length = int.from_bytes(data[pos + 2:pos + 4], "big")
            if marker in _JPEG_SOF:
                if pos + 9 > len(data):
                    return None
                return "jpeg", int.from_bytes(data[pos + 7:pos + 9], "big"), int.from_bytes(data[pos + 5:pos + 7], "big")
            if length < 2:
                return None
            pos += 2 + length
    return None


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


def image_to_numpy(msg, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    """The pixels of an Image as an (H, W) or (H, W, C) array in the encoding's own channel order.

    Row padding (``step``) is dropped, multi-byte samples come out in native byte order, and the
    result never aliases the message buffer. CompressedImage messages are decoded (to BGR/grey).
    Images of more than ``max_pixels`` pixels (0 or None: no limit) are refused.
    """
    if is_compressed(msg):
        return _decode_compressed(msg, max_pixels)
    layout = _layout(msg.encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise ImageConversionError(f"image has zero size ({width}x{height})")
    _check_size(width, height, max_pixels)
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
        finite = np.clip(np.nan_to_num(array, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        return (finite * 255.0).astype(np.uint8)
    return cv2.normalize(array.astype(np.float32), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def to_bgr8(msg, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    """Any supported Image / CompressedImage as an (H, W, 3) uint8 BGR array."""
    if is_compressed(msg):
        image = _decode_compressed(msg, max_pixels)
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image
    layout = _layout(msg.encoding)
    pixels = image_to_numpy(msg, max_pixels)
    if layout.to_bgr is not None:
        if msg.encoding.startswith("bayer_") and pixels.dtype != np.uint8:
            pixels = _scale_to_8bit(pixels)
        if layout.channels == 2 and pixels.shape[1] % 2:
            raise ImageConversionError(f"{msg.encoding}: a 4:2:2 image needs an even width (two pixels share one "
                                       f"chroma pair), got {pixels.shape[1]}")
        try:
            return np.ascontiguousarray(_scale_to_8bit(cv2.cvtColor(pixels, layout.to_bgr)))
        except cv2.error as exc:
            raise ImageConversionError(f"{msg.encoding} ({pixels.shape[1]}x{pixels.shape[0]}) could not be "
                                       f"converted to BGR: {str(exc).strip().splitlines()[-1]}") from None
    pixels = _scale_to_8bit(pixels)
    if pixels.ndim == 2:
        return cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)
    if pixels.shape[2] == 3:
        return pixels
    if pixels.shape[2] == 4:
        return cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
    raise ImageConversionError(f"cannot show {msg.encoding} ({pixels.shape[2]} channels) as BGR")


def to_mono8(msg, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    """Any supported Image / CompressedImage as an (H, W) uint8 grey array."""
    if is_compressed(msg):
        image = _decode_compressed(msg, max_pixels)
        return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    layout = _layout(msg.encoding)
    pixels = image_to_numpy(msg, max_pixels)
    if pixels.ndim == 2 and layout.to_gray is None:
        return _scale_to_8bit(pixels)
    if layout.to_gray is not None:
        if pixels.dtype != np.uint8:
            pixels = _scale_to_8bit(pixels)
        return cv2.cvtColor(pixels, layout.to_gray)
    return cv2.cvtColor(to_bgr8(msg, max_pixels), cv2.COLOR_BGR2GRAY)


def to_mono8_or_bgr8(msg, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    """Any supported Image / CompressedImage with its colour if it has any: (H, W) uint8 grey for a grey raw
    image, else (H, W, 3) uint8 BGR (Bayer images are demosaiced; a compressed image is decoded as ``to_bgr8``)."""
    if not is_compressed(msg) and _layout(msg.encoding).channels == 1 and not msg.encoding.startswith("bayer_"):
        return to_mono8(msg, max_pixels)
    return to_bgr8(msg, max_pixels)


def _decode_compressed(msg, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    raw = bytes(msg.data)
    if not raw:
        raise ImageConversionError("compressed image has no data")
    header = compressed_dimensions(raw)
    if header is None:
        raise ImageConversionError(f"compressed image ({msg.format or 'no format'}) could not be decoded: not "
                                   "PNG, JPEG or BMP (no readable size in its header)")
    kind, width, height = header
    if width <= 0 or height <= 0:
        raise ImageConversionError(f"compressed {kind} header gives zero size ({width}x{height})")
    _check_size(width, height, max_pixels, f"compressed {kind}")
    if kind == "png":
        _check_png_chunks(raw)
    try:
        image = cv2.imdecode(np.frombuffer(raw, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageConversionError(f"compressed {kind} could not be decoded: {str(exc).strip().splitlines()[-1]}") from None
    if image is None:
        raise ImageConversionError(f"compressed image ({msg.format or 'no format'}) could not be decoded")
    _check_size(image.shape[1], image.shape[0], max_pixels, f"decoded {kind}")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    elif image.ndim == 3 and image.shape[2] != 3:     # grey + alpha
        image = np.ascontiguousarray(image[:, :, 0])
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
