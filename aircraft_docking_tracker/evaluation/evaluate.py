"""``evaluate``: score an output bag (or results file) against its ground truth; table, JSON, plots.

    evaluate out.mcap                         (ground truth recorded in the same bag)
    evaluate ispf.mcap pf.mcap --gt scene.mcap --names ispf,pf --report out/report
    evaluate results.txt --gt ../shared/data/sot/Car4/groundtruth_rect.txt
    evaluate tracks.txt --gt ../shared/data/mot/TUD-Campus/gt.txt

The metric family follows from the topics present (output / ground truth):

* ``docking/polygon`` vs ``ground_truth/polygon`` -> single target (``sot_metrics``: OTB success
  AUC, precision at 20 px, lost frames; polygon IoU; nose error when ``ground_truth/stand`` and
  ``ground_truth/nose`` are there);
* ``docking/guidance`` vs ``ground_truth/guidance`` -> docking guidance (``guidance_metrics``: lateral and
  distance errors, median and p95, over the approach and within the last 15 m; where STOP was first shown;
  state accuracy; plotted over the distance to go);
* ``tracks`` vs ``ground_truth`` (rows with ``id``) -> multi target (``mot_metrics``: HOTA, DetA, AssA, MOTA, MOTP,
  IDF1, ID switches, fragmentations, MT/ML, seed 003 Fig. 4 continuity);
* ``detections`` vs ``ground_truth`` -> detection (``detection_metrics``: seed 003 Table 1 rates,
  PR curve, AP);
* speed: for each output topic, its rate and the latency from the input ``image`` (or
  ``detections``) with the same header stamp to the output, both from the recorder's log times.

Outputs and ground truth are matched by header stamp. A ground-truth frame with no output counts
as: single target - the last output held (``--missing hold``, default: what a viewer shows) or a
lost frame (``--missing lost``); multi target and detection - no objects. The number of such
frames is reported. Ground-truth rows marked hidden (``state`` 2 or visible fraction ``score`` below
``hidden_below``, the synthetic UAV scenes) are ignored: neither a miss when not found, nor a false
alarm when found (MOTChallenge's way with distractors).
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from aircraft_docking_tracker.io.bag import BagReader, header_stamp_ns
from aircraft_docking_tracker.config import add_config_arguments, config_from_arguments, param, validate
from aircraft_docking_tracker.docking.guidance import GUIDANCE_DTYPE, template_point
from aircraft_docking_tracker.evaluation import plots, report
from aircraft_docking_tracker.evaluation.detection_metrics import DetectionAccumulator, DetectionMetricsConfig
from aircraft_docking_tracker.evaluation.mot_metrics import MotEvaluator
from aircraft_docking_tracker.evaluation.sot_metrics import SotMetricsConfig, score_sequence
from aircraft_docking_tracker.geometry import box_iou, box_to_quad
from aircraft_docking_tracker.evaluation.speed import latency_percentiles, stream_fps
from aircraft_docking_tracker.images import to_bgr8
from aircraft_docking_tracker.object_table import TRACK_DTYPE, cloud_to_table, confident_rows, table_boxes
from aircraft_docking_tracker.scenarios import strips
from aircraft_docking_tracker.scenarios.datasets import mot_rows_to_tracks, read_results_regions, read_sot_boxes
from aircraft_docking_tracker.scenarios.messages import (DETECTIONS, DOCKING_GUIDANCE, DOCKING_POLYGON, GROUND_TRUTH,
                                                        GT_GUIDANCE, GT_NOSE, GT_POLYGON, GT_STAND, IMAGE, TRACKS,
                                                        polygon_to_quad)
from aircraft_docking_tracker.io import motchallenge

OUTPUT_TOPICS = (DOCKING_POLYGON, TRACKS, DETECTIONS)


class EvaluationError(ValueError):
    """Inputs that cannot be evaluated (no ground truth, nothing to compare); the message says why."""


@dataclass
class EvaluateConfig:
    """How outputs are scored."""

    iou_threshold: float = param(0.5, "IoU for a match (multi target, detection)", low=0.01, high=1.0)
    precision_px: float = param(20.0, "centre-error threshold of the single-target precision [px]", low=0.0, high=1000.0)
    lost_iou: float = param(0.0, "single target: a frame is lost when IoU <= this", low=0.0, high=1.0)
    missing: str = param("hold", "single target: a frame with no output holds the last one, or counts as lost",
                         choices=("hold", "lost"))
    track_states: str = param("1,2", "track states scored (0 tentative, 1 confirmed, 2 coasting published, 3 lost, "
                              "4 coasting unpublished); 1,2: what the association node publishes")
    hidden_below: float = param(0.3, "ground-truth rows whose visible fraction (score) is below this are ignored",
                                low=0.0, high=1.0)
    namespace: str = param("", "camera namespace of the topics (e.g. cam0); empty: the one there is")

    def validate(self) -> None:
        try:
            self.states()
        except ValueError:
            raise EvaluationError(f"track_states={self.track_states!r}: a comma-separated list of 0..4") from None

    def states(self) -> list[int]:
        return [int(s) for s in self.track_states.split(",") if s.strip()]


# --- reading -------------------------------------------------------------------------------------

@dataclass
class Stream:
    """One topic of a bag: stamp -> decoded value, and stamp -> log time."""

    values: dict
    log_ns: dict


def resolve_topics(available, wanted, namespace: str = "") -> dict:
    """``bag topic -> agreed relative name`` for each wanted name found in ``available``.

    A live recording holds absolute names (``/tracks``, ``/cam0/tracks``), a generated bag relative
    ones (``tracks``): ``namespace/name`` matches with or without the leading slash; with no
    namespace given, a single topic ending in ``/name`` matches too (several: say which namespace).
    """
    out = {}
    for name in wanted:
        full = f"{namespace.strip('/')}/{name}".strip("/")
        exact = [t for t in available if t.strip("/") == full]
        if not exact and not namespace:
            exact = [t for t in available if t.endswith("/" + name)]
        if len(exact) > 1:
            raise EvaluationError(f"several topics end in {name!r} ({', '.join(sorted(exact))}): give --namespace")
        if exact:
            out[exact[0]] = name
    return out


def read_streams(path: str | Path, topics, progress: bool = False, stamps_only=(IMAGE,), namespace: str = "",
                 problems: list | None = None) -> dict:
    """``topic -> Stream`` for the ``topics`` (agreed relative names) present in the bag; values are
    decoded messages (None for ``stamps_only`` topics, whose log times are all that is needed: images).
    ``problems``: gets what is wrong with the bag (truncated, damaged chunks), if anything."""
    reader = BagReader(path)
    names = resolve_topics(reader.topics, topics, namespace)
    streams = {name: Stream({}, {}) for name in names.values()}
    total = sum(reader.topics[t].count for t in names)
    for item in tqdm(reader.messages(list(names)), total=total, desc=f"reading {Path(path).name}",
                     disable=not progress or total < 2000, unit="msg"):
        name = names[item.topic]
        stream = streams[name]
        if name == GT_STAND:
            stream.values[0] = item.deserialize().data
            continue
        stamp = header_stamp_ns(item.data)
        stream.values[stamp] = None if name in stamps_only else item.deserialize()
        stream.log_ns[stamp] = item.log_time_ns
    if problems is not None and reader.problem and reader.problem not in problems:
        problems.append(reader.problem)
    return streams


_quad, _table = polygon_to_quad, cloud_to_table


# --- scoring, one family each ---------------------------------------------------------------------

def score_guidance(gt: dict, out: dict) -> dict:
    """``docking/guidance`` against ``ground_truth/guidance`` (one row each per stamp; a stamp without
    output holds the last row, as a display does, and none before the first counts as no figure), with the
    per-frame true distance to go and errors for the plots over distance."""
    from aircraft_docking_tracker.evaluation.guidance_metrics import guidance_errors  # noqa: PLC0415

    stamps = sorted(gt)
    truth = np.concatenate([gt[s][:1] for s in stamps]).astype(GUIDANCE_DTYPE)
    estimate = np.array([(np.nan, np.nan, np.nan, -1)] * len(stamps), dtype=GUIDANCE_DTYPE)
    held, missing = None, 0
    for k, s in enumerate(stamps):
        if s in out and len(out[s]):
            held = out[s][0]
        else:
            missing += 1
        if held is not None:
            estimate[k] = held
    result = guidance_errors(estimate, truth)
    result.update({"frames": len(stamps), "missing_frames": missing,
                   "true_distance_m": truth["distance_m"].tolist(),
                   "distance_error_m": (estimate["distance_m"] - truth["distance_m"]).tolist(),
                   "lateral_error_m": (estimate["lateral_m"] - truth["lateral_m"]).tolist()})
    return result


def score_sot(gt: dict, out: dict, cfg: EvaluateConfig, stand: dict | None = None, gt_nose: dict | None = None) -> dict:
    """``gt``, ``out``: stamp -> (4, 2) quad (NaN = absent / no output)."""
    stamps = sorted(gt)
    pred, missing, last = [], 0, np.full((4, 2), np.nan)
    for s in stamps:
        if s in out:
            last = out[s]
        else:
            missing += 1
            if cfg.missing == "lost":
                pred.append(np.full((4, 2), np.nan))
                continue
        pred.append(last)
    pred = np.array(pred).reshape(-1, 4, 2)
    truth = np.array([gt[s] for s in stamps]).reshape(-1, 4, 2)
    result = score_sequence(pred, truth, SotMetricsConfig(cfg.precision_px, cfg.lost_iou))
    result["missing_outputs"] = missing
    result["missing_policy"] = cfg.missing
    if stand and gt_nose:
        uv = np.array(stand["nose_template"]) / np.array(stand["template_size"], float)
        err = [np.linalg.norm(template_point(p, uv) - gt_nose[s]) for p, s in zip(pred, stamps) if s in gt_nose]
        err = np.array([e for e in err if np.isfinite(e)])
        result["nose_error_median"] = float(np.median(err)) if err.size else float("nan")
        result["nose_error_final"] = float(err[-1]) if err.size else float("nan")
        result.update(stop_errors(pred[-1], truth[-1], gt_nose.get(stamps[-1]), stand, uv))
    return result


def stop_errors(final_quad: np.ndarray, final_truth: np.ndarray, final_nose, stand: dict, nose_uv) -> dict:
    """Docking guidance at the last frame, in metres: how far the tracked aircraft is from the truth.

    Distance from the camera comes from the apparent size, as a docking guidance system reads it:
    depth = focal x (metres per template px) / scale, scale = sqrt(quad area / template area);
    ``stop_along_m`` = tracked depth - true depth (+ = the tracker sees the aircraft short of where
    it is); ``stop_lateral_m`` = horizontal nose offset x depth / focal; ``stop_error_m`` = both.
    """
    if final_nose is None or "metres_per_template_px" not in stand:
        return {}
    focal = stand["camera"]["focal_px"]
    template_area = float(np.prod(stand["template_size"]))

    def depth(quad):
        area = cv2.contourArea(np.asarray(quad, np.float32).reshape(-1, 1, 2))
        return focal * stand["metres_per_template_px"] / np.sqrt(area / template_area) if area > 0 else np.nan

    tracked = template_point(final_quad, nose_uv)
    along = depth(final_quad) - depth(final_truth) if np.isfinite(final_quad).all() else np.nan
    lateral = (tracked[0] - final_nose[0]) * depth(final_truth) / focal
    return {"stop_along_m": float(along), "stop_lateral_m": float(lateral), "stop_error_m": float(np.hypot(along, lateral))}


def hidden_rows(table: np.ndarray, cfg: EvaluateConfig) -> np.ndarray:
    """Ground-truth rows nobody is expected to see (synthetic UAV: hidden under trees or smoke)."""
    if len(table) == 0:
        return np.zeros(0, bool)
    hidden = np.zeros(len(table), bool)
    if "state" in table.dtype.names:
        hidden |= table["state"] == 2
    if "id" in table.dtype.names and "score" in table.dtype.names:
        hidden |= table["score"] < cfg.hidden_below
    return hidden


def on_hidden_targets(hyp: np.ndarray, truth: np.ndarray, hidden: np.ndarray, cfg: EvaluateConfig) -> np.ndarray:
    """Hypotheses that sit on a hidden target (``hidden``: :func:`hidden_rows` of ``truth``): IoU with one at least
    the threshold and above their IoU with any counted target. ``score_mot`` drops them, neither hit nor false
    positive."""
    if not hidden.any() or not len(hyp):
        return np.zeros(len(hyp), bool)
    iou_hidden = box_iou(table_boxes(hyp)[:, None], table_boxes(truth[hidden])[None]).max(axis=1)
    visible_boxes = table_boxes(truth[~hidden])
    iou_visible = (box_iou(table_boxes(hyp)[:, None], visible_boxes[None]).max(axis=1)
                   if len(visible_boxes) else np.zeros(len(hyp)))
    return (iou_hidden >= cfg.iou_threshold) & (iou_hidden > iou_visible)


def score_mot(gt: dict, out: dict, cfg: EvaluateConfig) -> dict:
    """``gt``, ``out``: stamp -> TRACK_DTYPE-like tables. motmetrics via ``mot_metrics.MotEvaluator``."""
    evaluator = MotEvaluator(cfg.iou_threshold)
    states = cfg.states()
    missing = 0
    for frame, s in enumerate(sorted(gt), start=1):
        truth = gt[s]
        hyp = out.get(s)
        if hyp is None:
            missing += 1
            hyp = np.zeros(0, TRACK_DTYPE)
        if "state" in hyp.dtype.names:
            hyp = hyp[np.isin(hyp["state"], states)]
        hidden = hidden_rows(truth, cfg)
        hyp = hyp[~on_hidden_targets(hyp, truth, hidden, cfg)]      # distractors: neither hit nor false positive
        truth = truth[~hidden]
        evaluator.update(frame, truth["id"], table_boxes(truth), hyp["id"], table_boxes(hyp))
    scores = evaluator.result()
    result = scores.as_dict(with_continuity=True)
    result["missing_outputs"] = missing
    result["timeline"] = timelines(evaluator)
    return result


def timelines(evaluator: MotEvaluator) -> dict:
    """gt id -> [[frame, track id or None], ...] from the accumulator's events."""
    events = evaluator.accumulator.mot_events
    events = events[events["Type"].isin(["MATCH", "SWITCH", "MISS"]) & events["OId"].notna()]
    out: dict = {}
    for (frame, _), row in events.iterrows():
        hyp = row["HId"]
        out.setdefault(int(row["OId"]), []).append([int(frame), None if hyp != hyp else int(hyp)])
    return {k: sorted(v) for k, v in sorted(out.items())}


