"""``docking_tracker_node``: images in, the docking aircraft's affine quadrilateral out (seed 000 §2
via :mod:`aircraft_docking_tracker.docking.tracker`, :mod:`~aircraft_docking_tracker.docking.ispf`).

Topics (relative names):

* in ``image`` (``sensor_msgs/Image``, any encoding; ``CompressedImage`` with ``node.compressed``),
  sensor-data QoS, newest frame kept, skipped frames counted; tracked in grey;
* in ``detections`` (``PointCloud2``, ``DETECTION_DTYPE``): while waiting or lost, the best row of
  class ``detection_class`` (re)starts the track; while tracking, rows that keep finding the aircraft
  away from the track restart it there (``override_after``); each table is used once, with the next
  image, when its stamp is within ``node.detection_max_age`` of the image's;
* in ``docking/init`` (``geometry_msgs/PolygonStamped``): a one-shot start: 4 points (TL, TR, BR,
  BL quadrilateral) or 2 points (box corners TL, BR); an empty polygon stops the track (waiting);
* out ``docking/polygon`` (``PolygonStamped``): the tracked quadrilateral, 4 points in pixels, TL,
  TR, BR, BL of the template; **empty while waiting or lost**;
* out ``docking/state`` (``PointCloud2``, one ``docking.STATE_DTYPE`` row: cx, cy, scale, aspect,
  rotation, skew, score, particles, state 0 tracking / 1 lost / 2 waiting);
* out ``docking/image_markers`` (``ImageMarker``: the quadrilateral as an image overlay, same colours);
* out ``docking/markers`` (legacy ``MarkerArray`` in pixels: the quadrilateral, green tracking / red lost, and a
  label);
* out ``docking/image`` (bgr8, the quadrilateral and the particles drawn, as the seed's Figs. 2-3; with
  guidance, a docking-guidance panel as the pilot's display shows it: state, distance to go, closing-rate
  bar, an arrow to the side to steer), only with ``node.annotate_image``;
* with a stand file (``guidance.stand_file``, :mod:`~aircraft_docking_tracker.docking.guidance`):
  out ``docking/guidance`` (``PointCloud2``, one ``GUIDANCE_DTYPE`` row: distance_m, lateral_m (the
  pilot's right +), speed_mps (closing), state 0 no aircraft / 1 tracking / 2 slow down / 3 STOP /
  4 overshoot / 5 lost; NaN figures without a track) and ``docking/guidance_markers`` (``MarkerArray``
  in metres in the stand's frame ``node.guidance_frame``, the image's stamp: lead-in line, stop mark,
  the nose and a text line; a static transform from the camera's frame to it places them in RViz).

Every output carries the input image's header. Parameters: the :class:`DockingConfig` fields (the
filter's constants, ``initial_box``, loss and re-acquisition rules) plus ``node.*``. Filter
constants set at runtime apply at the next (re)start; loss rules apply at once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .io.bag import stamp_to_ns
from .config import param
from .docking.guidance import (GUIDANCE_STATES, LOST as GUIDANCE_LOST, NO_AIRCRAFT, OVERSHOOT, PARAM_PREFIX as
                               GUIDANCE_PREFIX, SLOW_DOWN, STOP, DockingGuidance, GuidanceConfig, GuidanceResult,
                               survey_note)
from .docking.tracker import LOST, STATE_NAMES, TRACKING, WAITING, DockingConfig, DockingResult, DockingTracker, state_row
from .ros.node_base import PerceptionNode, run_node
from .object_table import DETECTION_DTYPE, cloud_to_table, table_to_cloud
from .ros.processing import DetectionsLimit, ImageLimit, MessageProcessor, ProcessorSpec, Rejected, best_rows

NODE_NAME = "docking_tracker"
NODE_PREFIX = "node."
COLORS = {TRACKING: (0.1, 1.0, 0.2), LOST: (1.0, 0.2, 0.1)}
_DRAWABLE = 1e6  # pixel coordinates drawn at most this far out (NaN and 1e30 are not)


@dataclass
class DockingNodeConfig(DetectionsLimit, ImageLimit):
    """Message handling around the docking tracker core (topics are fixed at start-up)."""

    compressed: bool = param(False, "subscribe to sensor_msgs/CompressedImage instead of Image (start-up only)",
                             read_only=True)
    detection_max_age: float = param(0.5, "detections older or newer than this [s] than the image are "
                                     "not used for (re)acquisition", low=0.0, high=3600.0)
    annotate_image: bool = param(False, "publish docking/image (bgr8, quadrilateral and particles drawn; start-up "
                                 "only)", read_only=True)
    max_drawn_particles: int = param(300, "particles drawn on docking/image at most", low=0, high=100000)
    guidance_frame: str = param("stand", "frame_id of docking/guidance_markers (metres on the stand, as the stand "
                                "file's coordinates)")


def draw_docking(bgr: np.ndarray, result: DockingResult, max_particles: int) -> np.ndarray:
    """The image with the particles' centres (white dots) and the tracked quadrilateral."""
    import cv2  # noqa: PLC0415

    out = np.ascontiguousarray(bgr).copy()
    if result.matrix is None:
        cv2.putText(out, "waiting", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 200, 255), 2)
        return out
    for cx, cy in result.particle_states[:max_particles, :2, 2]:
        if abs(cx) < _DRAWABLE and abs(cy) < _DRAWABLE:          # finite and within OpenCV's int range
            cv2.circle(out, (int(round(cx)), int(round(cy))), 1, (255, 255, 255), -1)
    r, g, b = COLORS[result.state]
    color = (int(255 * b), int(255 * g), int(255 * r))
    quad = result.quad
    if (np.abs(quad) < _DRAWABLE).all():
        cv2.polylines(out, [np.round(quad).astype(np.int32)], True, color, 2, cv2.LINE_AA)
    cv2.putText(out, f"{STATE_NAMES[result.state]} S={result.score:.2f} n={result.particles}", (8, 20),
                cv2.FONT_HERSHEY_SIMPLEX, 0.6, color, 2)
    return out


