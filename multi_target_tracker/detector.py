"""Detector core: backend choice, pyramid scan of the boosted cascade, grouping -> detection table.

Pure (numpy + OpenCV). The node, the ``detect`` tool, the trainer's negative mining and the
benchmark all call :class:`Detector` (or :func:`scan_cascade` for raw windows).

Scan (seed 003 §2: "run over the frame to search for targets"): the model window ``(w0, h0)``
pixels is searched at scales ``s = s_min * scale_factor^k`` between ``min_size`` and ``max_size``
(window heights in pixels). At each scale the frame is resized so that one window becomes 32x32
(texture level; the contour level is twice that) and every window on a ``stride``-pixel grid of
that level is scored at once by :class:`features.LevelScan` (its tables and compiled cascade loop).
With ``orientation = both`` the transposed frame is scanned too (objects turned by 90 degrees,
e.g. cars along the other street axis seen from a UAV).
With ``angles`` (default ``[0]``) the frame is also scanned turned by each angle about its centre
(:func:`turned_view`, on a canvas that holds all of it): a model trained on heading-aligned vehicles
(the UAV set-up's) then meets vehicles at any heading within half an angle step of one of its views;
each window of a turned view is mapped back as the upright box of its turned corners
(:func:`map_back`), the box the ground truth gives a turned vehicle, before grouping. ``turned_crop`` scans only
the central square of each turned view's canvas (half of a 45-degree canvas is reflected border).
With ``blob_views`` each colour blob of the frame (:mod:`blob_views`) is scanned too, on its own canvas turned onto
the window's axis at the one scale that frames it as the model's training chips framed a vehicle; its windows join
the scan's before grouping, so a vehicle between the fixed headings or grid positions still gathers a group.

Grouping (:func:`group_windows`, after OpenCV's ``groupRectangles``): a cascade fires on many
windows around one object, shifted by the stride and a scale step. Windows are taken best
last-stage margin first; each still-free window gathers every free window overlapping it by
``group_iou`` into a group, whose box is the *mean* of its members (better placed than any one
window on the stride grid) and whose score is

    score = n + 1 / (1 + exp(-m))      (n windows in the group, m the best member's margin)

so the integer part is OpenCV's neighbour count and the fraction orders groups of equal size.
With ``group_shape = turned`` the overlap is that of the windows' own rectangles as their views turned
them (:func:`map_back` keeps those corners): two vehicles side by side at 45 degrees have upright boxes
that overlap by far more than the vehicles do, and their windows would fall into one group.
Groups with fewer than ``min_neighbors`` windows are dropped, then every group lying at least
``containment`` inside a better one (intersection over the smaller area) is suppressed: vehicles
seen from above or an aircraft on a stand do not overlap, but a window on half a car does.
``suppression_iou`` < 1 also drops a group overlapping a better one by that IoU (greedy non-maximum
suppression); with ``containment`` 1 it keeps overlapping objects that containment would merge.
Last, ``box_scale`` scales each box about its centre: a cascade trained on object-centred boxes
also passes windows a little inside the object (their texture is the object's), so the mean
window can sit inside it; the UAV set-up calibrates this on its tuning scenes.
With a colour ``verifier`` (the UAV set-up's, :mod:`verifier`) the groups of at least ``min_neighbors``
windows are kept by its log odds instead of their count, and a ``box_regressor`` (:mod:`box_regression`)
then moves each kept group's box edges by offsets predicted from where its member windows lie; without a
verifier a ``box_regressor`` moves the boxes of the groups of at least ``min_neighbors`` windows the same way
(before containment; measured on the drone-view prefix folds by ``bench/detector.py --box-regression``).
A box regressor with image stages (``box_regression.ImageStage``) then moves the verified groups' boxes again
from what the colour image shows around them; it needs the verifier (colour images).
A ``patch_net`` (:mod:`patch_net`, also after a verifier) reads each group's colour patch around its box: its log
odds are added to the verifier's before ``verifier_threshold`` applies, and its box replaces the group's (so the
configuration refuses a box regressor with image stages beside it: both would place the box).
On the drone-view tiles this grouping, against keeping the best window of each cluster, took
detection at <= 10 % false alarms from 70 % to 91 % with the same cascade (bench/README.md).
"""
from __future__ import annotations

import itertools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import cv2
import numba
import numpy as np
from scipy.special import expit

from aircraft_docking_tracker.config import ConfigError, param
from aircraft_docking_tracker.geometry import box_to_quad, scale_boxes
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, FLAGGED_DETECTION_DTYPE, LOW_CONFIDENCE
from multi_target_tracker import blob_views
from multi_target_tracker.cascade import MAX_STUMPS, MIN_WINDOW, Cascade, CascadeError
from multi_target_tracker.area_resize import resize_area
from multi_target_tracker.features import LBP_SIZE, FeatureError, LevelScan, grid_origins, window_grid
from multi_target_tracker.heading import turned_canvas
from multi_target_tracker.box_regression import BoxRegressor, BoxRegressorError, member_features
from multi_target_tracker.patch_net import PatchNet, PatchNetError
from multi_target_tracker.verifier import TreeVerifier, Verifier, VerifierError, features, load_verifier_model

MODELS_DIR = Path(__file__).resolve().parent / "models"
DEFAULT_MODEL = "drone_vehicles_fused.json"
NEVER_EXEMPT = 50.0    # containment_exempt_log_odds that exempts no group (the top of its range)
EVERY_GROUP = -50.0    # patch_net_floor that shows every group to the patch network (the bottom of its range)


class DetectorError(ValueError):
    """Bad detector input (image, region of interest) or configuration."""


class _Job(NamedTuple):
    """One scan of :meth:`Detector.raw`: a view (or blob canvas) at one scale; the jobs of one ``key`` (a turned view's
    levels, both orientations; -1 the blob views) are mapped back to the frame at once."""

    image: np.ndarray
    transposed: bool                 # the view is the frame's transpose: its windows' x and y swap back
    back: np.ndarray | None          # the view's 2x3 map back to the frame (None: the frame itself)
    scale: float
    stride: int
    key: int
    image_transposed: np.ndarray | None   # the view's transpose, when the detector has it (the other orientation)


class Windows(NamedTuple):
    """The windows a cascade passes in one frame (:meth:`Detector.raw`): their upright boxes ``(n, 4)`` x, y, w, h
    in the frame, last-stage margins ``(n,)`` and turned corners ``(n, 4, 2)`` (the window's own rectangle as its
    view turned it; the box's corners for an upright view)."""

    boxes: np.ndarray
    margins: np.ndarray
    quads: np.ndarray