def score_detection(gt: dict, out: dict, cfg: EvaluateConfig) -> dict:
    """``gt``, ``out``: stamp -> tables with x, y, w, h (and score for ``out``); rows flagged ``low_confidence``
    (offered to the association's second pass only) are not detections and not scored."""
    acc = DetectionAccumulator(DetectionMetricsConfig(cfg.iou_threshold))
    missing = 0
    for s in sorted(gt):
        truth = gt[s]
        dets = out.get(s)
        if dets is None:
            missing += 1
            dets = np.zeros(0, [("x", "f4"), ("y", "f4"), ("w", "f4"), ("h", "f4"), ("score", "f4")])
        dets = confident_rows(dets)
        acc.add_frame(table_boxes(dets), dets["score"], table_boxes(truth), hidden_rows(truth, cfg))
    result = acc.summary()
    result["missing_outputs"] = missing
    return result


def score_speed(streams: dict) -> dict:
    """Per output topic: message count, rate from log times, latency from the input with the same stamp.

    The input is ``detections`` for ``tracks`` (when recorded), else ``image``.
    """
    out = {}
    for topic in OUTPUT_TOPICS:
        if topic not in streams or not streams[topic].log_ns:
            continue
        logs = streams[topic].log_ns
        entry = {"count": len(logs), "rate_hz": stream_fps(sorted(logs.values()))}
        source = DETECTIONS if topic == TRACKS and DETECTIONS in streams else IMAGE
        if source in streams:
            inputs = streams[source].log_ns
            lat = [(logs[s] - inputs[s]) * 1e-9 for s in logs if s in inputs]
            if lat:
                entry.update(latency_percentiles(lat))
                entry["latency_from"] = source
        out[topic] = entry
    return out


