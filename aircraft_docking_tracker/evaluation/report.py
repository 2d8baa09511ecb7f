"""Evaluation reports: a printed or Markdown table per metric family and a JSON file (no ROS, no plots here)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

# what the table shows per family: (key, heading, format)
COLUMNS = {
    "sot": [("scored_frames", "frames", "{:d}"), ("success_auc", "AUC", "{:.3f}"),
            ("precision", "prec@20px", "{:.3f}"), ("success_at_0.5", "succ@0.5", "{:.3f}"),
            ("mean_iou", "mIoU", "{:.3f}"), ("mean_center_error", "CLE px", "{:.1f}"),
            ("lost_frames", "lost", "{:d}"), ("longest_loss", "max loss", "{:d}"),
            ("nose_error_median", "nose px", "{:.1f}"), ("stop_error_m", "stop err m", "{:.2f}"),
            ("missing_outputs", "no output", "{:d}")],
    "guidance": [("frames", "frames", "{:d}"), ("lateral_near_median", "lat. <15m p50 m", "{:.2f}"),
                 ("lateral_near_p95", "lat. <15m p95 m", "{:.2f}"), ("distance_near_median", "dist. <15m p50 m", "{:.2f}"),
                 ("distance_near_p95", "dist. <15m p95 m", "{:.2f}"), ("stop_at_m", "STOP at m", "{:.2f}"),
                 ("stop_lateral_error_m", "STOP lat. err m", "{:.2f}"), ("state_accuracy", "state acc.", "{:.3f}"),
                 ("missing_frames", "no output", "{:d}")],
    "mot": [("num_frames", "frames", "{:d}"), ("hota", "HOTA", "{:.3f}"), ("deta", "DetA", "{:.3f}"),
            ("assa", "AssA", "{:.3f}"), ("mota", "MOTA", "{:.3f}"), ("motp", "MOTP", "{:.3f}"),
            ("idf1", "IDF1", "{:.3f}"), ("num_switches", "IDSW", "{:d}"), ("num_fragmentations", "Frag", "{:d}"),
            ("mostly_tracked", "MT", "{:d}"), ("mostly_lost", "ML", "{:d}"), ("num_false_positives", "FP", "{:d}"),
            ("num_misses", "FN", "{:d}"), ("num_unique_objects", "GT ids", "{:d}")],
    "detection": [("frames", "frames", "{:d}"), ("ground_truth", "GT", "{:d}"), ("detections", "dets", "{:d}"),
                  ("detection_rate", "det. rate", "{:.3f}"), ("false_alarm_rate", "false-alarm", "{:.3f}"),
                  ("average_precision", "AP", "{:.3f}")],
    "speed": [("count", "msgs", "{:d}"), ("rate_hz", "rate Hz", "{:.2f}"), ("p50_ms", "lat p50 ms", "{:.1f}"),
              ("p95_ms", "p95 ms", "{:.1f}"), ("p99_ms", "p99 ms", "{:.1f}")],
}
TITLES = {"sot": "single target (OTB)", "guidance": "docking guidance (issue 15; STOP at: true distance to go when "
          "STOP was first shown)", "mot": "multi target (HOTA / CLEAR MOT / IDF1)",
          "detection": "detection (seed 003 Table 1)", "speed": "speed (per output topic)"}


def _cell(value, fmt: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    try:
        return fmt.format(int(value) if "d" in fmt else float(value))
    except (TypeError, ValueError):
        return str(value)


def format_table(family: str, rows: dict) -> str:
    """``rows``: run name -> metrics dict of one family. A fixed-width text table."""
    columns = COLUMNS[family]
    header = ["run"] + [c[1] for c in columns]
    body = [[name] + [_cell(r.get(key), fmt) for key, _, fmt in columns] for name, r in rows.items()]
    widths = [max(len(str(x)) for x in col) for col in zip(header, *body)]
    lines = [TITLES[family], "  ".join(h.rjust(w) for h, w in zip(header, widths))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in body]
    return "\n".join(lines)


def format_report(results: dict) -> str:
    """``results``: run name -> evaluate_bags() dict. One table per family present."""
    out = []
    for family in COLUMNS:
        rows = _family_rows(results, family)
        if rows:
            out.append(format_table(family, rows))
    return "\n\n".join(out)


def _family_rows(results: dict, family: str) -> dict:
    """``run name -> metrics`` of one family; speed rows are per ``run:topic``."""
    if family == "speed":
        return {f"{name}:{topic}": s for name, r in results.items() for topic, s in r.get("speed", {}).items()
                if isinstance(s, dict)}
    return {name: r[family] for name, r in results.items() if isinstance(r, dict) and family in r}


def markdown_table(headings: list[str], body: list[list[str]]) -> str:
    """A GitHub-flavoured Markdown table (first column left-aligned, the others right)."""
    def row(cells) -> str:
        return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"
    return "\n".join([row(headings), "|" + "|".join([":---"] + ["---:"] * (len(headings) - 1)) + "|",
                      *(row(r) for r in body)])


def format_markdown(results: dict, level: int = 3) -> str:
    """``results``: run name -> evaluate_bags() dict. A heading and a Markdown table per family
    present; a line saying so when nothing could be scored."""
    out = []
    for family, columns in COLUMNS.items():
        rows = _family_rows(results, family)
        if not rows:
            continue
        body = [[name] + [_cell(r.get(key), fmt) for key, _, fmt in columns] for name, r in rows.items()]
        out.append(f"{'#' * level} {TITLES[family]}\n\n" + markdown_table(["run"] + [c[1] for c in columns], body))
    return "\n\n".join(out) if out else "(nothing scored: no output and ground-truth topics in common)"


def sanitize(obj):
    """JSON-safe copy: numpy scalars and arrays to Python, NaN / infinity to None."""
    if isinstance(obj, dict):
        return {str(k): sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [sanitize(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return sanitize(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: str | Path, obj) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(sanitize(obj), indent=1, allow_nan=False))
    return path
