"""``association_node``: detections in, tracks out (seed 003 §3 via :mod:`multi_target_tracker.association`).

Topics (relative names):

* in ``detections`` (``sensor_msgs/PointCloud2``, ``DETECTION_DTYPE`` rows);
* in ``image`` (``sensor_msgs/Image``), only with ``output.annotate_image`` or ``output.fill_skipped_frames``;
* out ``tracks`` (``PointCloud2``, ``TRACK_DTYPE`` rows, velocities in px/s): every track the core
  holds, with its ``state``: 0 tentative, 1 confirmed (detected in this frame), 2 coasting and
  published (its prediction still trusted), 3 lost (kept for re-acquisition), 4 coasting unpublished
  (prediction no longer trusted). The published targets are states 1 and 2 (``evaluate`` scores
  those by default); a consumer filters on ``state``;
* out ``tracks/image_markers`` (``visualization_msgs/ImageMarker``: boxes and trails coloured by id, one
  overlay) and ``tracks/markers`` (legacy ``visualization_msgs/MarkerArray`` in pixels: boxes, ids, short
  trails), both of the published targets (plus tentative ones with ``output.include_tentative``;
  without ``output.include_coasting`` only state 1);
* out ``tracks/image`` (``sensor_msgs/Image`` bgr8, the image with the tracks drawn), only with
  ``output.annotate_image``.

With ``output.fill_skipped_frames`` every camera frame gets its tracks: a frame the detector skipped (its
keep-newest input drops the frames it cannot keep up with) gets the tracks predicted to its stamp (eq. 6;
published targets coasting, state 2, while the prediction is trusted), published just before the tracks of
the next detections, so a consumer of ``tracks`` gets the camera's rate however slow the detector is (the
last 30 frames waiting at most).

Every output carries the header of the detections message (the image's stamp and frame_id; a skipped
frame's outputs, the image's own). The frame interval T of the filters comes from those stamps. Invalid
detection rows (NaN, inf, size <= 0) are dropped, counted and reported in ``/diagnostics``; stamps going
backwards (a looped bag) or jumping reset the tracks; new IDs keep counting up.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from aircraft_docking_tracker.io.bag import stamp_to_ns
from aircraft_docking_tracker.config import param
from aircraft_docking_tracker.ros.markers import boxes_to_image_marker, boxes_to_markers
from aircraft_docking_tracker.ros.node_base import PerceptionNode, run_node
from aircraft_docking_tracker.object_table import (DETECTION_DTYPE, FLAGGED_DETECTION_DTYPE, LOW_CONFIDENCE,
                                                   TRACK_DTYPE, cloud_to_table, low_confidence, table_boxes,
                                                   table_to_cloud)
from aircraft_docking_tracker.ros.processing import (DetectionsLimit, ImageLimit, MessageProcessor, ProcessorSpec, Rejected,
                                                 best_rows)
from multi_target_tracker.association import AssociationConfig, MultiTargetTracker, Tracks
from multi_target_tracker.kalman import KalmanConfig
from multi_target_tracker.mot_track import KALMAN_PREFIX, NODE_NAME

OUTPUT_PREFIX = "output."
NODE_PREFIX = "node."
_IMAGE_BUFFER = 30


@dataclass
class AssociationOutputConfig:
    """What the node publishes (set at start-up; topics do not change at runtime)."""

    include_tentative: bool = param(False, "also draw tentative tracks (state 0) in tracks/markers and tracks/image")
    include_coasting: bool = param(True, "draw trusted coasting tracks (state 2) in tracks/markers and tracks/image")
    trail_length: int = param(20, "trail points per track in tracks/markers", low=0, high=1000)
    annotate_image: bool = param(False, "subscribe to image and publish tracks/image with the tracks drawn "
                                 "(start-up only)", read_only=True)
    fill_skipped_frames: bool = param(False, "subscribe to image and publish tracks for every camera frame, also "
                                      "those the detector skipped (its keep-newest input drops frames it cannot "
                                      "keep up with): the tracks predicted at that frame's stamp (state 2), "
                                      "published when the next detections arrive (start-up only)", read_only=True)


@dataclass
class AssociationNodeConfig(ImageLimit, DetectionsLimit):
    """Bounds on the work one input message may cost (apply at once; images: output.annotate_image)."""


def tracks_to_table(tracks: Tracks) -> np.ndarray:
    """The core's tracks as ``TRACK_DTYPE`` rows."""
    table = np.zeros(len(tracks), dtype=TRACK_DTYPE)
    table["id"] = tracks.ids
    table["x"], table["y"], table["w"], table["h"] = tracks.boxes.T
    table["vx"], table["vy"] = tracks.velocities.T
    table["score"] = tracks.scores
    table["class_id"] = tracks.class_ids
    table["age"] = tracks.ages
    table["misses"] = tracks.misses
    table["state"] = tracks.states
    return table