# --- whole bags and files ---------------------------------------------------------------------------

def _decoded(streams: dict, topic: str, convert) -> dict:
    return {s: convert(v) for s, v in streams[topic].values.items()} if topic in streams else {}


def evaluate_streams(out_streams: dict, gt_streams: dict, config: EvaluateConfig | None = None) -> dict:
    """Every metric family whose output and ground-truth topics are both present."""
    cfg = validate(config or EvaluateConfig())
    result: dict = {}
    if DOCKING_POLYGON in out_streams and GT_POLYGON in gt_streams:
        stand = json.loads(gt_streams[GT_STAND].values[0]) if GT_STAND in gt_streams else None
        nose = {s: np.array([m.point.x, m.point.y]) for s, m in gt_streams[GT_NOSE].values.items()} \
            if GT_NOSE in gt_streams else None
        result["sot"] = score_sot(_decoded(gt_streams, GT_POLYGON, _quad), _decoded(out_streams, DOCKING_POLYGON, _quad),
                                  cfg, stand, nose)
    if DOCKING_GUIDANCE in out_streams and GT_GUIDANCE in gt_streams:
        guidance_rows = lambda msg: cloud_to_table(msg, GUIDANCE_DTYPE)  # noqa: E731
        result["guidance"] = score_guidance(_decoded(gt_streams, GT_GUIDANCE, guidance_rows),
                                            _decoded(out_streams, DOCKING_GUIDANCE, guidance_rows))
    gt_tables = _decoded(gt_streams, GROUND_TRUTH, _table)
    if TRACKS in out_streams and gt_tables:
        if any("id" not in t.dtype.names for t in gt_tables.values()):
            raise EvaluationError("ground_truth rows have no id: they are detection ground truth, not tracks")
        result["mot"] = score_mot(gt_tables, _decoded(out_streams, TRACKS, _table), cfg)
    if DETECTIONS in out_streams and gt_tables:
        result["detection"] = score_detection(gt_tables, _decoded(out_streams, DETECTIONS, _table), cfg)
    speed = score_speed(out_streams)
    if speed:
        result["speed"] = speed
    return result


