"""Plots and image strips of the evaluation reports (matplotlib with the Agg backend, OpenCV; no ROS).

* :func:`success_precision_plot` - OTB success and precision plots, one line per run, AUC and
  precision at 20 px in the legend (as the OTB toolkit labels them);
* :func:`pr_plot` - precision-recall curves with AP in the legend;
* :func:`continuity_bars` - seed 003 Fig. 4: per target, frames present vs frames of continuous
  tracking, each bar labelled with the target's first~last frame;
* :func:`timeline_plot` - per target, which track followed it in which frame (gaps = misses,
  colour changes = identity switches);
* :func:`frame_strip` / :func:`draw_annotations` - frames side by side with ground truth (green)
  and results (magenta) drawn in.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from aircraft_docking_tracker.object_table import table_boxes

GT_COLOR = (60, 220, 60)          # BGR
RESULT_COLOR = (230, 40, 230)
HIDDEN_COLOR = (40, 40, 230)


def _pyplot():
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


def success_precision_plot(runs: dict, path: str | Path, title: str = "") -> Path:
    """``runs``: name -> ``sot_metrics.score_sequence`` dict. Writes one PNG with both plots."""
    plt = _pyplot()
    fig, (ax_s, ax_p) = plt.subplots(1, 2, figsize=(10, 4))
    for name, s in runs.items():
        ax_s.plot(s["success_thresholds"], s["success_curve"], label=f"{name} [{s['success_auc']:.3f}]")
        ax_p.plot(s["precision_thresholds"], s["precision_curve"],
                  label=f"{name} [{s['precision']:.3f}]")
    ax_s.set(xlabel="overlap threshold", ylabel="success rate", title="Success plot (AUC)", xlim=(0, 1), ylim=(0, 1.02))
    ax_p.set(xlabel="location error threshold [px]", ylabel="precision",
             title="Precision plot (at 20 px)", xlim=(0, 50), ylim=(0, 1.02))
    for ax in (ax_s, ax_p):
        ax.grid(alpha=0.3)
        ax.legend(loc="lower left" if ax is ax_s else "lower right", fontsize=8)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def iou_over_time_plot(runs: dict, path: str | Path, title: str = "") -> Path:
    """Per-frame IoU and centre error of each run (where the track was lost shows at a glance)."""
    plt = _pyplot()
    fig, (ax_i, ax_e) = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    for name, s in runs.items():
        ax_i.plot(s["iou"], label=name, lw=1)
        err = np.array([np.nan if e is None else e for e in s["center_error"]], float)
        ax_e.plot(err, label=name, lw=1)
    ax_i.set(ylabel="IoU", ylim=(0, 1.02))
    ax_e.set(ylabel="centre error [px]", xlabel="scored frame")
    errors = [e for s in runs.values() for e in s["center_error"] if e is not None and e > 0]
    if errors:                                   # log scale needs a positive value (all lost: none)
        ax_e.set_yscale("log")
    ax_i.legend(fontsize=8)
    for ax in (ax_i, ax_e):
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def pr_plot(runs: dict, path: str | Path, title: str = "") -> Path:
    """``runs``: name -> ``detection_metrics`` summary dict (pr_precision, pr_recall, AP)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5, 4))
    for name, s in runs.items():
        ax.plot(s["pr_recall"], s["pr_precision"],
                label=f"{name} [AP {s['average_precision']:.3f}, DR {s['detection_rate']:.3f}, "
                      f"FAR {s['false_alarm_rate']:.3f}]")
    ax.set(xlabel="recall", ylabel="precision", xlim=(0, 1), ylim=(0, 1.02), title=title or "Precision-recall")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    return _save(fig, path)


def grouped_bars(ax, groups: list[str], series: dict[str, list[float]], colors=None, **tick_options) -> None:
    """Side-by-side bars on ``ax``: one group per x tick, one bar per series (in order), the tick
    labelled with the group at the centre of its bars; ``tick_options`` go to ``set_xticks``."""
    width = 0.8 / max(len(series), 1)
    x = np.arange(len(groups))
    for k, (label, values) in enumerate(series.items()):
        color = {} if colors is None else {"color": colors[k % len(colors)]}
        ax.bar(x + k * width, values, width, label=label, **color)
    ax.set_xticks(x + 0.4 - width / 2, groups, **tick_options)


def continuity_bars(runs: dict, path: str | Path, title: str = "") -> Path:
    """Seed 003 Fig. 4: ``runs``: name -> list of ``TargetContinuity``-like dicts, grouped per target."""
    plt = _pyplot()
    names = list(runs)
    targets = sorted({c["gt_id"] for r in runs.values() for c in r})
    span = {c["gt_id"]: c for r in runs.values() for c in r}
    fig, ax = plt.subplots(figsize=(max(6, 0.6 * len(targets) * (len(names) + 1)), 4))
    width = 0.8 / (len(names) + 1)
    x = np.arange(len(targets))
    ax.bar(x, [span[t]["frames_present"] for t in targets], width, color="0.8", label="frames present")
    for k, name in enumerate(names):
        by_id = {c["gt_id"]: c for c in runs[name]}
        ax.bar(x + (k + 1) * width, [by_id.get(t, {}).get("longest_continuous", 0) for t in targets], width,
               label=f"{name}: longest continuous tracking")
    for i, t in enumerate(targets):
        ax.text(x[i], span[t]["frames_present"], f"{span[t]['first_frame']}~{span[t]['last_frame']}",
                ha="center", va="bottom", fontsize=6, rotation=90)
    ax.set_xticks(x + width * len(names) / 2, [str(t) for t in targets])
    ax.set(xlabel="target (ground-truth id)", ylabel="frames", title=title or "Continuous tracking per target")
    ax.legend(fontsize=7)
    return _save(fig, path)


