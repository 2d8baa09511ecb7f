"""Docking guidance against its ground truth (issue 15): lateral and distance errors, STOP placement, states.

Both inputs are per-frame ``GUIDANCE_DTYPE`` rows matched frame by frame (``docking/guidance`` against
``ground_truth/guidance``). A frame where the estimate has no figure (NaN: no track, lost) while the
truth has one counts as an infinite error: a display that shows nothing has not guided.
"""
from __future__ import annotations

import numpy as np

NEAR_M = 15.0               # "within the last 15 m" (issue 15)
STOP_WITHIN_M = 0.5         # STOP first shown with the nose within this of its mark (ICAO's stopping accuracy)
EARLY_M = 1.0               # a STOP shown with more than this still to go is early


def _spread(name: str, errors: np.ndarray) -> dict:
    """``<name>_median`` and ``<name>_p95`` of the absolute errors (NaN: none to take)."""
    errors = np.nan_to_num(np.abs(errors), nan=np.inf)
    if not len(errors):
        return {f"{name}_median": float("nan"), f"{name}_p95": float("nan")}
    # frames without a figure are infinite errors: interpolating between two of them would give NaN
    p95 = np.percentile(errors, 95) if np.isfinite(errors).all() else np.percentile(errors, 95, method="higher")
    return {f"{name}_median": float(np.median(errors)), f"{name}_p95": float(p95)}


def guidance_errors(estimate: np.ndarray, truth: np.ndarray, near_m: float = NEAR_M) -> dict:
    """Errors of ``estimate`` against ``truth`` (equal-length ``GUIDANCE_DTYPE`` arrays): the median and p95 of
    the absolute lateral and distance errors over every frame and within the last ``near_m`` (``*_near_*``), and of
    the closing speed's there;
    where STOP was first shown (``stop_at_m``: the true distance to go then; ``stop_nose_error_m``: the shown
    distance's error there), whether that is within 0.5 m, more than 1 m early, or never; the fraction of
    frames showing the true state."""
    from ..docking.guidance import STOP  # noqa: PLC0415

    if len(estimate) != len(truth):
        raise ValueError(f"guidance: {len(estimate)} estimated rows against {len(truth)} true ones")
    near = truth["distance_m"] <= near_m
    lateral = estimate["lateral_m"].astype(float) - truth["lateral_m"]
    distance = estimate["distance_m"].astype(float) - truth["distance_m"]
    speed = estimate["speed_mps"].astype(float) - truth["speed_mps"]
    shown = np.flatnonzero(estimate["state"] == STOP)
    first = int(shown[0]) if len(shown) else None
    stop_at = float(truth["distance_m"][first]) if first is not None else float("nan")
    return {
        **_spread("lateral", lateral), **_spread("lateral_near", lateral[near]),
        **_spread("distance", distance), **_spread("distance_near", distance[near]), "near_frames": int(near.sum()),
        **_spread("speed_near", speed[near]),
        "stop_frame": first, "stop_at_m": stop_at,
        "stop_nose_error_m": float(distance[first]) if first is not None else float("nan"),
        "stop_lateral_error_m": float(lateral[first]) if first is not None else float("nan"),
        "stop_within": bool(abs(stop_at) <= STOP_WITHIN_M), "stop_early": bool(stop_at > EARLY_M),
        "stop_missed": first is None,
        "state_accuracy": float(np.mean(estimate["state"] == truth["state"])) if len(truth) else float("nan"),
    }