def evaluate_bags(output_bag: str | Path, gt_bag: str | Path | None = None, config: EvaluateConfig | None = None,
                  progress: bool = False) -> dict:
    """Score ``output_bag`` against ``gt_bag`` (default: the ground truth inside ``output_bag``).

    Returns ``{"sot"|"guidance"|"mot"|"detection": metrics, "speed": {...}}`` for the families present;
    raises EvaluationError when no family can be scored.
    """
    cfg = validate(config or EvaluateConfig())
    problems: list[str] = []
    out_streams = read_streams(output_bag, (IMAGE, DETECTIONS, TRACKS, DOCKING_POLYGON, DOCKING_GUIDANCE), progress,
                               namespace=cfg.namespace, problems=problems)
    gt_path = gt_bag or output_bag
    gt_streams = read_streams(gt_path, (GROUND_TRUTH, GT_POLYGON, GT_NOSE, GT_STAND, GT_GUIDANCE), progress,
                              namespace=cfg.namespace, problems=problems)
    result = evaluate_streams(out_streams, gt_streams, cfg)
    if not {"sot", "mot", "detection", "guidance"} & set(result):
        raise EvaluationError(f"nothing to score: output topics {sorted(out_streams)}, ground truth topics "
                              f"{sorted(gt_streams)} in {gt_path}")
    result["inputs"] = {"output": str(output_bag), "ground_truth": str(gt_path),
                        "truncated": [str(p) for p in {output_bag, gt_path} if BagReader(p).truncated],
                        "problems": problems}
    return result