@dataclass
class DetectorConfig:
    """Detector constants: model, backend, pyramid, grouping, region of interest."""

    backend: str = param("cascade", "cascade: our seed 003 boosted cascade (JSON model); opencv: a "
                         "cv2.CascadeClassifier XML (Haar/LBP)", choices=("cascade", "opencv"))
    model: str = param(DEFAULT_MODEL, "model file; a bare name is looked up in multi_target_tracker/models")
    scale_factor: float = param(1.2, "pyramid step between window scales", low=1.01, high=3.0)
    stride: int = param(4, "window step in texture-level pixels (one window = 32 px)", choices=(2, 4, 8))
    min_size: float = param(0.0, "smallest window height searched [px] (0: the range the model was trained "
                            "for, else its window)", low=0.0, high=10000.0)
    max_size: float = param(0.0, "largest window height searched [px] (0: the range the model was trained "
                            "for, else up to the frame)", low=0.0, high=10000.0)
    orientation: str = param("model", "also scan the transposed frame: model (as trained), upright, both",
                             choices=("model", "upright", "both"))
    angles: list = param([0.0], "scan the frame turned by each of these angles [deg] (with orientation both, "
                         "each also transposed: angles [0, 45] look along 0, 45, 90 and 135 degrees, for a model "
                         "trained on heading-aligned vehicles); a turned view's windows are mapped back as the "
                         "upright boxes of the turned windows; cascade backend only")
    border: int = param(0, "reflected border [px] added around the upright frame (and its transpose) before the "
                        "scan, so that windows may reach past the image edge onto a vehicle the frame cuts; their "
                        "boxes are clipped to the frame and windows centred outside it dropped, as in the turned "
                        "views, whose canvases hold reflected borders already; 0: windows inside the frame only",
                        low=0, high=256)
    blob_views: bool = param(False, "also scan each colour blob of the frame (an MSER region of the colour's "
                             "distance from the ground around it, rectangle-shaped) along its own axis, at the one "
                             "scale that frames it as the model's training chips framed a vehicle; its windows join "
                             "the scan's before grouping (blob_views.py; needs colour images and a model trained on "
                             "objects along its window: the UAV set-up's heading-aligned chips, the drone-view "
                             "model's boxes)")
    blob_background: float = param(122.0, "side of the square around each pixel whose mean colour is its ground, "
                                   "for blob_views [px]", low=8.0, high=2000.0)
    blob_min_fill: float = param(0.5, "share of its rotated bounding rectangle a colour region must fill to be a "
                                 "blob (blob_views)", low=0.0, high=1.0)
    blob_context: float = param(1.25, "the blob's window holds its length x width (reshaped to the window's aspect) "
                                "enlarged this many times: the context of the model's training chips (blob_views)",
                                low=1.0, high=4.0)
    blob_scale: float = param(0.5, "the blobs are looked for at this share of the frame's size (blob_views; the "
                              "cost goes with its square: keep the smallest wanted blob's width above ~8 px there)",
                              low=0.05, high=1.0)
    turned_crop: float = param(0.0, "scan only the central square of each turned view (angles other than 0), of "
                               "this many times the square root of the frame's area a side (a 640x480 frame turned "
                               "45 degrees fills half of its 792-px canvas; 1.1: a 610-px square, 0.59 of the "
                               "canvas); 0: the whole canvas", low=0.0, high=4.0)
    group_iou: float = param(0.3, "a window joins a group when it overlaps the group's best window by this "
                             "IoU", low=0.0, high=1.0)
    group_shape: str = param("upright", "what group_iou compares: upright (each window's upright box in the frame) or "
                             "turned (the window's own rectangle as its view turned it: two vehicles side by side at "
                             "45 degrees overlap far less than their upright boxes do)", choices=("upright", "turned"))
    min_neighbors: int = param(3, "windows a group needs to be a detection (OpenCV's minNeighbors); the "
                               "detection score is this count plus a fraction (the drone-view set-up's, "
                               "config/detector.yaml, is chosen by k-fold by video over three training seeds)",
                               low=1, high=100)
    containment: float = param(0.4, "drop a group lying this much inside a better one (intersection over the "
                               "smaller box; 1: never)", low=0.0, high=1.0)
    suppression_iou: float = param(1.0, "also drop a group overlapping a better one by this IoU (non-maximum "
                                   "suppression; 1: never)", low=0.0, high=1.0)
    containment_exempt_log_odds: float = param(NEVER_EXEMPT, "a verified group whose log odds (verifier and patch network "
                                               "summed) reach this is not dropped by containment, only by "
                                               "suppression_iou: one the verifier is that sure of, half inside a "
                                               "better one, is taken as a vehicle beside it (vehicles that overlap "
                                               "in the image); needs the verifier; 50: never", low=-50.0, high=NEVER_EXEMPT)
    window_margin: float = param(-0.5, "minimum last-stage margin of a window (0: the trained cascade; <0 more "
                                 "windows, >0 fewer; the drone-view set-up's, config/detector.yaml, is chosen with "
                                 "min_neighbors)", low=-100.0, high=100.0)
    box_scale: float = param(1.0, "each detection box is scaled about its centre by this factor (a cascade fires "
                             "most on windows a little inside the object; 1: the grouped windows as they are; the "
                             "UAV set-up's is chosen on tuning scenes)", low=0.25, high=4.0)
    verifier: str = param("", "colour verifier of the groups (JSON model; a bare name is looked up in "
                          "multi_target_tracker/models; empty: none): groups of at least min_neighbors windows are "
                          "kept when its log odds reach verifier_threshold, the detection score is then its "
                          "probability; needs colour images and the cascade backend (the UAV set-up's)")
    verifier_threshold: float = param(0.0, "log odds a group needs from the verifier to be a detection (chosen on "
                                      "tuning scenes)", low=-50.0, high=50.0)
    low_confidence_band: float = param(0.0, "groups whose verifier log odds lie less than this below "
                                       "verifier_threshold are published too, flagged low_confidence (the table's "
                                       "extra field), for the association's second pass (ByteTrack); scored by "
                                       "their probability like the others; 0: none, the table without the field",
                                       low=0.0, high=50.0)
    box_regressor: str = param("", "box regressor of the groups (JSON model; a bare name is looked up in "
                               "multi_target_tracker/models; empty: none): moves each edge of a group's mean box by "
                               "an offset predicted from its member windows, before containment and box_scale; "
                               "cascade backend only (the UAV set-up's, after its verifier); a model with image "
                               "stages then moves the groups the verifier accepts again, from the colour image "
                               "around each box (needs the verifier)")
    patch_net: str = param("", "patch network of the groups (JSON header of an ONNX graph; a bare name is looked up in "
                           "multi_target_tracker/models; empty: none): a small CNN reads each group's colour patch "
                           "around its box (after the box regressor's member statistics), its log odds are added to "
                           "the verifier's before verifier_threshold applies and its box is published, cut to the "
                           "frame; needs the verifier and a box regressor without image stages (if any)")
    patch_net_floor: float = param(EVERY_GROUP, "groups whose verifier log odds (before the patch network's are added) "
                                   "lie below this are rejected without the network, which costs about 0.5 ms a group "
                                   "(one core); at most verifier_threshold - low_confidence_band; -50: every group "
                                   "is shown to it", low=EVERY_GROUP, high=50.0)
    roi: list = param([0, 0, 0, 0], "region of interest x, y, w, h [px]; w or h 0 = whole frame")
    class_id: int = param(0, "class id written into each detection", low=0, high=1000000)
    max_detections: int = param(500, "keep at most this many detections (best scores)", low=1, high=100000)
    threads: int = param(1, "pyramid levels scanned at once (the compiled loops release the GIL; 1: one core)",
                         low=1, high=16)
    max_model_stumps: int = param(MAX_STUMPS, "refuse a cascade model with more stumps than this (bounds the "
                                  "work per window)", low=1, high=10000000)
    min_model_window: int = param(MIN_WINDOW, "refuse a model whose window is smaller than this [px] (bounds "
                                  "the windows per frame)", low=4, high=1024)

    def validate(self) -> None:
        """Cross-field rules ``config.validate`` calls, at start-up and on every ``ros2 param set``:
        a well-formed roi, ``min_size <= max_size``, and a model that exists and loads with the
        chosen backend within the model limits (so a bad model is refused, not run)."""
        roi = list(self.roi)
        if len(roi) != 4 or any(v != int(v) for v in roi) or roi[2] < 0 or roi[3] < 0:
            raise ConfigError(f"roi must be 4 whole numbers x, y, w, h with w, h >= 0, got {roi}", ("roi",))
        angles = list(self.angles)
        if not angles or len(angles) > 8 or any(not isinstance(a, (int, float)) or not -180.0 <= float(a) <= 180.0
                                                 for a in angles):
            raise ConfigError(f"angles must be 1-8 numbers in [-180, 180] degrees, got {angles}", ("angles",))
        if self.backend == "opencv" and any(a != 0 for a in angles):
            raise ConfigError("angles other than 0 need the cascade backend", ("angles", "backend"))
        if self.blob_views and self.backend != "cascade":
            raise ConfigError("blob_views needs the cascade backend", ("blob_views", "backend"))
        if self.verifier and self.backend != "cascade":
            raise ConfigError("a verifier needs the cascade backend", ("verifier", "backend"))
        if self.containment_exempt_log_odds < NEVER_EXEMPT and not self.verifier:
            raise ConfigError("containment_exempt_log_odds needs a verifier (its log odds)",
                              ("containment_exempt_log_odds", "verifier"))
        if self.low_confidence_band > 0 and not self.verifier:
            raise ConfigError("low_confidence_band needs a verifier (its log odds)", ("low_confidence_band", "verifier"))
        if self.patch_net_floor > EVERY_GROUP and not self.patch_net:
            raise ConfigError("patch_net_floor needs a patch network", ("patch_net_floor", "patch_net"))
        if self.patch_net_floor > max(EVERY_GROUP, self.verifier_threshold - self.low_confidence_band):
            raise ConfigError(f"patch_net_floor {self.patch_net_floor} would reject groups the verifier alone accepts: "
                              f"at most verifier_threshold - low_confidence_band "
                              f"({self.verifier_threshold - self.low_confidence_band:g})",
                              ("patch_net_floor", "verifier_threshold", "low_confidence_band"))
        if self.box_regressor and self.backend != "cascade":
            raise ConfigError("a box regressor needs the cascade backend", ("box_regressor", "backend"))
        if self.min_size > 0 and self.max_size > 0 and self.min_size > self.max_size:
            raise ConfigError(f"min_size={self.min_size} must not exceed max_size={self.max_size}",
                              ("min_size", "max_size"))
        try:
            load_model(self)
        except (DetectorError, CascadeError) as exc:
            raise ConfigError(f"model {self.model!r} ({self.backend} backend): {exc}",
                              ("model", "backend", "max_model_stumps", "min_model_window")) from None
        try:
            load_verifier(self)
        except (DetectorError, VerifierError) as exc:
            raise ConfigError(f"verifier {self.verifier!r}: {exc}", ("verifier",)) from None
        try:
            regressor = load_box_regressor(self)
        except (DetectorError, BoxRegressorError) as exc:
            raise ConfigError(f"box regressor {self.box_regressor!r}: {exc}", ("box_regressor",)) from None
        if regressor is not None and regressor.image_stages and not self.verifier:
            raise ConfigError(f"box regressor {self.box_regressor!r} reads the image (image stages): it needs the "
                              "verifier (colour images)", ("box_regressor", "verifier"))
        if self.patch_net and not self.verifier:
            raise ConfigError("a patch network adds to the verifier's log odds: it needs the verifier",
                              ("patch_net", "verifier"))
        if self.patch_net and regressor is not None and regressor.image_stages:
            raise ConfigError(f"box regressor {self.box_regressor!r} has image stages, and the patch network places "
                              "the published boxes itself: use a box regressor of member statistics only (e.g. "
                              "uav_vehicles_box_regressor.json) or no patch network", ("patch_net", "box_regressor"))
        try:
            load_patch_net(self)
        except (DetectorError, PatchNetError) as exc:
            raise ConfigError(f"patch network {self.patch_net!r}: {exc}", ("patch_net",)) from None
        for_models = regressor.info.get("for_models") if regressor is not None else None
        if for_models and Path(self.model).name not in for_models:   # its offsets fit those models' windows only
            raise ConfigError(f"box regressor {self.box_regressor!r} was trained for {', '.join(for_models)}, not "
                              f"{Path(self.model).name}: set box_regressor to '' (or to one for this model); the "
                              "set-up that pairs them (config/detector.yaml) chose its grouping (min_neighbors, "
                              "window_margin) and blob views with that model too: set them for this one",
                              ("box_regressor", "model"))


