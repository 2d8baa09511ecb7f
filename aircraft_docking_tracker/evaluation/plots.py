"""Plots and image strips of the evaluation reports (matplotlib with the Agg backend; no ROS).

* :func:`success_precision_plot` - OTB success and precision plots, one line per run, AUC and
  precision at 20 px in the legend (as the OTB toolkit labels them);
* :func:`pr_plot` - precision-recall curves with AP in the legend;
* :func:`continuity_bars` - seed 003 Fig. 4: per target, frames present vs frames of continuous
  tracking, each bar labelled with the target's first~last frame;
* :func:`timeline_plot` - per target, which track followed it in which frame (gaps = misses,
  colour changes = identity switches);

The image strips (frames with ground truth and results drawn in) are ``scenarios.strips``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


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


def guidance_error_plot(runs: dict, path: str | Path, title: str = "", last_m: float = 60.0) -> Path:
    """Docking guidance: distance and lateral errors over the true distance to go (the last ``last_m``),
    with issue 15's bands (0.5 m, 0.25 m) and the 15 m line."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharex=True)
    for name, g in runs.items():
        d = np.asarray(g["true_distance_m"], float)
        keep = d <= last_m
        width = 1.0 if len(runs) <= 8 else 0.6
        axes[0].plot(d[keep], np.asarray(g["distance_error_m"], float)[keep], lw=width, label=name)
        axes[1].plot(d[keep], np.asarray(g["lateral_error_m"], float)[keep], lw=width, label=name)
    for ax, label, band in ((axes[0], "distance error [m]", 0.5), (axes[1], "lateral error [m]", 0.25)):
        ax.set_yscale("symlog", linthresh=1.0)      # linear within 1 m, where the targets are; a lost track still fits
        ax.axhspan(-band, band, color="g", alpha=0.12)
        ax.axvline(15.0, color="k", lw=0.5, ls="--")
        ax.set_xlabel("true distance to go [m]")
        ax.set_ylabel(label)
        ax.set_xlim(last_m, min(-1.0, ax.get_xlim()[1]))
        ax.grid(alpha=0.3)
    if len(runs) <= 8:
        axes[0].legend(fontsize=8)
    fig.suptitle(title or "Docking guidance errors over the distance to go")
    fig.tight_layout()
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


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt  # noqa: PLC0415

    plt.close(fig)
    return path