def _sot_gt_from_file(path: Path) -> dict:
    boxes, _ = read_sot_boxes(path)
    return dict(enumerate(box_to_quad(boxes)))


def _mot_tables_from_file(path: Path) -> dict:
    rows = motchallenge.read_ground_truth(path) if path.name.startswith("gt") else motchallenge.read_mot(path)
    return {frame: mot_rows_to_tracks(r) for frame, r in motchallenge.frames(rows)}


def evaluate_files(results: str | Path, gt: str | Path, config: EvaluateConfig | None = None) -> dict:
    """Score a results text file against a gt file or bag: OTB ``x,y,w,h`` lines, quadrilateral lines
    ``x1,y1,...,x4,y4`` (TL, TR, BR, BL; as ``sot_track --quads`` writes), or MOTChallenge rows.

    Frames are matched by order: line k of an OTB file, frame k of a MOTChallenge file, the k-th
    ground-truth message of a bag. A single-target results file shorter than its ground truth is
    scored on its own frames (``ground_truth_frames`` tells how many there were).
    """
    cfg = validate(config or EvaluateConfig())
    results, gt = Path(results), Path(gt)
    stand = gt_nose = None
    first = next((ln for ln in results.read_text().splitlines() if ln.strip()), "")
    columns = len(first.replace(",", " ").split())
    if gt.suffix == ".mcap" or gt.is_dir():
        streams = read_streams(gt, (GROUND_TRUTH, GT_POLYGON, GT_NOSE, GT_STAND), namespace=cfg.namespace)
        key = GT_POLYGON if columns in (4, 8) else GROUND_TRUTH
        if key not in streams:
            raise EvaluationError(f"{gt}: no {key} topic for a {'single' if key == GT_POLYGON else 'multi'}-target results file")
        convert = _quad if key == GT_POLYGON else _table
        stamps = sorted(streams[key].values)
        gt_frames = {k: convert(streams[key].values[s]) for k, s in enumerate(stamps, start=0 if key == GT_POLYGON else 1)}
        if GT_STAND in streams and GT_NOSE in streams:
            stand = json.loads(streams[GT_STAND].values[0])
            noses = streams[GT_NOSE].values
            gt_nose = {k: np.array([noses[s].point.x, noses[s].point.y]) for k, s in enumerate(stamps) if s in noses}
    else:
        gt_frames = _sot_gt_from_file(gt) if columns in (4, 8) else _mot_tables_from_file(gt)
    if columns in (4, 8):
        pred = dict(enumerate(read_results_regions(results)))
        # a results file shorter than the ground truth (a --max-frames run) is scored on its frames
        scored = {k: q for k, q in gt_frames.items() if k < len(pred)}
        result = score_sot(scored, pred, cfg, stand, gt_nose)
        result["ground_truth_frames"] = len(gt_frames)
        return {"sot": result, "inputs": {"output": str(results), "ground_truth": str(gt)}}
    if columns >= 6 and columns != 8:
        return {"mot": score_mot(gt_frames, _mot_tables_from_file(results), cfg),
                "inputs": {"output": str(results), "ground_truth": str(gt)}}
    raise EvaluationError(f"{results}: {columns} columns; OTB results have 4 (x,y,w,h), quadrilaterals 8, "
                          "MOTChallenge results at least 6")