def draw_tracks(bgr: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The image with one box and id label per track (OpenCV drawing)."""
    import cv2  # noqa: PLC0415

    from aircraft_docking_tracker.ros.markers import id_color  # noqa: PLC0415

    out = np.ascontiguousarray(bgr).copy()
    for row in table:
        r, g, b = id_color(int(row["id"]))
        color = (int(255 * b), int(255 * g), int(255 * r))
        p0 = (int(round(row["x"])), int(round(row["y"])))
        p1 = (int(round(row["x"] + row["w"])), int(round(row["y"] + row["h"])))
        cv2.rectangle(out, p0, p1, color, 1 if row["state"] != 1 else 2)
        cv2.putText(out, str(int(row["id"])), (p0[0], max(p0[1] - 3, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4, color, 1)
    return out


class AssociationProcessor(MessageProcessor):
    """Message conversion around :class:`MultiTargetTracker` (live node and offline runner alike)."""

    def __init__(self, config: AssociationConfig | None = None, kalman: KalmanConfig | None = None,
                 output: AssociationOutputConfig | None = None, node: AssociationNodeConfig | None = None):
        self.tracker = MultiTargetTracker(config, kalman)
        self.output = output or AssociationOutputConfig()
        self.node = node or AssociationNodeConfig()
        self.invalid_detections = 0
        self.resets = 0
        self.inputs = {"detections": "sensor_msgs/msg/PointCloud2"}
        self.outputs = {"tracks": "sensor_msgs/msg/PointCloud2",
                        "tracks/markers": "visualization_msgs/msg/MarkerArray",
                        "tracks/image_markers": "visualization_msgs/msg/ImageMarker"}
        self.latest_only = frozenset()
        if self.output.annotate_image or self.output.fill_skipped_frames:
            self.inputs["image"] = "sensor_msgs/msg/Image"
            self.latest_only = frozenset({"image"})
        if self.output.annotate_image:
            self.outputs["tracks/image"] = "sensor_msgs/msg/Image"
        self._images: OrderedDict[int, object] = OrderedDict()   # stamp -> image waiting for its tracks
        self._tables: OrderedDict[int, np.ndarray] = OrderedDict()  # stamp -> tracks waiting for the image
        self._frames: OrderedDict[int, object] = OrderedDict()   # stamp -> header of a frame not yet tracked
        self._last_detections: int | None = None                 # stamp of the last detections tracked
        self.filled_frames = 0
        self._shown = 0

    def process(self, topic, msg):
        if topic == "image":
            return self._image(msg)
        stamp = stamp_to_ns(msg.header.stamp)
        flagged = any(f.name == LOW_CONFIDENCE for f in msg.fields)
        rows = best_rows(cloud_to_table(msg, FLAGGED_DETECTION_DTYPE if flagged else DETECTION_DTYPE),
                         self.node.max_detections, self.report_rejection, "detections")
        out = self._fill_skipped(stamp)     # after the message is read: a malformed one loses no waiting frame
        boxes = table_boxes(rows)
        result = self.tracker.step(stamp * 1e-9, boxes, rows["score"], rows["class_id"], low_confidence(rows))
        if result.rejected:
            self.invalid_detections += result.rejected
            self.report_rejection(f"detections: {result.rejected} invalid rows (NaN, inf or size <= 0) dropped")
        if result.reset:
            self.resets += 1
            self.report_event("detections: stamp jumped; the tracks were reset (new ids keep counting up)")
        self._last_detections = stamp
        self._shown = len(result.tracks.visible())
        return out + self._outputs(result.tracks, msg.header)

    def _outputs(self, tracks: Tracks, header) -> list:
        """``tracks`` (every state) and what is drawn of them, with the frame's ``header``."""
        shown = tracks.visible(self.output.include_tentative, self.output.include_coasting)
        drawn = tracks_to_table(shown)
        trails = self._trails(shown.ids)
        out = [("tracks", table_to_cloud(tracks_to_table(tracks), header)),
               ("tracks/markers", boxes_to_markers(drawn, header, "tracks", label_field="id", trails=trails)),
               ("tracks/image_markers", boxes_to_image_marker(drawn, header, "tracks", label_field="id",
                                                              trails=trails))]
        if self.output.annotate_image:
            out += self._annotate(stamp_to_ns(header.stamp), drawn)
        return out

    def _fill_skipped(self, stamp: int) -> list:
        """With ``fill_skipped_frames``: the predicted tracks of the camera frames before ``stamp`` (the detections
        now tracked) that got no detections since the last ones, oldest first; frames up to ``stamp`` are then
        forgotten."""
        out = []
        for frame in sorted(s for s in self._frames if s <= stamp):
            header = self._frames.pop(frame)
            if frame == stamp:
                continue
            tracks = self.tracker.predicted(frame * 1e-9)
            if tracks is not None:      # None: before the first detections, or a gap the next step resets
                self.filled_frames += 1
                out += self._outputs(tracks, header)
        return out

    def _trails(self, ids) -> dict:
        n = self.output.trail_length
        if n == 0:
            return {}
        trails = {}
        for track_id in ids:
            t = self.tracker.trail(int(track_id))[-n:]
            trails[int(track_id)] = [(x + w / 2, y + h / 2) for _, x, y, w, h, _ in t]
        return trails

    def _image(self, msg):
        from aircraft_docking_tracker.images import is_compressed  # noqa: PLC0415

        stamp = stamp_to_ns(msg.header.stamp)
        if self.output.fill_skipped_frames and (self._last_detections is None or stamp > self._last_detections):
            self._remember(self._frames, stamp, msg.header)    # its stamp is all the filling needs
        if not self.output.annotate_image:
            return []
        if not is_compressed(msg) and int(msg.width) * int(msg.height) > self.node.max_image_pixels:
            raise Rejected(f"image {msg.width}x{msg.height} exceeds max_image_pixels={self.node.max_image_pixels}")
        if stamp in self._tables:
            return self._publish_image(msg, self._tables.pop(stamp))
        self._remember(self._images, stamp, msg)
        return []

    def _annotate(self, stamp, table):
        if stamp in self._images:
            return self._publish_image(self._images.pop(stamp), table)
        self._remember(self._tables, stamp, table)
        return []

    @staticmethod
    def _remember(buffer: OrderedDict, stamp: int, value) -> None:
        buffer[stamp] = value
        while len(buffer) > _IMAGE_BUFFER:
            buffer.popitem(last=False)

    def _publish_image(self, image_msg, table):
        from aircraft_docking_tracker.images import numpy_to_image, to_bgr8  # noqa: PLC0415

        drawn = draw_tracks(to_bgr8(image_msg, self.node.max_image_pixels), table)
        return [("tracks/image", numpy_to_image(drawn, "bgr8", image_msg.header))]

    def reset(self) -> None:
        self.tracker.reset()
        self._images.clear()
        self._tables.clear()
        self._frames.clear()
        self._last_detections = None

    def status(self) -> dict:
        states = self.tracker.states
        return {"tracks published": self._shown, "tracks tentative": int((states == 0).sum()),
                "tracks confirmed": int(np.isin(states, (1, 2, 4)).sum()),
                "invalid detection rows": self.invalid_detections, "track resets": self.resets,
                "skipped frames filled": self.filled_frames,
                "next id": self.tracker.next_id}


def build(configs: dict) -> AssociationProcessor:
    return AssociationProcessor(configs[""], configs[KALMAN_PREFIX], configs[OUTPUT_PREFIX], configs[NODE_PREFIX])


#: How the live node and ``run_offline`` build the same processor from config/association.yaml.
SPEC = ProcessorSpec(NODE_NAME, {"": AssociationConfig, KALMAN_PREFIX: KalmanConfig,
                                 OUTPUT_PREFIX: AssociationOutputConfig, NODE_PREFIX: AssociationNodeConfig}, build)


class AssociationNode(PerceptionNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.attach_spec(SPEC)

    def on_config_changed(self, cfg) -> None:
        if isinstance(cfg, AssociationConfig):
            self.processor.tracker.configure(config=cfg)
        elif isinstance(cfg, KalmanConfig):
            self.processor.tracker.configure(kalman=cfg)
        elif isinstance(cfg, AssociationNodeConfig):
            self.processor.node = cfg
        else:   # output settings: trail length and track selection apply at once, topics at restart
            self.processor.output = cfg


def main(args=None):
    return run_node(AssociationNode, args)


if __name__ == "__main__":
    main()
