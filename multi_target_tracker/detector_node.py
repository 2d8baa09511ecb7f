"""``detector_node``: images in, detections out (seed 003 §2 via :mod:`multi_target_tracker.detector`).

Topics (relative names):

* in ``image`` (``sensor_msgs/Image``, any encoding; ``sensor_msgs/CompressedImage`` with
  ``node.compressed``), sensor-data QoS, newest frame kept, skipped frames counted;
* out ``detections`` (``sensor_msgs/PointCloud2``, ``DETECTION_DTYPE`` rows: x, y, w, h [px,
  top-left corner], score [last-stage margin, or OpenCV's level weight], class_id);
* out ``detections/image_markers`` (``visualization_msgs/ImageMarker``: every box, one LINE_LIST overlay);
* out ``detections/markers`` (legacy ``visualization_msgs/MarkerArray`` in pixels, one box per detection);
* out ``detections/image`` (``sensor_msgs/Image`` bgr8 with the boxes drawn), only with
  ``node.annotate_image``;
* ``/diagnostics``: rate, latency, skipped and rejected frames, detections per frame.

Every output carries the input image's header. Parameters: the :class:`DetectorConfig` fields
(model, backend, pyramid, grouping, region of interest, class id, score threshold) plus
``node.*`` (compressed input, frame stride, annotated image). A model that cannot be loaded, or a
frame that cannot be converted, is a counted, logged rejection; the node keeps running.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aircraft_docking_tracker.config import param
from aircraft_docking_tracker.ros.markers import boxes_to_image_marker, boxes_to_markers
from aircraft_docking_tracker.ros.node_base import PerceptionNode, run_node
from aircraft_docking_tracker.object_table import confident_rows, table_to_cloud
from aircraft_docking_tracker.ros.processing import ERROR, ImageLimit, MessageProcessor, ProcessorSpec, Rejected
from multi_target_tracker.detector import Detector, DetectorConfig

NODE_NAME = "detector"
NODE_PREFIX = "node."


@dataclass
class DetectorNodeConfig(ImageLimit):
    """Message handling around the detector core (topics are fixed at start-up)."""

    compressed: bool = param(False, "subscribe to sensor_msgs/CompressedImage instead of Image (start-up only)",
                             read_only=True)
    frame_stride: int = param(1, "detect on every k-th received frame (others are passed over)", low=1, high=1000)
    annotate_image: bool = param(False, "publish detections/image (bgr8 with the boxes drawn; start-up only)",
                                 read_only=True)


def draw_detections(bgr: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The image with one green box and score per detection."""
    import cv2  # noqa: PLC0415

    out = np.ascontiguousarray(bgr).copy()
    for row in table:
        p0 = (int(round(row["x"])), int(round(row["y"])))
        p1 = (int(round(row["x"] + row["w"])), int(round(row["y"] + row["h"])))
        cv2.rectangle(out, p0, p1, (40, 220, 40), 2)
        cv2.putText(out, f"{row['score']:.2f}", (p0[0], max(p0[1] - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (40, 220, 40), 1)
    return out


class DetectorProcessor(MessageProcessor):
    """Message conversion around :class:`Detector` (live node and offline runner alike)."""

    def __init__(self, config: DetectorConfig | None = None, node: DetectorNodeConfig | None = None):
        self.node = node or DetectorNodeConfig()
        image_type = "sensor_msgs/msg/CompressedImage" if self.node.compressed else "sensor_msgs/msg/Image"
        self.inputs = {"image": image_type}
        self.outputs = {"detections": "sensor_msgs/msg/PointCloud2",
                        "detections/markers": "visualization_msgs/msg/MarkerArray",
                        "detections/image_markers": "visualization_msgs/msg/ImageMarker"}
        if self.node.annotate_image:
            self.outputs["detections/image"] = "sensor_msgs/msg/Image"
        self.latest_only = frozenset({"image"})
        self.frames = self.passed_over = self.last_count = 0
        self.detector: Detector | None = None
        self.model_error = ""
        self.configure(config or DetectorConfig())
        self.warm_up()

    def warm_up_work(self) -> None:
        """One small blank frame through the detector (make demo lost its first 26 UAV frames to the kernels'
        loading in a fresh worktree before there was a warm-up)."""
        if self.detector is not None:
            self.detector.detect(np.zeros((120, 160, 3) if self.detector.needs_colour else (120, 160), np.uint8))

    def configure(self, config: DetectorConfig) -> None:
        """(Re)load the model; on failure every frame is rejected with the reason until fixed (the
        node's parameter validation refuses such a model first; this covers a file gone since)."""
        try:
            self.detector, self.model_error = Detector(config), ""
        except Exception as exc:  # noqa: BLE001 - a model that cannot run disables detection, not the node
            self.detector, self.model_error = None, f"{type(exc).__name__}: {exc}" if not isinstance(
                exc, ValueError) else str(exc)

    def process(self, topic, msg):
        from aircraft_docking_tracker.images import numpy_to_image, to_bgr8, to_mono8  # noqa: PLC0415

        if self.detector is None:
            raise Rejected(f"no detector model: {self.model_error}")
        self.frames += 1
        if (self.frames - 1) % self.node.frame_stride:
            self.passed_over += 1
            return []
        limit = self.node.max_image_pixels
        if self.node.annotate_image or self.detector.needs_colour:             # the colour verifier reads BGR
            bgr = to_bgr8(msg, limit)
            image = bgr if self.detector.needs_colour else _gray(bgr)
        else:
            bgr, image = None, to_mono8(msg, limit)
        table = self.detector.detect(image)
        shown = confident_rows(table)     # low-confidence rows (low_confidence_band) are for the association only
        self.last_count = len(shown)
        out = [("detections", table_to_cloud(table, msg.header)),
               ("detections/markers", boxes_to_markers(shown, msg.header, "detections")),
               ("detections/image_markers", boxes_to_image_marker(shown, msg.header, "detections"))]
        if self.node.annotate_image:      # bgr is there for the colour verifier too: publish only when asked
            out.append(("detections/image", numpy_to_image(draw_detections(bgr, shown), "bgr8", msg.header)))
        return out

    def reset(self) -> None:
        self.frames = 0

    def status(self) -> dict:
        return {"detections last frame": self.last_count, "frames passed over (stride)": self.passed_over,
                "model": "" if self.detector is None else self.detector.config.model,
                "model error": self.model_error}

    def health(self):
        if self.detector is None:
            return ERROR, f"detector disabled, no model: {self.model_error}"
        return None


def _gray(bgr: np.ndarray) -> np.ndarray:
    import cv2  # noqa: PLC0415

    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)


def build(configs: dict) -> DetectorProcessor:
    return DetectorProcessor(configs[""], configs[NODE_PREFIX])


SPEC = ProcessorSpec(NODE_NAME, {"": DetectorConfig, NODE_PREFIX: DetectorNodeConfig}, build)


class DetectorNode(PerceptionNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        processor = self.attach_spec(SPEC)
        if processor.model_error:
            self.get_logger().error(f"detector model not loaded: {processor.model_error}")

    def on_config_changed(self, cfg) -> None:
        if isinstance(cfg, DetectorConfig):
            self.processor.configure(cfg)
            if self.processor.model_error:
                self.get_logger().error(f"detector model not loaded: {self.processor.model_error}")
        else:  # frame stride applies at once; topics and compression at restart
            self.processor.node = cfg


def main(args=None):
    return run_node(DetectorNode, args)


if __name__ == "__main__":
    main()