# --- report ---------------------------------------------------------------------------------------

def write_plots(results: dict, folder: str | Path) -> list[Path]:
    """The report's PNGs for the families present in ``results`` (run name -> evaluate dict)."""
    folder = Path(folder)
    written = []
    sot = {name: r["sot"] for name, r in results.items() if "sot" in r}
    if sot:
        written.append(plots.success_precision_plot(sot, folder / "success_precision.png"))
        written.append(plots.iou_over_time_plot(sot, folder / "iou_over_time.png"))
    guidance = {name: r["guidance"] for name, r in results.items() if "guidance" in r}
    if guidance:
        written.append(plots.guidance_error_plot(guidance, folder / "guidance_errors.png"))
    mot = {name: r["mot"] for name, r in results.items() if "mot" in r}
    if mot:
        written.append(plots.continuity_bars({n: m["continuity"] for n, m in mot.items()}, folder / "continuity.png"))
        for name, m in mot.items():
            tl = {int(k): [(f, h) for f, h in v] for k, v in m["timeline"].items()}
            if tl:
                written.append(plots.timeline_plot(tl, folder / f"timeline_{name}.png", f"Tracking timeline: {name}"))
    det = {name: r["detection"] for name, r in results.items() if "detection" in r}
    if det:
        written.append(plots.pr_plot(det, folder / "pr.png"))
    return written