def timeline_plot(timelines: dict, path: str | Path, title: str = "") -> Path:
    """``timelines``: gt id -> list of (frame, track id or None). One row per target; colour = track id."""
    plt = _pyplot()
    ids = sorted(timelines)
    fig, ax = plt.subplots(figsize=(10, max(2.5, 0.3 * len(ids) + 1)))
    tab20 = plt.get_cmap("tab20")
    colors = [tab20(i) for i in range(20) if i not in (14, 15)]          # no greys: grey means missed
    for row, gt_id in enumerate(ids):
        frames = np.array([f for f, _ in timelines[gt_id]])
        hyps = [h for _, h in timelines[gt_id]]
        missed = frames[[h is None for h in hyps]]
        ax.scatter(missed, np.full(len(missed), row), marker=".", color="0.7", s=12)
        for hyp in sorted({h for h in hyps if h is not None}):
            sel = frames[[h == hyp for h in hyps]]
            ax.scatter(sel, np.full(len(sel), row), marker="|", color=colors[int(hyp) % len(colors)], s=40)
    ax.set_yticks(range(len(ids)), [str(i) for i in ids])
    ax.set(xlabel="frame", ylabel="target", title=title or "Tracking timeline (colour = track id, grey = missed)")
    return _save(fig, path)


def draw_annotations(image: np.ndarray, quads=(), boxes=(), color=GT_COLOR, labels=None, point=None,
                     hidden=None) -> np.ndarray:
    """A copy of ``image`` with quadrilaterals, ``x, y, w, h`` boxes (labels), and a point drawn in."""
    out = image.copy()
    for quad in quads:
        if np.isfinite(np.asarray(quad, float)).all():
            cv2.polylines(out, [np.round(np.asarray(quad)).astype(np.int32)], True, color, 2, cv2.LINE_AA)
    for k, (x, y, w, h) in enumerate(np.asarray(boxes, float).reshape(-1, 4)):
        c = HIDDEN_COLOR if hidden is not None and hidden[k] else color
        cv2.rectangle(out, (int(x), int(y)), (int(x + w), int(y + h)), c, 1, cv2.LINE_AA)
        if labels is not None:
            cv2.putText(out, str(labels[k]), (int(x), int(y) - 2), cv2.FONT_HERSHEY_SIMPLEX, 0.35, c, 1, cv2.LINE_AA)
    if point is not None and np.isfinite(np.asarray(point, float)).all():
        cv2.drawMarker(out, (int(point[0]), int(point[1])), color, cv2.MARKER_CROSS, 12, 2)
    return out


def annotate_scene_frame(frame) -> np.ndarray:
    """Ground truth drawn on a ``DockingFrame`` (quad, nose) or ``UavFrame`` (boxes, ids; hidden red)."""
    if hasattr(frame, "quad"):
        return draw_annotations(frame.image, quads=[frame.quad], point=frame.nose)
    gt = frame.ground_truth
    return draw_annotations(frame.image, boxes=table_boxes(gt), labels=gt["id"].tolist(), hidden=(gt["state"] == 2).tolist())


def strip_image(frames, tile_width: int = 427, caption: str = "", numbers=None) -> np.ndarray:
    """Scene frames (annotated with their ground truth) or plain images side by side, frame numbers
    (``numbers``, else the scene frame's index, else the position) on top."""
    tiles = []
    for k, frame in enumerate(frames):
        image = annotate_scene_frame(frame) if hasattr(frame, "image") else np.asarray(frame)
        scale = tile_width / image.shape[1]
        tile = cv2.resize(image, (tile_width, int(round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
        number = numbers[k] if numbers is not None else getattr(frame, "index", k)
        label = f"{caption + ' ' if caption and k == 0 else ''}frame {number}"
        cv2.putText(tile, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 2, cv2.LINE_AA)
        cv2.putText(tile, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(tile)
    if not tiles:
        raise ValueError("frame strip: no frames")
    height = max(t.shape[0] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, height - t.shape[0], 0, 2, cv2.BORDER_CONSTANT, value=(255, 255, 255))
             for t in tiles]
    return np.hstack(tiles)


def frame_strip(frames, path: str | Path, tile_width: int = 427, numbers=None) -> Path:
    """:func:`strip_image` written as a PNG."""
    return write_image(strip_image(frames, tile_width, numbers=numbers), path)


def write_image(image: np.ndarray, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")
    return path


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt  # noqa: PLC0415

    plt.close(fig)
    return path
