"""Speed of a core: frames per second and per-frame latency percentiles (no ROS here).

Latencies are wall-clock seconds per processed frame. ``fps`` is frames / total processing time
(the throughput of the core alone), not the camera rate; ``stream_fps`` is the rate of a stream
from its time stamps.
"""
from __future__ import annotations

import time
from typing import Callable, Iterable

import numpy as np

LATENCY_PERCENTILES = (50.0, 95.0, 99.0)


def fps(latencies_s) -> float:
    """Frames per second of a core that took ``latencies_s`` seconds per frame."""
    lat = np.asarray(latencies_s, dtype=np.float64)
    total = float(lat.sum())
    return len(lat) / total if total > 0 else 0.0


def stream_fps(stamps_ns) -> float:
    """Mean rate [Hz] of a stream from its (sorted) time stamps in nanoseconds."""
    t = np.asarray(stamps_ns, dtype=np.float64)
    if len(t) < 2 or t[-1] <= t[0]:
        return 0.0
    return (len(t) - 1) / ((t[-1] - t[0]) * 1e-9)


def latency_percentiles(latencies_s, percentiles=LATENCY_PERCENTILES) -> dict:
    """``{"p50_ms": ..., "p95_ms": ..., "p99_ms": ..., "max_ms": ...}`` of per-frame latencies."""
    lat = np.asarray(latencies_s, dtype=np.float64) * 1e3
    if lat.size == 0:
        return {f"p{p:g}_ms": float("nan") for p in percentiles} | {"max_ms": float("nan")}
    out = {f"p{p:g}_ms": float(v) for p, v in zip(percentiles, np.percentile(lat, percentiles))}
    out["max_ms"] = float(lat.max())
    return out


def speed_summary(latencies_s) -> dict:
    """Frames, fps and latency percentiles in one dict (JSON-ready)."""
    return {"frames": int(len(latencies_s)), "fps": fps(latencies_s)} | latency_percentiles(latencies_s)


def time_calls(fn: Callable, items: Iterable, clock: Callable[[], float] = time.perf_counter):
    """Call ``fn(item)`` for each item; return ``(results, latencies_s)``."""
    results, latencies = [], []
    for item in items:
        start = clock()
        results.append(fn(item))
        latencies.append(clock() - start)
    return results, np.asarray(latencies)