def annotated_frames(output_bag: str | Path, gt_bag: str | Path | None = None, count: int | None = None,
                     namespace: str = ""):
    """Yield ``(frame index, image)`` of the bag's ``image`` topic with ground truth (green; hidden
    targets red) and outputs (magenta: docking polygon, tracks with ids, else detections) drawn in;
    ``count``: only that many frames, evenly spaced. Yields nothing when neither bag holds images."""
    for source in (p for p in (output_bag, gt_bag) if p is not None):
        reader = BagReader(source)
        image_topic = next(iter(resolve_topics(reader.topics, (IMAGE,), namespace)), None)
        if image_topic is not None:
            break
    else:
        return
    n = reader.topics[image_topic].count
    wanted = set(np.linspace(0, n - 1, min(count, n)).astype(int).tolist()) if count else None
    outs = read_streams(output_bag, (DOCKING_POLYGON, TRACKS, DETECTIONS), namespace=namespace)
    gts = read_streams(gt_bag or output_bag, (GT_POLYGON, GROUND_TRUTH), namespace=namespace)
    drawn = ((gts, strips.GT_COLOR, GT_POLYGON, GROUND_TRUTH),
             (outs, strips.RESULT_COLOR, DOCKING_POLYGON, TRACKS if TRACKS in outs else DETECTIONS))
    for k, item in enumerate(reader.messages([image_topic])):
        if wanted is not None and k not in wanted:
            continue
        stamp = header_stamp_ns(item.data)
        image = to_bgr8(item.deserialize())
        for streams, color, polygon_topic, table_topic in drawn:
            quads = [_quad(streams[polygon_topic].values[stamp])] \
                if polygon_topic in streams and stamp in streams[polygon_topic].values else []
            table = _table(streams[table_topic].values[stamp]) \
                if table_topic in streams and stamp in streams[table_topic].values else None
            labels = table["id"].tolist() if table is not None and "id" in table.dtype.names else None
            hidden = hidden_rows(table, EvaluateConfig()) if table is not None and streams is gts else None
            image = strips.draw_annotations(image, quads=quads, boxes=table_boxes(table) if table is not None else (),
                                           color=color, labels=labels, hidden=hidden)
        yield k, image