#: Panel colours (BGR) per guidance state, as a VDGS shows them.
PANEL_COLORS = {NO_AIRCRAFT: (160, 160, 160), 1: (60, 220, 60), SLOW_DOWN: (0, 200, 255), STOP: (40, 40, 255),
                OVERSHOOT: (40, 40, 255), GUIDANCE_LOST: (160, 160, 160)}
LATERAL_SHOWN_M = 0.25   # an offset the panel's arrow points out (ICAO's azimuth accuracy)


def draw_guidance_panel(bgr: np.ndarray, guidance: GuidanceResult, slow_down_m: float) -> np.ndarray:
    """A VDGS-like panel in the image's top right corner (as the pilot sees the display): the state, the
    distance to go, a closing-rate bar that shrinks over the last ``slow_down_m``, an arrow to the side the
    pilot must steer to with the offset, and the closing speed. Draws on ``bgr`` in place."""
    import cv2  # noqa: PLC0415

    h, w = bgr.shape[:2]
    pw, ph = min(150, w // 3), min(190, h - 8)
    x0, y0 = w - pw - 4, 4
    cv2.rectangle(bgr, (x0, y0), (x0 + pw, y0 + ph), (20, 20, 20), -1)
    color = PANEL_COLORS[guidance.state]
    label = {STOP: "STOP", OVERSHOOT: "TOO FAR", SLOW_DOWN: "SLOW"}.get(guidance.state,
                                                                      GUIDANCE_STATES[guidance.state].upper())
    cv2.putText(bgr, label, (x0 + 8, y0 + 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8 if len(label) < 8 else 0.55, color, 2)
    if not np.isfinite(guidance.distance_m):
        return bgr
    cv2.putText(bgr, f"{guidance.distance_m:.1f} m", (x0 + 8, y0 + 62), cv2.FONT_HERSHEY_SIMPLEX, 0.7, color, 2)
    bar_top, bar_bottom = y0 + 75, y0 + ph - 40
    fill = float(np.clip(guidance.distance_m / slow_down_m, 0.0, 1.0)) if slow_down_m > 0 else 0.0
    cv2.rectangle(bgr, (x0 + pw - 26, bar_top), (x0 + pw - 12, bar_bottom), (90, 90, 90), 1)
    cv2.rectangle(bgr, (x0 + pw - 26, int(bar_bottom - fill * (bar_bottom - bar_top))), (x0 + pw - 12, bar_bottom),
                  color, -1)
    mid_y = (bar_top + bar_bottom) // 2
    lateral = guidance.lateral_m
    if abs(lateral) >= LATERAL_SHOWN_M:   # the nose is right of the line (lateral > 0): steer left
        left = lateral > 0
        tail, head = (x0 + 90, mid_y), (x0 + 20, mid_y)
        cv2.arrowedLine(bgr, tail if left else head, head if left else tail, (0, 200, 255), 4, cv2.LINE_AA,
                        tipLength=0.4)
        cv2.putText(bgr, f"{abs(lateral):.1f} m", (x0 + 30, mid_y + 28), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (0, 200, 255), 1)
    else:
        cv2.putText(bgr, "on line", (x0 + 20, mid_y + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (60, 220, 60), 1)
    if np.isfinite(guidance.speed_mps):
        cv2.putText(bgr, f"{guidance.speed_mps:.1f} m/s", (x0 + 8, y0 + ph - 14), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (220, 220, 220), 1)
    return bgr


class DockingProcessor(MessageProcessor):
    """Message conversion around :class:`DockingTracker` (live node and offline runner alike)."""

    def __init__(self, config: DockingConfig | None = None, node: DockingNodeConfig | None = None,
                 guidance: GuidanceConfig | None = None):
        self.tracker = DockingTracker(config or DockingConfig())
        self.node = node or DockingNodeConfig()
        self.guidance = None
        if guidance is not None and guidance.stand_file:
            from .docking.stand import load_stand  # noqa: PLC0415

            self.guidance = DockingGuidance(load_stand(guidance.stand_file), guidance)
            self.start_up_notes = (survey_note(self.guidance),)
        self.last_guidance = GuidanceResult()
        image_type = "sensor_msgs/msg/CompressedImage" if self.node.compressed else "sensor_msgs/msg/Image"
        self.inputs = {"image": image_type, "detections": "sensor_msgs/msg/PointCloud2",
                       "docking/init": "geometry_msgs/msg/PolygonStamped"}
        self.outputs = {"docking/polygon": "geometry_msgs/msg/PolygonStamped",
                        "docking/state": "sensor_msgs/msg/PointCloud2",
                        "docking/markers": "visualization_msgs/msg/MarkerArray",
                        "docking/image_markers": "visualization_msgs/msg/ImageMarker"}
        if self.node.annotate_image:
            self.outputs["docking/image"] = "sensor_msgs/msg/Image"
        if self.guidance is not None:
            self.outputs["docking/guidance"] = "sensor_msgs/msg/PointCloud2"
            self.outputs["docking/guidance_markers"] = "visualization_msgs/msg/MarkerArray"
        self.latest_only = frozenset({"image"})
        self._detections: tuple[int, np.ndarray] | None = None
        self.last: DockingResult = DockingResult(WAITING)
        self.starts = 0
        self.warm_up()

    def warm_up_work(self) -> None:
        """A throwaway track over two small blank frames: the compiled affine exp and log load now (the camera's
        first frame took 0.48 s in make demo before, and the stand track skipped the 3 frames behind it)."""
        tracker = DockingTracker(self.tracker.config)
        blank = np.zeros((120, 160), np.uint8)
        tracker.start(blank, [60.0, 40.0, 40.0, 20.0])
        tracker.step(blank)

    def process(self, topic, msg):
        if topic == "detections":
            table = best_rows(cloud_to_table(msg, DETECTION_DTYPE), self.node.max_detections,
                              self.report_rejection, "detections")
            self._detections = (stamp_to_ns(msg.header.stamp), table)
            return []
        if topic == "docking/init":
            self._init(msg)
            return []
        return self._image(msg)

    def _init(self, msg) -> None:
        points = np.array([[p.x, p.y] for p in msg.polygon.points[:5]], dtype=float).reshape(-1, 2)
        if len(msg.polygon.points) > 4:
            raise Rejected(f"docking/init needs 4 points (quadrilateral) or 2 (box corners), got "
                           f"{len(msg.polygon.points)}")
        if not (np.abs(points) < _DRAWABLE).all():
            raise Rejected(f"docking/init has a point that is not finite or beyond +-{_DRAWABLE:g} px")
        if len(points) == 0:
            self.tracker.stop()                    # an empty polygon: stop, wait for a new start
            return
        if len(points) == 2:
            (x0, y0), (x1, y1) = points
            points = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        if len(points) != 4:
            raise Rejected(f"docking/init needs 4 points (quadrilateral) or 2 (box corners), got {len(points)}")
        self.tracker.request_start(points)

    def _image(self, msg):
        from .images import to_mono8_or_bgr8  # noqa: PLC0415
        from .ros.markers import delete_all, polygon_image_marker, polygon_marker, text_marker  # noqa: PLC0415
        from .scenarios.messages import quad_to_polygon  # noqa: PLC0415
        from visualization_msgs.msg import MarkerArray  # noqa: PLC0415

        frame = to_mono8_or_bgr8(msg, self.node.max_image_pixels)      # tracked in grey; colour for the start re-fit
        result = self.tracker.step(frame, self._fresh_detections(stamp_to_ns(msg.header.stamp)))
        self.last = result
        self.starts += int(result.started)
        shown = result.quad if result.state == TRACKING else np.full((4, 2), np.nan)
        markers = MarkerArray()
        markers.markers.append(delete_all(msg.header, "docking"))
        if result.matrix is not None:
            color = COLORS[result.state]
            quad = result.quad
            markers.markers.append(polygon_marker(msg.header, "docking", 0, quad, color))
            markers.markers.append(text_marker(msg.header, "docking", 1, float(quad[0, 0]), float(quad[0, 1]) - 4.0,
                                               f"{STATE_NAMES[result.state]} {result.score:.2f}", color))
        out = [("docking/polygon", quad_to_polygon(shown, msg.header)),
               ("docking/state", table_to_cloud(state_row(result), msg.header)),
               ("docking/markers", markers),
               ("docking/image_markers", polygon_image_marker(
                   msg.header, "docking", result.quad if result.matrix is not None else None,
                   COLORS.get(result.state, COLORS[TRACKING])))]
        if self.guidance is not None:
            guidance = self.guidance.guide_frame(frame, result.quad if result.matrix is not None else None,
                                                 result.state == TRACKING, result.state == LOST,
                                                 stamp_to_ns(msg.header.stamp))
            self.last_guidance = guidance
            out.append(("docking/guidance", table_to_cloud(guidance.row(), msg.header)))
            out.append(("docking/guidance_markers", self._guidance_markers(msg.header, guidance)))
        if self.node.annotate_image:
            from .images import numpy_to_image  # noqa: PLC0415

            import cv2  # noqa: PLC0415

            bgr = frame if frame.ndim == 3 else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
            drawn = draw_docking(bgr, result, self.node.max_drawn_particles)
            if self.guidance is not None:
                draw_guidance_panel(drawn, self.last_guidance, self.guidance.config.slow_down_m)
            out.append(("docking/image", numpy_to_image(drawn, "bgr8", msg.header)))
        return out

    def _guidance_markers(self, image_header, guidance: GuidanceResult):
        """``docking/guidance_markers``: the lead-in line, the stop mark, the nose and the figures, in metres."""
        from builtin_interfaces.msg import Time  # noqa: PLC0415
        from std_msgs.msg import Header  # noqa: PLC0415
        from visualization_msgs.msg import MarkerArray  # noqa: PLC0415

        from .ros.markers import delete_all, line_strip_marker, sphere_marker, text_marker  # noqa: PLC0415

        header = Header(stamp=Time(sec=image_header.stamp.sec, nanosec=image_header.stamp.nanosec),
                        frame_id=self.node.guidance_frame)
        lead_in, stop = self.guidance.stand.lead_in, self.guidance.stop_bar
        rgb = tuple(c / 255.0 for c in PANEL_COLORS[guidance.state][::-1])
        markers = MarkerArray()
        markers.markers.append(delete_all(header, "guidance"))
        markers.markers.append(line_strip_marker(header, "guidance", 0, np.c_[lead_in, np.zeros(len(lead_in))],
                                                 (1.0, 0.85, 0.0), 0.15))
        markers.markers.append(line_strip_marker(header, "guidance", 1, np.c_[stop, np.zeros(2)], (1.0, 0.1, 0.1), 0.3))
        if np.isfinite(guidance.nose_stand).all():
            nose = guidance.nose_stand
            markers.markers.append(sphere_marker(header, "guidance", 2, nose, rgb, 1.0))
            text = text_marker(header, "guidance", 3, float(nose[0]), float(nose[1]),
                               f"{GUIDANCE_STATES[guidance.state]} {guidance.distance_m:.1f} m, "
                               f"{'R' if guidance.lateral_m > 0 else 'L'} {abs(guidance.lateral_m):.2f} m, "
                               f"{guidance.speed_mps:.1f} m/s", rgb, 1.0)
            text.pose.position.z = float(nose[2]) + 2.0
            markers.markers.append(text)
        return markers

    def _fresh_detections(self, stamp_ns: int) -> np.ndarray | None:
        """The newest detection table, once (a table is one frame's evidence for the override count),
        if its stamp is within ``detection_max_age`` of the image's."""
        if self._detections is None:
            return None
        det_stamp, table = self._detections
        if abs(det_stamp - stamp_ns) > self.node.detection_max_age * 1e9:
            return None
        self._detections = None
        return table

    def configure(self, config: DockingConfig) -> None:
        self.tracker.configure(config)

    def configure_guidance(self, config: GuidanceConfig) -> None:
        """The guidance's constants, at once (the stand file and aircraft type are read at start-up)."""
        if self.guidance is not None:
            self.guidance.configure(config)

    def reset(self) -> None:
        self.tracker.reset()
        self._detections = None
        self.last = DockingResult(WAITING)
        if self.guidance is not None:
            self.guidance.reset()
        self.last_guidance = GuidanceResult()

    def status(self) -> dict:
        """Diagnostic values, with the static-camera extent's counts since the last start (how many
        frames corrected X̂, and why the others did not: moving camera, still target, no or implausible
        silhouette, refused by the appearance), with ``start_refit`` the start re-fit's (re-fitted, or why
        not) and, with ``shape_prior`` silhouette, the shape prior's."""
        values = {"docking state": STATE_NAMES[self.last.state], "score": f"{self.last.score:.3f}",
                  "particles last frame": self.last.particles, "track starts": self.starts,
                  "method": self.tracker.config.method}
        values.update({f"extent {name}": count for name, count in self.tracker.filter.extent_counts.items()})
        values["detections refused (still)"] = self.tracker.still_detections_refused
        values["overrides refused (vouched)"] = self.tracker.vouched_detections_refused
        if self.tracker.config.start_refit > 0:
            values.update({f"start re-fit {name}": count for name, count in self.tracker.filter.start_counts.items()})
        if self.tracker.config.shape_prior == "silhouette":       # frames whose silhouette moved the shape prior
            values.update({f"shape {name}": count for name, count in self.tracker.filter.shape_counts.items()})
        if self.guidance is not None:
            g = self.last_guidance
            values.update({"guidance state": GUIDANCE_STATES[g.state], "distance to go m": f"{g.distance_m:.2f}",
                           "lateral m": f"{g.lateral_m:.2f}", "closing speed m/s": f"{g.speed_mps:.2f}",
                           "guidance smoothing restarts": self.guidance.restarts,
                           "guidance jumps rejected": self.guidance.rejected,
                           "guidance frames measured at the nose wheel": self.guidance.gear_measured,
                           "guidance nose-wheel contacts refused (far from the size's range)":
                               self.guidance.gear_refused,
                           "guidance STOP withheld (figure too fast, or off the line)": self.guidance.stop_withheld,
                           "guidance STOPs for a standing aircraft": self.guidance.halted_stops,
                           "guidance figures held at STOP (measurement not taken)": self.guidance.held_at_stop,
                           "stand": self.guidance.stand.name, "aircraft type": self.guidance.aircraft.name,
                           "survey at the stop mark, along / across the line (95 %) m":
                               "{:.2f} / {:.2f}".format(*self.guidance.survey_95_m)})
        return values


def build(configs: dict) -> DockingProcessor:
    return DockingProcessor(configs[""], configs[NODE_PREFIX], configs[GUIDANCE_PREFIX])


SPEC = ProcessorSpec(NODE_NAME, {"": DockingConfig, NODE_PREFIX: DockingNodeConfig, GUIDANCE_PREFIX: GuidanceConfig},
                     build)


class DockingTrackerNode(PerceptionNode):
    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.attach_spec(SPEC)

    def on_config_changed(self, cfg) -> None:
        if isinstance(cfg, DockingConfig):
            self.processor.configure(cfg)
        elif isinstance(cfg, GuidanceConfig):
            self.processor.configure_guidance(cfg)
        else:  # detection age and drawing apply at once; topics and compression at restart
            self.processor.node = cfg


def main(args=None):
    return run_node(DockingTrackerNode, args)


if __name__ == "__main__":
    main()