def resolve_model(name: str) -> Path:
    """A model path, or a bare file name inside the package's ``models`` folder."""
    try:
        path = Path(name).expanduser()
        if not path.is_file() and (MODELS_DIR / name).is_file():
            path = MODELS_DIR / name
        found = path.is_file()
    except (OSError, ValueError, RuntimeError) as exc:   # a NUL byte, a name too long, an unknown ~user
        raise DetectorError(f"model file {name!r}: {exc}") from None
    if not found:
        raise DetectorError(f"model file {name!r} not found (nor in {MODELS_DIR})")
    return path


_MODEL_CACHE: dict = {}


def _cached(path: Path, load, *extra):
    """``load(path)``, once per version of the file (its path, size and modification time) and ``extra``: the
    configuration's validation and the detector built after it read each JSON model once."""
    stat = path.stat()
    key = (load, str(path), stat.st_size, stat.st_mtime_ns, *extra)
    if key not in _MODEL_CACHE:
        value = load(path, *extra)
        while len(_MODEL_CACHE) >= 8:
            _MODEL_CACHE.pop(next(iter(_MODEL_CACHE)))
        _MODEL_CACHE[key] = value
    return _MODEL_CACHE[key]


def load_model(cfg: DetectorConfig):
    """The model of ``cfg`` loaded with its backend (a :class:`Cascade` or an ``OpenCVCascade``).

    JSON cascades are cached (:func:`_cached`); any failure is a :class:`DetectorError` with the reason.
    """
    path = resolve_model(cfg.model)
    if cfg.backend == "opencv":
        from multi_target_tracker.opencv_backend import OpenCVCascade, OpenCVCascadeError  # noqa: PLC0415

        if path.suffix.lower() == ".json":
            raise DetectorError(f"{path.name} is a JSON cascade; the opencv backend needs a cv2 cascade XML")
        try:
            return OpenCVCascade(path)
        except (OpenCVCascadeError, ValueError, cv2.error) as exc:
            raise DetectorError(str(exc)) from None
    try:
        return _cached(path, Cascade.load, cfg.max_model_stumps, cfg.min_model_window)
    except CascadeError as exc:
        raise DetectorError(str(exc)) from None


def load_verifier(cfg: DetectorConfig) -> Verifier | TreeVerifier | None:
    """The colour verifier of ``cfg`` (None when ``cfg.verifier`` is empty)."""
    if not cfg.verifier:
        return None
    return _cached(resolve_model(cfg.verifier), load_verifier_model)


def load_box_regressor(cfg: DetectorConfig) -> BoxRegressor | None:
    """The box regressor of ``cfg`` (None when ``cfg.box_regressor`` is empty)."""
    if not cfg.box_regressor:
        return None
    return _cached(resolve_model(cfg.box_regressor), BoxRegressor.load)