def write_strip(output_bag: str | Path, gt_bag: str | Path | None, path: str | Path, count: int = 6,
                namespace: str = ""):
    """Six (``count``) annotated frames side by side as a PNG; None when there are no images."""
    frames = list(annotated_frames(output_bag, gt_bag, count, namespace))
    return strips.frame_strip([f[1] for f in frames], path, numbers=[f[0] for f in frames]) if frames else None


def write_video(output_bag: str | Path, gt_bag: str | Path | None, path: str | Path, namespace: str = "",
                progress: bool = False):
    """Every annotated frame into an MP4 (OpenCV ``mp4v``) at the bag's image rate; None without images."""
    writer = None
    for _, image in tqdm(annotated_frames(output_bag, gt_bag, None, namespace), desc="video",
                         disable=not progress, unit="frame"):
        if writer is None:
            reader = next(r for r in (BagReader(p) for p in (output_bag, gt_bag) if p is not None)
                          if resolve_topics(r.topics, (IMAGE,), namespace))
            count = reader.topics[next(iter(resolve_topics(reader.topics, (IMAGE,), namespace)))].count
            rate = (count - 1) / (reader.duration_ns * 1e-9) if reader.duration_ns > 0 and count > 1 else 10.0
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), float(min(rate, 120.0)),
                                     (image.shape[1], image.shape[0]))
        writer.write(image)
    if writer is None:
        return None
    writer.release()
    return Path(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="evaluate", description=__doc__.split("\n")[0])
    parser.add_argument("outputs", nargs="+", help="output bag(s) (.mcap or bag folder) or results file(s)")
    parser.add_argument("--gt", help="ground truth: bag, OTB groundtruth_rect.txt or MOTChallenge gt.txt "
                                     "(default: the ground truth inside each output bag)")
    parser.add_argument("--names", help="comma-separated run names (default: file names)")
    parser.add_argument("--report", help="folder for report.json and the PNG plots")
    parser.add_argument("--video", action="store_true", help="with --report: also annotated.mp4 of every frame")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    add_config_arguments(parser, EvaluateConfig)
    args = parser.parse_args(argv)
    names = args.names.split(",") if args.names else [Path(p).stem for p in args.outputs]
    if len(names) != len(args.outputs):
        parser.error(f"{len(names)} names for {len(args.outputs)} outputs")
    try:
        cfg = config_from_arguments(EvaluateConfig, args)
        results = {}
        for name, output in zip(names, args.outputs):
            if Path(output).suffix == ".txt":
                if not args.gt:
                    raise EvaluationError(f"{output}: a results file needs --gt")
                results[name] = evaluate_files(output, args.gt, cfg)
            else:
                results[name] = evaluate_bags(output, args.gt, cfg, progress=not args.quiet)
    except (ValueError, OSError) as exc:
        print(f"evaluate: {exc}", file=sys.stderr)
        return 2
    for name, r in results.items():
        for problem in r["inputs"].get("problems", []):  # truncated (a recording killed hard?) or damaged
            print(f"evaluate: warning: {problem}; scored what could be read", file=sys.stderr)
    print(report.format_report(results), flush=True)
    if args.report:
        folder = Path(args.report)
        report.write_json(folder / "report.json", results)
        written = write_plots(results, folder)
        first = args.outputs[0]
        if Path(first).suffix != ".txt":
            gt_bag = args.gt if args.gt and Path(args.gt).suffix == ".mcap" else None
            strip = write_strip(first, gt_bag, folder / "strip.png", namespace=cfg.namespace)
            video = write_video(first, gt_bag, folder / "annotated.mp4", cfg.namespace, not args.quiet) \
                if args.video else None
            written += [p for p in (strip, video) if p]
        print(f"\nreport: {folder / 'report.json'}" + "".join(f"\n        {p}" for p in written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