def load_patch_net(cfg: DetectorConfig) -> PatchNet | None:
    """The patch network of ``cfg`` (None when ``cfg.patch_net`` is empty). Not cached: an OpenCV network keeps its
    input and outputs between calls, so each detector has its own (a few ms to load)."""
    if not cfg.patch_net:
        return None
    return PatchNet.load(resolve_model(cfg.patch_net))


def to_gray(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise DetectorError(f"expected a uint8 image, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim != 2:
        raise DetectorError(f"expected a grey or BGR image, got shape {image.shape}")
    return image


def is_bgr(image: np.ndarray) -> bool:
    """Whether ``image`` is a three-channel (BGR) image, what the colour verifier and the blob views read."""
    return image.ndim == 3 and image.shape[2] == 3


def window_scales(window: tuple[int, int], frame_size: tuple[int, int], scale_factor: float,
                  min_size: float = 0.0, max_size: float = 0.0) -> list[float]:
    """Scales ``s`` (window = ``s * window`` px) from ``min_size`` to ``max_size`` heights that fit the frame."""
    w0, h0 = window
    width, height = frame_size
    s = max(1.0, min_size / h0) if min_size > 0 else 1.0
    top = min(width / w0, height / h0)
    if max_size > 0:
        top = min(top, max_size / h0)
    scales = []
    while s <= top + 1e-9:
        scales.append(s)
        s *= scale_factor
    return scales


def turned_view(gray: np.ndarray, angle: float, border: int = 0,
                crop: float = 0.0) -> tuple[np.ndarray, np.ndarray | None]:
    """``gray`` turned by ``angle`` degrees about its centre on a canvas that holds all of it (borders
    reflected), and the 2x3 affine map from the canvas back to ``gray`` (None for angle 0 without ``border``).
    At angle 0 the canvas is ``gray`` with ``border`` reflected pixels on every side. With ``crop`` > 0 a turned
    canvas keeps only its central square of ``crop`` times the square root of ``gray``'s area a side (a 640x480
    frame turned 45 degrees: 792 px a side, half of it reflected border; crop 1.1: 610)."""
    if angle % 360 == 0:
        if border <= 0:
            return gray, None
        view = cv2.copyMakeBorder(gray, border, border, border, border, cv2.BORDER_REFLECT)
        return view, np.array([[1.0, 0.0, -border], [0.0, 1.0, -border]])
    h, w = gray.shape
    c, s = abs(np.cos(np.radians(angle))), abs(np.sin(np.radians(angle)))
    size = (int(np.ceil(w * c + h * s)), int(np.ceil(w * s + h * c)))
    if crop > 0:
        side = int(round(crop * np.sqrt(w * h)))
        size = (min(size[0], side), min(size[1], side))
    view, turn = turned_canvas(gray, (w / 2, h / 2), angle, size)
    return view, cv2.invertAffineTransform(turn)


def map_back(boxes: np.ndarray, scores: np.ndarray, back: np.ndarray, frame_size: tuple[int, int],
             with_quads: bool = False):
    """Windows of a turned view (x, y, w, h in its pixels) as the upright boxes of their turned corners in
    the frame, clipped to it; windows whose centre falls outside the frame are dropped. ``with_quads``: also
    those corners ``(n, 4, 2)``, unclipped (the windows' own rectangles in the frame). ``back`` is the view's 2x3
    map, or one per window ``(n, 2, 3)`` (windows of several views at once: the same product, window by window)."""
    if back is None or not len(boxes):
        return (boxes, scores, box_to_quad(boxes).reshape(-1, 4, 2)) if with_quads else (boxes, scores)
    if back.ndim == 3:                                                # the windows' corners in the frame
        mapped = box_to_quad(boxes) @ back[:, :, :2].transpose(0, 2, 1) + back[:, None, :, 2]
    else:
        mapped = box_to_quad(boxes) @ back[:, :2].T + back[:, 2]
    lo, hi = mapped.min(axis=1), mapped.max(axis=1)
    centre = (lo + hi) / 2
    width, height = frame_size
    inside = (centre[:, 0] >= 0) & (centre[:, 0] < width) & (centre[:, 1] >= 0) & (centre[:, 1] < height)
    lo, hi = np.maximum(lo[inside], 0), np.minimum(hi[inside], (width, height))
    if with_quads:
        return np.column_stack([lo, hi - lo]), scores[inside], mapped[inside]
    return np.column_stack([lo, hi - lo]), scores[inside]


def scan_level(gray: np.ndarray, cascade: Cascade, scale: float, stride: int = 4, last_stage_margin: float = 0.0,
               with_vectors: bool = False, select=None, transposed: np.ndarray | None = None):
    """The windows of one pyramid level (window = ``scale * cascade.window`` px) that the cascade passes:
    ``(boxes (n,4) xywh, scores, vectors|None)``. ``select(boxes) -> indices`` (training) picks which
    are returned. ``transposed``: ``gray``'s transpose, when the caller has it."""
    height, width = gray.shape
    level = level_size(gray.shape, cascade.window, scale)
    packed = cascade.packed()
    scan = LevelScan(gray, level, stride, cascade.feature_set, cascade.edge_threshold,
                     None if with_vectors else packed.codes,   # detection keeps the planes of the codes it reads
                     transposed)
    idx, score = (scan.evaluate(packed, last_stage_margin) if scan.n_windows
                  else (np.zeros(0, np.int64), np.zeros(0)))
    fx, fy = width / max(level[0], 1), height / max(level[1], 1)
    boxes = _window_boxes(scan.window_origins(idx), fx, fy)
    if select is not None and len(idx):
        chosen = np.asarray(select(boxes), int)
        idx, score, boxes = idx[chosen], score[chosen], boxes[chosen]
    return boxes, score, (scan.vectors(idx) if with_vectors else None)


def level_size(shape: tuple[int, ...], window: tuple[int, int], scale: float) -> tuple[int, int]:
    """(width, height) of the texture level of an image of ``shape`` (height, width, ...) at which a window of
    ``scale * window`` px becomes 32x32."""
    (w0, h0), (height, width) = window, shape[:2]
    return int(round(width * LBP_SIZE / (w0 * scale))), int(round(height * LBP_SIZE / (h0 * scale)))


def _window_boxes(origin: np.ndarray, fx, fy) -> np.ndarray:
    """``(n, 4)`` boxes x, y, w, h in the image of windows whose texture-level top-left pixels are ``origin`` ``(n, 2)``,
    the image being ``fx`` x ``fy`` times the level (numbers, or one per window)."""
    boxes = np.empty((len(origin), 4))       # filled column by column: 4x faster than column_stack on 50 windows
    boxes[:, 0], boxes[:, 1] = origin[:, 0] * fx, origin[:, 1] * fy
    boxes[:, 2], boxes[:, 3] = LBP_SIZE * fx, LBP_SIZE * fy
    return boxes


def scan_canvases(canvases: list[tuple[np.ndarray, float]], cascade: Cascade, stride: int = 4,
                  last_stage_margin: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`scan_level` of each ``(canvas, scale)``, ``(boxes, scores)`` a canvas: the same windows and scores, from
    one :class:`LevelScan` of their levels side by side (each at a multiple of ``stride``, so that it keeps its window
    grid; only the windows inside one canvas are scored, and they see its pixels only). The blob views are many and
    small (about 37 a UAV frame): one scan each spent more on its fixed costs than on its pixels. Their levels are all
    about one size (each is scanned at the scale that makes its window 32x32), so the atlas, as tall as the tallest,
    holds little but them."""
    sizes = [level_size(canvas.shape, cascade.window, scale) for canvas, scale in canvases]
    inside = [window_grid(size, stride) for size in sizes]             # each canvas' rows and columns of windows
    used = [i for i, (rows, cols) in enumerate(inside) if rows and cols]
    out = [(np.zeros((0, 4)), np.zeros(0))] * len(canvases)
    if not used:
        return out
    left = np.cumsum([0] + [-(-sizes[i][0] // stride) * stride for i in used])   # each level's x in the atlas
    width, height = int(left[-1]), max(sizes[i][1] for i in used)
    texture = np.zeros((height, width), np.uint8) if cascade.feature_set != "contour" else None
    contour = np.zeros((2 * height, 2 * width), np.uint8) if cascade.feature_set != "lbp" else None
    for i, x in zip(used, left):
        wl, hl = sizes[i]
        gray = to_gray(canvases[i][0])
        if texture is not None:
            texture[:hl, x:x + wl] = resize_area(gray, (wl, hl))
        if contour is not None:
            contour[:2 * hl, 2 * x:2 * (x + wl)] = resize_area(gray, (2 * wl, 2 * hl))
    packed = cascade.packed()
    scan = LevelScan.of_levels(texture, contour, stride, cascade.feature_set, cascade.edge_threshold, packed.codes)
    rows, cols = np.array([inside[i] for i in used]).T
    counts = rows * cols
    start = np.cumsum(counts) - counts                                   # each canvas' first window in ``first``
    owner = np.repeat(np.arange(len(used)), counts)                      # its windows, row by row
    r, c = np.divmod(np.arange(len(owner)) - start[owner], cols[owner])
    first = r * scan.cols + left[:-1][owner] // stride + c
    idx, score = scan.evaluate(packed, last_stage_margin, first)
    position = np.full(scan.n_windows, -1)
    position[first] = np.arange(len(first))
    kept = position[idx]                                                 # the passing windows' places in ``first``
    which = owner[kept]
    r, c = np.divmod(kept - start[which], cols[which])
    shape = np.array([canvases[i][0].shape[:2] for i in used], float)    # (height, width)
    fx = shape[:, 1] / np.array([sizes[i][0] for i in used])
    fy = shape[:, 0] / np.array([sizes[i][1] for i in used])
    fx, fy = fx[which], fy[which]
    boxes = _window_boxes(grid_origins(r, c, stride), fx, fy)
    ends = np.searchsorted(which, np.arange(1, len(used)))
    for i, b, sc in zip(used, np.split(boxes, ends), np.split(score, ends)):
        out[i] = (b, sc)
    return out


def scan_cascade(gray: np.ndarray, cascade: Cascade, scale_factor: float = 1.2, stride: int = 4,
                 min_size: float = 0.0, max_size: float = 0.0, last_stage_margin: float = 0.0,
                 with_vectors: bool = False, select=None):
    """Every window of the pyramid that the cascade passes: ``(boxes (n,4) xywh, scores, vectors|None)``.

    ``gray`` is scanned upright only (the caller transposes for the other orientation).
    ``select(boxes) -> indices`` (training) picks which passing windows of a level are returned.
    """
    height, width = gray.shape
    levels = [scan_level(gray, cascade, scale, stride, last_stage_margin, with_vectors, select)
              for scale in window_scales(cascade.window, (width, height), scale_factor, min_size, max_size)]
    return merge_levels(levels, with_vectors)


def merge_levels(levels: list, with_vectors: bool):
    """:func:`scan_level` results, in order, as one ``(boxes, scores, vectors|None)``."""
    if not levels:
        return np.zeros((0, 4)), np.zeros(0), (np.zeros((0, 1152), np.uint8) if with_vectors else None)
    boxes, scores, vectors = zip(*levels)
    return np.vstack(boxes), np.concatenate(scores), (np.vstack(vectors) if with_vectors else None)


def suppress_contained(boxes: np.ndarray, scores: np.ndarray, containment: float,
                       limit: int | None = None, iou: float = 1.0, exempt: np.ndarray | None = None) -> np.ndarray:
    """Indices of the boxes kept, best score first, dropping each box lying ``containment`` inside a
    better kept one (intersection over the smaller box's area) or overlapping one by ``iou`` (intersection over
    union: greedy non-maximum suppression); the boxes of the mask ``exempt`` are tested by ``iou`` only; at most
    ``limit``."""
    order = np.argsort(-np.asarray(scores, np.float64), kind="stable")
    limit = len(order) if limit is None else limit
    if (containment >= 1.0 and iou >= 1.0) or len(order) < 2:
        return order[:limit]
    boxes = np.ascontiguousarray(np.asarray(boxes, np.float64).reshape(-1, 4))
    exempt = np.zeros(len(order), np.bool_) if exempt is None else np.asarray(exempt, np.bool_).reshape(-1)
    if len(exempt) != len(order):
        raise ValueError(f"exempt has {len(exempt)} entries for {len(order)} boxes")
    return _suppress_contained(boxes, exempt, order.astype(np.int64), float(containment), int(limit), float(iou))


@numba.njit(cache=True, nogil=True)
def _suppress_contained(boxes, exempt, order, containment, limit, iou):
    """Greedy containment and overlap suppression over ``order`` (compiled: the kept boxes are few, the loop is
    O(n k)); a ratio of 1 never drops a box, nor containment an ``exempt`` one."""
    kept = np.empty(min(len(order), max(limit, 0)), np.int64)
    n_kept = 0
    for k in order:
        if n_kept >= limit:
            break
        ax, ay, aw, ah = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]
        contain = containment < 1.0 and not exempt[k]
        inside = False
        for i in range(n_kept):
            b = kept[i]
            bx, by, bw, bh = boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3]
            inter = max(min(ax + aw, bx + bw) - max(ax, bx), 0.0) * max(min(ay + ah, by + bh) - max(ay, by), 0.0)
            if (contain and inter / max(min(aw * ah, bw * bh), 1e-12) >= containment) or \
                    (iou < 1.0 and inter / max(aw * ah + bw * bh - inter, 1e-12) >= iou):
                inside = True
                break
        if not inside:
            kept[n_kept] = k
            n_kept += 1
    return kept[:n_kept]


@numba.njit(cache=True, nogil=True)
def _polygon_area(xs, ys, n):
    """Area of the polygon ``xs[:n], ys[:n]`` (shoelace; either vertex order)."""
    total = 0.0
    for i in range(n):
        j = (i + 1) % n
        total += xs[i] * ys[j] - xs[j] * ys[i]
    return abs(0.5 * total)


@numba.njit(cache=True, nogil=True)
def quad_intersection(a, b):
    """Area of the intersection of two convex quadrilaterals ``(4, 2)``, either vertex order: ``a`` clipped by each
    edge of ``b`` (Sutherland-Hodgman). The grouping's compiled form of ``cv2.intersectConvexConvex`` (the metrics'
    ``polygon_iou`` calls OpenCV once per pair; the grouping tests thousands of pairs a frame)."""
    xs, ys, next_x, next_y = np.empty(8), np.empty(8), np.empty(8), np.empty(8)
    for i in range(4):
        xs[i], ys[i] = a[i, 0], a[i, 1]
    n = 4
    turn = 0.0                                     # b's orientation: inside is on this side of each edge
    for i in range(4):
        j = (i + 1) % 4
        turn += b[i, 0] * b[j, 1] - b[j, 0] * b[i, 1]
    sign = 1.0 if turn >= 0 else -1.0
    for e in range(4):
        if n < 3:
            return 0.0
        ex, ey = b[e, 0], b[e, 1]
        dx, dy = b[(e + 1) % 4, 0] - ex, b[(e + 1) % 4, 1] - ey
        m = 0
        for i in range(n):
            px, py, qx, qy = xs[i], ys[i], xs[(i + 1) % n], ys[(i + 1) % n]
            side_p = sign * (dx * (py - ey) - dy * (px - ex))
            side_q = sign * (dx * (qy - ey) - dy * (qx - ex))
            if side_p >= 0:
                next_x[m], next_y[m] = px, py
                m += 1
            if (side_p >= 0) != (side_q >= 0):     # the edge pq crosses b's edge: keep the crossing
                t = side_p / (side_p - side_q)
                next_x[m], next_y[m] = px + t * (qx - px), py + t * (qy - py)
                m += 1
        n = m
        xs[:n], ys[:n] = next_x[:n], next_y[:n]
    return _polygon_area(xs, ys, n) if n >= 3 else 0.0


@numba.njit(cache=True, nogil=True)
def _window_iou(boxes, quads, areas, s, j):
    """IoU of windows ``s`` and ``j``: of their upright ``boxes`` (as ``box_iou``: 0 for empty boxes) when ``quads``
    is empty, else of their turned rectangles ``quads`` (``areas`` theirs), the boxes ruling out at once the pairs
    that cannot overlap."""
    ax, ay, aw, ah = boxes[s, 0], boxes[s, 1], boxes[s, 2], boxes[s, 3]
    bx, by, bw, bh = boxes[j, 0], boxes[j, 1], boxes[j, 2], boxes[j, 3]
    if len(quads) == 0:
        inter = max(min(ax + aw, bx + bw) - max(ax, bx), 0.0) * max(min(ay + ah, by + bh) - max(ay, by), 0.0)
        union = max(aw, 0.0) * max(ah, 0.0) + max(bw, 0.0) * max(bh, 0.0) - inter
        return inter / union if union > 0.0 else 0.0
    if min(ax + aw, bx + bw) <= max(ax, bx) or min(ay + ah, by + bh) <= max(ay, by):
        return 0.0
    inter = quad_intersection(quads[s], quads[j])
    union = areas[s] + areas[j] - inter
    return inter / union if union > 0.0 else 0.0


@numba.njit(cache=True, nogil=True)
def _group_labels(boxes, quads, group_iou):
    """Group label of every window (sorted best margin first) and each group's seed window.

    Window ``s`` still free seeds a group that takes every later free window overlapping it by ``group_iou``
    (:func:`_window_iou`: the upright ``boxes``, or the turned rectangles ``quads`` unless empty); earlier windows
    are all taken by then.
    """
    n = len(boxes)
    label = np.full(n, -1, np.int64)
    seeds = np.empty(n, np.int64)
    areas = np.empty(len(quads))
    for i in range(len(quads)):
        areas[i] = _polygon_area(quads[i, :, 0], quads[i, :, 1], 4)
    groups = 0
    for s in range(n):
        if label[s] >= 0:
            continue
        label[s] = groups
        seeds[groups] = s
        for j in range(s + 1, n):
            if label[j] < 0 and _window_iou(boxes, quads, areas, s, j) >= group_iou:
                label[j] = groups
        groups += 1
    return label, seeds[:groups]


def group_members(boxes: np.ndarray, margins: np.ndarray, group_iou: float = 0.3, quads: np.ndarray | None = None):
    """The groups of :func:`group_windows` before any is dropped: ``(boxes, margins, label, seeds)`` with the
    windows sorted best margin first, each window's group label and each group's seed (best) window.
    With ``quads`` (the windows' turned corners, ``(n, 4, 2)``) ``group_iou`` is their overlap, not the boxes'.
    Benchmarks score other group confidences from it (e.g. the members' summed margins)."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    margins = np.asarray(margins, np.float64).reshape(-1)
    order = np.argsort(-margins, kind="stable")
    boxes, margins = np.ascontiguousarray(boxes[order]), margins[order]
    if len(boxes) == 0:
        return boxes, margins, np.zeros(0, np.int64), np.zeros(0, np.int64)
    if quads is None:
        quads = np.zeros((0, 4, 2))
    else:
        quads = np.asarray(quads, np.float64).reshape(-1, 4, 2)
        if len(quads) != len(order):
            raise ValueError(f"{len(quads)} turned windows for {len(order)} boxes")
        quads = np.ascontiguousarray(quads[order])
    label, seeds = _group_labels(boxes, quads, float(group_iou))
    return boxes, margins, label, seeds


def group_stats(boxes: np.ndarray, margins: np.ndarray, group_iou: float = 0.3, margin_floor: float = 0.0,
                min_count: int = 1, quads: np.ndarray | None = None):
    """The groups of :func:`group_members` of at least ``min_count`` windows: ``(boxes, counts, margin_sums,
    best_margins)`` with the mean box of each group, its number of windows, its members' margins above
    ``margin_floor`` summed (OpenCV's level weights) and its best member's margin."""
    return members_stats(*group_members(boxes, margins, group_iou, quads), margin_floor, min_count)[1:]


def members_stats(boxes: np.ndarray, margins: np.ndarray, label: np.ndarray, seeds: np.ndarray,
                  margin_floor: float = 0.0, min_count: int = 1):
    """:func:`group_stats` from :func:`group_members`' output, with the labels of the groups kept first:
    ``(kept labels, boxes, counts, margin_sums, best_margins)``."""
    if len(seeds) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    counts = np.bincount(label, minlength=len(seeds))
    sums = np.zeros((len(seeds), 4))
    np.add.at(sums, label, boxes)          # members in window order, as a per-group mean adds them
    margin_sums = np.bincount(label, weights=margins - margin_floor, minlength=len(seeds))
    big = counts >= min_count
    return np.flatnonzero(big), sums[big] / counts[big, None], counts[big], margin_sums[big], margins[seeds[big]]


def group_windows(boxes: np.ndarray, margins: np.ndarray, group_iou: float = 0.3, min_neighbors: int = 3,
                  containment: float = 0.4, max_detections: int = 500,
                  quads: np.ndarray | None = None, suppression_iou: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Raw windows ``(n, 4)`` and their last-stage margins -> grouped ``(boxes, scores)``, best first.

    See the module docstring: mean box per group, score = windows in the group + logistic of the best
    margin, groups smaller than ``min_neighbors`` dropped, contained (or ``suppression_iou`` overlapping) groups
    suppressed. With ``quads`` the windows are grouped by the overlap of their turned rectangles
    (:func:`group_members`).
    """
    group_boxes, counts, _, best = group_stats(boxes, margins, group_iou, min_count=min_neighbors, quads=quads)
    if len(counts) == 0:
        return np.zeros((0, 4)), np.zeros(0)
    group_scores = counts + expit(best)
    keep = suppress_contained(group_boxes, group_scores, containment, max_detections, suppression_iou)
    return group_boxes[keep], group_scores[keep]


class Detector:
    """Image in, DETECTION_DTYPE table out, with either backend."""

    def __init__(self, config: DetectorConfig | None = None):
        self.config = config or DetectorConfig()
        cfg = self.config
        if len(cfg.roi) != 4:
            raise DetectorError(f"roi needs 4 numbers x, y, w, h, got {cfg.roi}")
        model = load_model(cfg)
        self.cascade = model if isinstance(model, Cascade) else None
        self.opencv = None if isinstance(model, Cascade) else model
        self.window = model.window
        info = self.cascade.info if self.cascade is not None else {}
        self.min_size = cfg.min_size or float(info.get("search_min_size", 0.0))
        self.max_size = cfg.max_size or float(info.get("search_max_size", 0.0))
        orientation = cfg.orientation
        if orientation == "model":
            orientation = "both" if (self.cascade is not None and self.cascade.rotate90) else "upright"
        self.both_orientations = orientation == "both"
        self.angles = sorted({float(a) for a in cfg.angles}) if self.cascade is not None else [0.0]
        self.pool = ThreadPoolExecutor(cfg.threads, "detector") if cfg.threads > 1 else None
        try:
            self.verifier = load_verifier(cfg) if self.cascade is not None else None
            self.box_regressor = load_box_regressor(cfg) if self.cascade is not None else None
            self.patch_net = load_patch_net(cfg) if self.verifier is not None else None
        except (VerifierError, BoxRegressorError, PatchNetError) as exc:
            raise DetectorError(str(exc)) from None

    @property
    def needs_colour(self) -> bool:
        """Whether :meth:`detect` needs a BGR image (a colour verifier or ``blob_views`` is configured)."""
        return self.verifier is not None or (self.cascade is not None and self.config.blob_views)

    def raw(self, image: np.ndarray, last_stage_margin: float | None = None) -> Windows:
        """Ungrouped :class:`Windows` in ``image``'s pixels (grey, or BGR: ``blob_views`` needs colour), both
        orientations if configured, and the windows of the colour blobs' views with ``blob_views``."""
        return self._raw(image, to_gray(image), last_stage_margin)

    def _group_quads(self, windows: Windows) -> np.ndarray | None:
        """What the grouping overlaps besides the boxes: the windows' turned rectangles with ``group_shape``
        turned, else None (the grouping functions' ``quads``)."""
        return windows.quads if self.config.group_shape == "turned" else None

    def members(self, windows: Windows):
        """:func:`group_members` of ``windows`` as this detector groups them (``group_iou``, ``group_shape``)."""
        return group_members(windows.boxes, windows.margins, self.config.group_iou, self._group_quads(windows))

    def _raw(self, image: np.ndarray, gray: np.ndarray, last_stage_margin: float | None) -> Windows:
        """:meth:`raw` of ``image`` whose grey version ``gray`` the caller has already."""
        cfg = self.config
        margin = cfg.window_margin if last_stage_margin is None else last_stage_margin
        if self.cascade is not None:   # every (view, level) is one job; merged in job order either way
            turned = [turned_view(gray, angle, cfg.border, cfg.turned_crop) for angle in self.angles]
            views = []                   # (view, transposed, back, key, the view's transpose if at hand)
            for turn, (v, back) in enumerate(turned):
                if self.both_orientations:
                    v_t = np.ascontiguousarray(v.T)
                    views += [(v, False, back, turn, v_t), (v_t, True, back, turn, v)]
                else:
                    views.append((v, False, back, turn, None))
            jobs = [_Job(view, transposed, back, scale, cfg.stride, turn, other)
                    for view, transposed, back, turn, other in views
                    for scale in window_scales(self.window, view.shape[::-1], cfg.scale_factor, self.min_size,
                                               self.max_size)]
            blobs = self.blob_canvases(image, gray) if cfg.blob_views else []
            scan = lambda job: scan_level(job.image, self.cascade, job.scale, job.stride, margin,  # noqa: E731
                                          transposed=job.image_transposed)
            scan_blobs = lambda: scan_canvases([(canvas, scale) for canvas, scale, _ in blobs],  # noqa: E731
                                               self.cascade, blob_views.STRIDE, margin)
            if self.pool is not None:    # the blob views (one scan, scan_canvases) beside the turned views' levels
                blob_levels = self.pool.submit(scan_blobs)
                levels, blob_levels = list(self.pool.map(scan, jobs)), blob_levels.result()
            else:
                levels, blob_levels = list(map(scan, jobs)), scan_blobs()
            jobs += [_Job(canvas, False, back, scale, blob_views.STRIDE, -1, None) for canvas, scale, back in blobs]
            levels += [(b, sc, None) for b, sc in blob_levels]
            if not jobs:
                return Windows(np.zeros((0, 4)), np.zeros(0), np.zeros((0, 4, 2)))
            return Windows(*self._mapped_back(jobs, levels, gray.shape[::-1]))
        all_boxes, all_scores = [], []
        views = [(gray, False)] + ([(np.ascontiguousarray(gray.T), True)] if self.both_orientations else [])
        for view, transposed in views:
            boxes, scores = self.opencv.detect(view, cfg.scale_factor, cfg.min_neighbors, self.min_size, self.max_size)
            if transposed:
                boxes = boxes[:, [1, 0, 3, 2]]
            all_boxes.append(boxes)
            all_scores.append(scores)
        boxes = np.vstack(all_boxes)
        return Windows(boxes, np.concatenate(all_scores), box_to_quad(boxes).reshape(-1, 4, 2))

    @staticmethod
    def _mapped_back(jobs: list, levels: list, frame: tuple[int, int]):
        """The jobs' windows in the frame, in job order (:func:`map_back`): a turned view's levels share its map and
        are mapped at once, the blob views all at once with one map per window (70 calls a UAV frame were 6 ms)."""
        boxes = [b[:, [1, 0, 3, 2]] if job.transposed else b for job, (b, _, _) in zip(jobs, levels)]
        mapped = []
        for key, members in itertools.groupby(range(len(jobs)), key=lambda i: jobs[i].key):
            members = list(members)
            back = jobs[members[0]].back if key >= 0 else \
                np.repeat(np.stack([jobs[i].back for i in members]), [len(boxes[i]) for i in members], axis=0)
            mapped.append(map_back(np.concatenate([boxes[i] for i in members]).reshape(-1, 4),
                                   np.concatenate([levels[i][1] for i in members]), back, frame, with_quads=True))
        return tuple(np.concatenate([m[k] for m in mapped]) for k in range(3))

    def blob_canvases(self, image: np.ndarray, gray: np.ndarray) -> list[tuple[np.ndarray, float, np.ndarray]]:
        """``(canvas, scale, canvas-to-frame affine)`` of each colour blob of ``image`` (:mod:`blob_views`)."""
        if not is_bgr(image):
            raise DetectorError(f"blob_views needs a BGR image, got shape {image.shape}")
        cfg = self.config
        aspect = self.window[0] / self.window[1]
        blobs = blob_views.colour_blobs(image, cfg.blob_background, cfg.blob_min_fill, aspect, cfg.blob_context,
                                        self.min_size, self.max_size, cfg.blob_scale)
        return [blob_views.blob_view(gray, blob, self.window, cfg.blob_context) for blob in blobs]

    def detect(self, image: np.ndarray, last_stage_margin: float | None = None) -> np.ndarray:
        """Detections in ``image`` (grey or BGR uint8; BGR with a verifier or blob views), best score first."""
        cfg = self.config
        gray = to_gray(image)
        if self.needs_colour and not is_bgr(image):
            raise DetectorError(f"the colour verifier and blob_views need a BGR image, got shape {image.shape}")
        x0, y0 = 0, 0
        rx, ry, rw, rh = (int(v) for v in cfg.roi)
        if rw > 0 and rh > 0:
            x0, y0 = max(0, rx), max(0, ry)
            frame_width, frame_height = image.shape[1], image.shape[0]
            gray, image = gray[y0:ry + rh, x0:rx + rw], image[y0:ry + rh, x0:rx + rw]
            if gray.size == 0:
                raise DetectorError(f"roi {cfg.roi} lies outside the {frame_width}x{frame_height} frame")
        try:
            windows = self._raw(image, gray, last_stage_margin)
        except FeatureError as exc:
            raise DetectorError(str(exc)) from exc
        boxes, scores = windows.boxes, windows.margins
        low = None
        if self.verifier is not None:
            boxes, scores, low = self._verified(image, windows,
                                                cfg.window_margin if last_stage_margin is None else last_stage_margin)
        elif self.box_regressor is not None:
            boxes, scores = self._regressed(windows, gray.shape[::-1],
                                            cfg.window_margin if last_stage_margin is None else last_stage_margin)
        elif self.cascade is not None:
            boxes, scores = group_windows(boxes, scores, cfg.group_iou, cfg.min_neighbors, cfg.containment,
                                          cfg.max_detections, self._group_quads(windows), cfg.suppression_iou)
        else:  # OpenCV grouped already (minNeighbors); the two orientations only need merging
            keep = suppress_contained(boxes, scores, cfg.containment, cfg.max_detections, cfg.suppression_iou)
            boxes, scores = boxes[keep], scores[keep]
        out = np.zeros(len(boxes), DETECTION_DTYPE if low is None else FLAGGED_DETECTION_DTYPE)
        if low is not None:
            out[LOW_CONFIDENCE] = low
        scaled = scale_boxes(boxes, cfg.box_scale)
        out["x"], out["y"] = scaled[:, 0] + x0, scaled[:, 1] + y0
        out["w"], out["h"] = scaled[:, 2], scaled[:, 3]
        out["score"], out["class_id"] = scores, cfg.class_id
        return out

    def _groups(self, windows: Windows, margin_floor: float, frame_size: tuple[int, int]):
        """The groups of at least ``min_neighbors`` windows: ``(mean boxes, boxes refined by the box regressor (the
        mean boxes without one), counts, margin sums, best margins, box regression features (None without a
        regressor))``."""
        cfg = self.config
        members = self.members(windows)
        kept, group_boxes, counts, margin_sums, best = members_stats(*members, margin_floor, cfg.min_neighbors)
        refined, regression = group_boxes, None
        if self.box_regressor is not None and len(group_boxes):
            regression = member_features(members[0], members[1], members[2], kept, group_boxes, margin_floor,
                                         frame_size)
            refined = self.box_regressor.refine(group_boxes, regression)
        return group_boxes, refined, counts, margin_sums, best, regression

    def candidates(self, bgr: np.ndarray, windows: Windows, margin_floor: float):
        """Every group of at least ``min_neighbors`` windows before the verifier decides: ``(boxes, log odds)``,
        the boxes refined by the box regressor's member statistics if one is configured (before its image stages
        and ``box_scale``); with a patch network its boxes and the log odds summed."""
        return self._candidates(bgr, windows, margin_floor)[:2]

    def _candidates(self, bgr: np.ndarray, windows: Windows, margin_floor: float):
        """:meth:`candidates` and the groups' box regression features (None without a box regressor)."""
        group_boxes, refined, counts, margin_sums, best, regression = self._groups(windows, margin_floor,
                                                                                   bgr.shape[1::-1])
        colour_box = refined if self.verifier.colour_box == "refined" else group_boxes
        logit = self.verifier.logit(features(bgr, colour_box, counts, margin_sums, best))
        if self.patch_net is not None and len(refined):
            floor = self.config.patch_net_floor               # the groups below keep the verifier's log odds: rejected
            shown = np.flatnonzero(logit >= floor) if floor > EVERY_GROUP else np.arange(len(logit))
            patch_logit, boxes = self.patch_net.predict(bgr, refined[shown])
            logit, refined = logit.copy(), refined.copy()
            logit[shown] += patch_logit
            refined[shown] = boxes
        return refined, logit, regression

    def _regressed(self, windows: Windows, frame_size: tuple[int, int], margin_floor: float):
        """:func:`group_windows` with each group's mean box refined by the box regressor before containment
        (no verifier: the drone-view set-up's)."""
        cfg = self.config
        _, group_boxes, counts, _, best, _ = self._groups(windows, margin_floor, frame_size)
        if not len(group_boxes):
            return np.zeros((0, 4)), np.zeros(0)
        scores = counts + expit(best)
        keep = suppress_contained(group_boxes, scores, cfg.containment, cfg.max_detections, cfg.suppression_iou)
        return group_boxes[keep], scores[keep]

    def _verified(self, bgr: np.ndarray, windows: Windows, margin_floor: float):
        """The :meth:`candidates` that the colour verifier accepts, scored by its probability, contained ones dropped:
        ``(boxes, scores, low)``, ``low`` None without ``low_confidence_band``, else the mask of the groups published
        low-confidence (log odds within the band below ``verifier_threshold``). Containment keeps the better score
        first, so a low-confidence group never drops a detection: the others are the same with or without the band
        (``max_detections`` aside). The box regressor's image stages, if any, move the accepted groups' boxes (each
        box on its own, so the same with any band) before containment."""
        cfg = self.config
        group_boxes, logit, regression = self._candidates(bgr, windows, margin_floor)
        band = cfg.low_confidence_band
        accepted = logit >= cfg.verifier_threshold - band
        group_boxes, logit = group_boxes[accepted], logit[accepted]
        if regression is not None and self.box_regressor.image_stages:
            group_boxes = self.box_regressor.refine_image(bgr, group_boxes, regression[accepted])
        keep = self.kept_after_suppression(group_boxes, logit)
        return group_boxes[keep], expit(logit[keep]), (logit[keep] < cfg.verifier_threshold) if band > 0 else None

    def kept_after_suppression(self, boxes: np.ndarray, logit: np.ndarray) -> np.ndarray:
        """Indices of the verified groups (``boxes``, summed log odds ``logit``) that :func:`suppress_contained` keeps,
        best first: ``containment``, ``suppression_iou``, ``max_detections``, and ``containment_exempt_log_odds``
        exempting the confident ones from containment."""
        cfg = self.config
        logit = np.asarray(logit, np.float64).reshape(-1)
        exempt = logit >= cfg.containment_exempt_log_odds if cfg.containment_exempt_log_odds < NEVER_EXEMPT else None
        return suppress_contained(boxes, expit(logit), cfg.containment, cfg.max_detections, cfg.suppression_iou,
                                  exempt)

    def verified(self, bgr: np.ndarray, windows: Windows, margin_floor: float):
        """:meth:`_verified`'s detections proper ``(boxes, scores)``, without the low-confidence ones (what the
        verifier accepts at ``verifier_threshold``; tuning tools and the detector bench count these)."""
        group_boxes, scores, low = self._verified(bgr, windows, margin_floor)
        return (group_boxes, scores) if low is None else (group_boxes[~low], scores[~low])
