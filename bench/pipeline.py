"""bench/pipeline.py: the live pipeline under load and faults, every node a separate process.

    python bench/pipeline.py [--quick]

Four measurements, side by side in one run (``--quick``: a few minutes; full: ~15 minutes):

1. **latency**: images from a publisher in this process, stamped with the wall clock at publish,
   through ``detector_node -> association_node`` (``tracks``) and through ``docking_tracker_node``
   (``docking/polygon``) at 10, 30, 60 Hz, 640x480 and 1280x720; receive time - header stamp at a
   subscriber here; frames in / handled / skipped from the nodes' ``/diagnostics``;
2. **memory**: ``mcap_play --loop`` of a UAV scenario bag through detector + association, each
   node's RSS (``/proc/<pid>/status``) sampled; start / end / slope; time jumps (one per pass);
3. **restart**: while ``mcap_play`` plays and ``mcap_record`` records, association_node is stopped
   and started again; tracks resume, the recording is complete (``BagReader``), the gap is counted;
4. **faults**: malformed images, CompressedImage garbage, NaN / negative-size detection rows,
   out-of-order and jumping stamps; every node still running, rejections counted with reasons.

Writes bench/results/pipeline.json, bench/results/pipeline.md and bench/plots/pipeline_*.png.
The machine is shared: numbers are noisy, read them as orders of magnitude and ratios.
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# One DDS domain for this run (inherited by every node process): other jobs on the machine stay apart.
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: E402

from aircraft_docking_tracker.io.bag import BagReader, get_message_class, ns_to_stamp  # noqa: E402
from aircraft_docking_tracker.config import package_config_dir  # noqa: E402
from aircraft_docking_tracker.images import numpy_to_compressed, numpy_to_image  # noqa: E402
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, table_to_cloud  # noqa: E402
from aircraft_docking_tracker.processes import NodeProcess, wait_until  # noqa: E402
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: E402
from aircraft_docking_tracker.scenarios.make_scenario import write_uav_bag  # noqa: E402
from aircraft_docking_tracker.scenarios.uav import UavScene, UavSceneConfig  # noqa: E402
from multi_target_tracker.detector import DetectorConfig, DetectorError, resolve_model  # noqa: E402

RESULTS = ROOT / "bench" / "results"
PLOTS = ROOT / "bench" / "plots"
RELIABLE = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CLOUD = "sensor_msgs/msg/PointCloud2"
POLYGON = "geometry_msgs/msg/PolygonStamped"


@dataclass
class Settings:
    quick: bool
    rates: tuple = (10, 30, 60)
    sizes: tuple = ((640, 480), (1280, 720))
    stream_s: float = 10.0            # per latency cell
    distinct_frames: int = 40         # rendered frames per size, published in a cycle
    loop_s: float = 600.0             # memory: replay loop length
    loop_bag_frames: int = 250        # frames of the looped bag (25 fps)
    rss_every_s: float = 5.0
    restart_after_s: float = 12.0     # restart: association stopped after this much playing
    restart_down_s: float = 3.0       # ... and started again after this pause
    restart_tail_s: float = 12.0      # ... then played this long more
    fault_repeats: int = 3

    @classmethod
    def make(cls, quick: bool) -> "Settings":
        if not quick:
            return cls(quick=False)
        return cls(quick=True, stream_s=4.0, distinct_frames=20, loop_s=60.0, loop_bag_frames=100,
                   rss_every_s=2.5, restart_after_s=6.0, restart_down_s=2.0, restart_tail_s=8.0, fault_repeats=2)


# Transports: "profile" is what every make command uses (tools/ros_env.sh sets the shipped
# config/fastdds_large_images.xml: 32 MB shared-memory segments); "builtin" is Fast DDS with no profile
# (512 KB segments: larger images go over UDP in fragments, and best-effort loses them under load).
TRANSPORTS = ("profile", "builtin")
PROFILE_VARS = ("FASTDDS_DEFAULT_PROFILES_FILE", "FASTRTPS_DEFAULT_PROFILES_FILE")


def use_transport(name: str) -> str:
    """Set this process's (and its nodes') Fast DDS profile; returns what was used."""
    for var in PROFILE_VARS:
        os.environ.pop(var, None)
    if name == "builtin":
        return "Fast DDS built-in transports (no profile)"
    path = package_config_dir() / "fastdds_large_images.xml"
    for var in PROFILE_VARS:
        os.environ[var] = str(path)
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


# ---------------------------------------------------------------------------------- shared helpers
# The cascade for UAV scenes at the scene's own height (ground_resolution 1), which this bench plays; the
# UAV set-up (config/uav_camera.yaml) flies 3x lower with uav_vehicles_heading.json (bench/uav_detector.py).
UAV_MODEL = "uav_vehicles_fused.json"
def detector_parameters() -> dict:
    """The UAV cascade for the bench's scene height (``UAV_MODEL``) if shipped, else the
    configured default, else an OpenCV Haar cascade shipped with cv2 (the bench still measures the pipeline).
    config/detector.yaml's box regressor and grouping belong to the drone-view model: with any other model, no
    regressor and the dataclass's grouping."""
    defaults = DetectorConfig()
    other_model = {"box_regressor": "", "min_neighbors": defaults.min_neighbors, "window_margin": defaults.window_margin}
    for model in (UAV_MODEL, defaults.model):
        try:
            resolve_model(model)
            return {"model": model} if model == defaults.model else {"model": model, **other_model}
        except DetectorError:
            continue
    import cv2  # noqa: PLC0415

    return {"backend": "opencv", **other_model,
            "model": str(Path(cv2.data.haarcascades) / "haarcascade_frontalface_default.xml")}


def rss_mb(pid: int) -> float | None:
    """Resident set size of a process [MB] from /proc (psutil is not installed)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None


def percentiles(values_ms) -> dict:
    if len(values_ms) == 0:
        return {"p50": None, "p95": None, "p99": None}
    p = np.percentile(np.asarray(values_ms, float), [50, 95, 99])
    return {"p50": round(float(p[0]), 1), "p95": round(float(p[1]), 1), "p99": round(float(p[2]), 1)}


def as_int(value) -> int:
    try:
        return int(float(value))
    except (TypeError, ValueError):
        return 0


class Probe:
    """This process's ROS node: publishes the inputs, times the outputs, keeps the latest diagnostics."""

    def __init__(self):
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("pipeline_bench_probe", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._publishers = {}
        self.arrivals: dict[str, list[tuple[int, int]]] = {}   # topic -> (receive ns, stamp ns)
        self.diagnostics: dict[str, tuple[int, dict]] = {}      # node FQN -> (receive ns, values)
        self._lock = threading.Lock()
        self.node.create_subscription(get_message_class("diagnostic_msgs/msg/DiagnosticArray"), "/diagnostics",
                                      self._on_diagnostics, RELIABLE)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()

    def now_ns(self) -> int:
        return self.node.get_clock().now().nanoseconds

    def publisher(self, topic: str, type_name: str, qos=qos_profile_sensor_data):
        key = (topic, type_name)
        if key not in self._publishers:
            self._publishers[key] = self.node.create_publisher(get_message_class(type_name), topic, qos)
        return self._publishers[key]

    def publish(self, topic: str, type_name: str, msg, stamp_ns: int | None = None, qos=qos_profile_sensor_data):
        """Publish ``msg`` with its header stamped ``stamp_ns`` (default: the clock now)."""
        msg.header.stamp = ns_to_stamp(self.now_ns() if stamp_ns is None else stamp_ns)
        self.publisher(topic, type_name, qos).publish(msg)

    def connect(self, topic: str, type_name: str, qos=qos_profile_sensor_data, timeout_s: float = 30.0) -> bool:
        """Wait until a subscriber matched our publisher, then a moment more (discovery settles)."""
        pub = self.publisher(topic, type_name, qos)
        ok = wait_until(lambda: pub.get_subscription_count() > 0, timeout_s)
        time.sleep(1.0)
        return ok

    def watch(self, topic: str, type_name: str) -> list:
        """Record (receive time, header stamp) of every message on ``topic``."""
        if topic not in self.arrivals:
            self.arrivals[topic] = []

            def on_message(msg, arrivals=self.arrivals[topic]):
                stamp = msg.header.stamp
                arrivals.append((self.now_ns(), stamp.sec * 1_000_000_000 + stamp.nanosec))

            self.node.create_subscription(get_message_class(type_name), topic, on_message, RELIABLE)
        return self.arrivals[topic]

    def _on_diagnostics(self, msg) -> None:
        now = self.now_ns()
        with self._lock:
            for status in msg.status:
                self.diagnostics[status.hardware_id] = (now, {kv.key: kv.value for kv in status.values})

    def diag(self, fqn: str, newer_than_ns: int = 0, timeout_s: float = 5.0) -> dict:
        """The node's diagnostics values, waiting for a report received after ``newer_than_ns``."""
        wait_until(lambda: self.diagnostics.get(fqn, (0, {}))[0] > newer_than_ns, timeout_s, 0.05)
        with self._lock:
            return dict(self.diagnostics.get(fqn, (0, {}))[1])

    def fresh_diag(self, *fqns: str) -> dict[str, dict]:
        now = self.now_ns()
        return {fqn: self.diag(fqn, now) for fqn in fqns}

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


COUNTERS = ("received", "processed", "skipped", "rejected", "time_jumps")


def counter_delta(before: dict, after: dict, keys=COUNTERS) -> dict:
    return {k: as_int(after.get(k)) - as_int(before.get(k)) for k in keys}


class Nodes:
    """Node processes of one measurement (started together, stopped on exit), logs in ``log_dir``."""

    def __init__(self, probe: Probe, log_dir: Path, specs: dict[str, NodeProcess]):
        self.probe, self.log_dir, self.procs = probe, log_dir, specs
        for name, proc in specs.items():
            proc.log_path = log_dir / f"{name}.log"

    def __enter__(self) -> "Nodes":
        for proc in self.procs.values():
            proc.start()
        for name, proc in self.procs.items():
            if proc.executable.endswith("_node"):
                fqn = self.fqn(name)
                if not wait_until(lambda f=fqn: f in self.probe.diagnostics, 60):
                    raise RuntimeError(f"{fqn} did not report diagnostics:\n{self.log(name)[-2000:]}")
        return self

    def __exit__(self, *exc) -> None:
        for proc in self.procs.values():
            proc.stop()

    def fqn(self, name: str) -> str:
        proc = self.procs[name]
        base = {"detector_node": "detector", "association_node": "association",
                "docking_tracker_node": "docking_tracker"}[proc.executable]
        return f"/{proc.namespace.strip('/')}/{proc.node_name or base}"

    def log(self, name: str) -> str:
        path = self.log_dir / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def running(self, name: str) -> bool:
        return self.procs[name].running()


def node(executable: str, namespace: str, **parameters) -> NodeProcess:
    params_file = package_config_dir() / {"detector_node": "detector.yaml", "association_node": "association.yaml",
                                          "docking_tracker_node": "docking_tracker.yaml"}[executable]
    return NodeProcess(executable, namespace=namespace, params_file=params_file, parameters=parameters)


def image_messages(kind: str, size: tuple[int, int], count: int, seed: int = 3) -> list:
    """Rendered scenario frames as ready ``sensor_msgs/Image`` messages (bgr8)."""
    width, height = size
    if kind == "uav":
        scene = UavScene(UavSceneConfig(width=width, height=height, frames=count), seed=seed)
    else:
        scene = DockingScene(DockingSceneConfig(width=width, height=height, frames=count), seed=seed)
    return [numpy_to_image(frame.image, "bgr8") for frame in scene.frames()]


def settle(arrivals: list, quiet_s: float = 2.0, timeout_s: float = 20.0) -> None:
    """Wait until no message has arrived for ``quiet_s`` (at most ``timeout_s``)."""
    state = {"n": -1, "since": time.monotonic()}

    def quiet() -> bool:
        if len(arrivals) != state["n"]:
            state["n"], state["since"] = len(arrivals), time.monotonic()
        return time.monotonic() - state["since"] >= quiet_s

    wait_until(quiet, timeout_s)


def stream(probe: Probe, topic: str, messages: list, rate_hz: float, duration_s: float) -> int:
    """Publish ``messages`` in a cycle at ``rate_hz`` (wall-clock stamps at publish); returns the count."""
    period = 1.0 / rate_hz
    start = time.monotonic()
    sent = 0
    while time.monotonic() - start < duration_s:
        target = start + sent * period
        delay = target - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        probe.publish(topic, IMAGE, messages[sent % len(messages)])
        sent += 1
    return sent


# ---------------------------------------------------------------------------------- 1. latency
PIPELINES = {  # name -> (image topic, output topic, output type, nodes whose diagnostics are reported)
    "detector→association (tracks)": ("/lat/image", "/lat/tracks", CLOUD, ("detector", "association")),
    "docking_tracker (docking/polygon)": ("/dock/image", "/dock/docking/polygon", POLYGON, ("docking_tracker",)),
}


STATE_KEYS = ("docking state", "track starts", "tracks published", "detections last frame")


def docking_init(probe: Probe, size: tuple[int, int]) -> None:
    """Start the docking track on a central box (2-point docking/init): it tracks, not waits."""
    msg = get_message_class(POLYGON)()
    width, height = size
    point = get_message_class("geometry_msgs/msg/Point32")
    msg.polygon.points = [point(x=0.35 * width, y=0.35 * height), point(x=0.65 * width, y=0.65 * height)]
    probe.publish("/dock/docking/init", POLYGON, msg, qos=RELIABLE)


def measure_latency(probe: Probe, settings: Settings, log_dir: Path) -> list[dict]:
    det_params = detector_parameters()
    specs = {"detector": node("detector_node", "lat", **det_params),
             "association": node("association_node", "lat"),
             "docking_tracker": node("docking_tracker_node", "dock")}
    rows = []
    with Nodes(probe, log_dir, specs) as nodes:
        for topic, (image_topic, out_topic, out_type, _) in PIPELINES.items():
            probe.watch(out_topic, out_type)
            probe.connect(image_topic, IMAGE)
        probe.publisher("/dock/docking/init", POLYGON, RELIABLE)
        for size in settings.sizes:
            frames = {"uav": image_messages("uav", size, settings.distinct_frames),
                      "docking": image_messages("docking", size, settings.distinct_frames)}
            for rate in settings.rates:
                for pipeline, (image_topic, out_topic, _, reported) in PIPELINES.items():
                    fqns = [nodes.fqn(n) for n in reported]
                    if "docking" in pipeline:
                        docking_init(probe, size)
                    before = probe.fresh_diag(*fqns)
                    arrivals = probe.arrivals[out_topic]
                    first = len(arrivals)
                    t0 = probe.now_ns()
                    sent = stream(probe, image_topic, frames["docking" if "docking" in pipeline else "uav"],
                                  rate, settings.stream_s)
                    settle(arrivals)  # the frames still in the nodes come out
                    after = probe.fresh_diag(*fqns)
                    got = [(r - s) / 1e6 for r, s in arrivals[first:] if s >= t0]
                    deltas = {n: counter_delta(before[f], after[f]) for n, f in zip(reported, fqns)}
                    head = deltas[reported[0]]
                    rows.append({"pipeline": pipeline, "size": f"{size[0]}x{size[1]}", "rate_hz": rate,
                                 "published": sent, "in_node": head["received"] + head["skipped"],
                                 "handled": head["received"], "skipped": head["skipped"],
                                 "lost_in_transport": sent - head["received"] - head["skipped"],
                                 "outputs": len(got), "latency_ms": percentiles(got),
                                 "processing_ms_p50": {n: after[f].get("processing_ms_p50") for n, f in zip(reported, fqns)},
                                 "nodes": deltas, "alive": all(nodes.running(n) for n in reported),
                                 "state": {k: after[f][k] for f in fqns for k in STATE_KEYS if k in after[f]}})
                    print(f"latency {pipeline} {size} {rate} Hz: {rows[-1]['latency_ms']} "
                          f"in {rows[-1]['in_node']} skipped {head['skipped']} out {len(got)}", flush=True)
    return rows


# ---------------------------------------------------------------------------------- 2. memory
def uav_bag(path: Path, frames: int) -> Path:
    write_uav_bag(UavScene(UavSceneConfig(frames=frames), seed=5), path, progress=False, overwrite=True)
    return path


def player(bag: Path, namespace: str, *extra: str) -> NodeProcess:
    return NodeProcess("mcap_play", args=[bag, "--topics", "image", "--remap", f"image:=/{namespace}/image",
                                          "--wait-for-subscribers", "20", "--delay", "2", *extra])


def fit_slope_mb_per_min(samples: list[tuple[float, float]]) -> float | None:
    if len(samples) < 3:
        return None
    t, mb = np.array(samples).T
    return round(float(np.polyfit(t / 60.0, mb, 1)[0]), 3)


def rss_summary(series: list[tuple[float, float]], duration_s: float) -> dict:
    """Start / end / max RSS and slopes: of every sample, after a 20 % warm-up, and of the floor (the
    smallest sample of each tenth of the run: a frame's working memory comes and goes, a leak stays)."""
    warm = [s for s in series if s[0] >= 0.2 * duration_s]
    bins = np.minimum((np.array([t for t, _ in series]) / duration_s * 10).astype(int), 9)
    floor = [min((s for s, b in zip(series, bins) if b == k), key=lambda s: s[1]) for k in sorted(set(bins))]
    return {"rss_start_mb": round(series[0][1], 1), "rss_end_mb": round(series[-1][1], 1),
            "rss_max_mb": round(max(m for _, m in series), 1),
            "rss_floor_first_mb": round(floor[0][1], 1), "rss_floor_last_mb": round(floor[-1][1], 1),
            "slope_mb_per_min": fit_slope_mb_per_min(series),
            "slope_after_warmup_mb_per_min": fit_slope_mb_per_min(warm),
            "floor_slope_after_warmup_mb_per_min": fit_slope_mb_per_min([f for f in floor if f[0] >= 0.2 * duration_s])}


def measure_memory(probe: Probe, settings: Settings, log_dir: Path, bag: Path) -> dict:
    specs = {"detector": node("detector_node", "loop", **detector_parameters()),
             "association": node("association_node", "loop"),
             "player": player(bag, "loop", "--loop")}
    tracks = probe.watch("/loop/tracks", CLOUD)
    samples: dict[str, list[tuple[float, float]]] = {"detector": [], "association": []}
    with Nodes(probe, log_dir, specs) as nodes:
        wait_until(lambda: len(tracks) > 0, 60)
        start = time.monotonic()
        while time.monotonic() - start < settings.loop_s:
            for name in samples:
                mb = rss_mb(nodes.procs[name].process.pid)
                if mb is not None:
                    samples[name].append((time.monotonic() - start, mb))
            time.sleep(settings.rss_every_s)
        diag = {name: probe.fresh_diag(nodes.fqn(name))[nodes.fqn(name)] for name in samples}
        alive = {name: nodes.running(name) for name in specs}
    out = {"duration_s": settings.loop_s, "bag_frames": settings.loop_bag_frames, "bag_fps": 25.0,
           "passes": round(settings.loop_s * 25.0 / settings.loop_bag_frames, 1), "tracks_received": len(tracks),
           "alive": alive, "nodes": {}}
    for name, series in samples.items():
        out["nodes"][name] = {**rss_summary(series, settings.loop_s),
                              **{k: as_int(diag[name].get(k)) for k in ("time_jumps", "processed", "skipped", "rejected")},
                              "samples": [(round(t, 1), round(m, 2)) for t, m in series]}
    print(f"memory: {json.dumps({k: {kk: vv for kk, vv in v.items() if kk != 'samples'} for k, v in out['nodes'].items()})}",
          flush=True)
    return out


# ---------------------------------------------------------------------------------- 3. restart
def largest_gap(times_ns: list[int]) -> tuple[int, int]:
    times = sorted(times_ns)
    i = int(np.argmax(np.diff(times)))
    return times[i], times[i + 1]


def measure_restart(probe: Probe, settings: Settings, log_dir: Path, bag: Path) -> dict:
    recording = log_dir / "restart.mcap"
    specs = {"detector": node("detector_node", "rs", **detector_parameters()),
             "association": node("association_node", "rs"),
             "recorder": NodeProcess("mcap_record", args=["/rs/detections", "/rs/tracks", "-o", recording]),
             "player": player(bag, "rs", "--loop")}
    tracks = probe.watch("/rs/tracks", CLOUD)
    with Nodes(probe, log_dir, specs) as nodes:
        wait_until(lambda: len(tracks) > 0, 60)
        time.sleep(settings.restart_after_s)
        association = nodes.procs["association"]
        stopped_at = probe.now_ns()
        exit_code = association.stop()
        stop_s = (probe.now_ns() - stopped_at) / 1e9
        time.sleep(settings.restart_down_s)
        association.log_path = log_dir / "association_restarted.log"
        started_at = probe.now_ns()
        association.start()
        resumed = wait_until(lambda: tracks[-1][0] > started_at, 60)
        resumed_after_s = (tracks[-1][0] - started_at) / 1e9 if resumed else None
        time.sleep(settings.restart_tail_s)
        nodes.procs["player"].stop()
        time.sleep(1.0)
        recorder_exit = nodes.procs["recorder"].stop()
        alive = {n: nodes.running(n) for n in ("detector", "association")}
    reader = BagReader(recording)
    counts = {t: 0 for t in ("/rs/detections", "/rs/tracks")}
    log_times = {t: [] for t in counts}
    for m in reader.messages():
        counts[m.topic] += 1
        log_times[m.topic].append(m.log_time_ns)
    gap_from, gap_to = largest_gap(log_times["/rs/tracks"])
    missing = sum(gap_from < t < gap_to for t in log_times["/rs/detections"])
    out = {"association_exit_code_on_stop": exit_code, "recorder_exit_code": recorder_exit,
           "stop_took_s": round(stop_s, 2), "down_s": settings.restart_down_s, "resumed": bool(resumed),
           "first_tracks_after_start_s": None if resumed_after_s is None else round(resumed_after_s, 2), "recording_truncated": reader.truncated,
           "recording_messages": counts, "recording_index_count": reader.message_count,
           "tracks_gap_s": round((gap_to - gap_from) / 1e9, 2), "detections_without_tracks": missing,
           "tracks_after_restart": sum(t > gap_to for t in log_times["/rs/tracks"]), "alive_after": alive}
    print(f"restart: {out}", flush=True)
    return out


# ---------------------------------------------------------------------------------- 4. faults
def bad_image(width=64, height=48, encoding="bgr8", step=None, data=None):
    msg = get_message_class(IMAGE)()
    msg.width, msg.height, msg.encoding = width, height, encoding
    msg.step = width * 3 if step is None else step
    msg.data = bytes(msg.step * height) if data is None else data
    return msg


def nan_32fc1(width=64, height=48):
    return numpy_to_image(np.full((height, width), np.nan, np.float32), "32FC1")


def good_image():
    rng = np.random.default_rng(0)
    return numpy_to_image(rng.integers(0, 255, (120, 160, 3), dtype=np.uint8), "bgr8")


def compressed(data: bytes, fmt: str = "jpeg"):
    msg = get_message_class(COMPRESSED)()
    msg.format, msg.data = fmt, data
    return msg


def detections(*rows):
    table = np.zeros(len(rows), DETECTION_DTYPE)
    for i, (x, y, w, h) in enumerate(rows):
        table[i] = (x, y, w, h, 1.0, 0)
    return table_to_cloud(table)


def cloud_wrong_fields():
    msg = table_to_cloud(np.zeros(2, DETECTION_DTYPE))
    msg.fields = msg.fields[:2]
    return msg


def cloud_short_data():
    msg = table_to_cloud(np.zeros(3, DETECTION_DTYPE))
    msg.data = bytes(msg.data[:10])
    return msg


def good_compressed():
    return numpy_to_compressed(np.full((48, 64, 3), 128, np.uint8))


GOOD_BOX = (10.0, 10.0, 20.0, 20.0)
HOUR_NS = 3600 * 10**9
# (node, fault, message factory, stamp offset from now [ns]); the last rows of each node show it still works
FAULTS = [
    *[(target, name, factory, 0) for target in ("detector", "docking_tracker") for name, factory in [
        ("Image data shorter than step*height", lambda: bad_image(data=bytes(100))),
        ("Image unknown encoding", lambda: bad_image(encoding="yuv_magic")),
        ("Image zero size", lambda: bad_image(width=0, height=0, data=b"")),
        ("Image 32FC1 all NaN", nan_32fc1),
        ("Image wrong step (< width*channels)", lambda: bad_image(step=64 * 3 - 7)),
    ]],
    ("detector_compressed", "CompressedImage garbage bytes", lambda: compressed(b"\x00garbage" * 50), 0),
    ("detector_compressed", "CompressedImage empty", lambda: compressed(b""), 0),
    ("detector_compressed", "CompressedImage unknown format", lambda: compressed(b"\x89PNG" + bytes(40), "webp2"), 0),
    ("association", "detection row NaN x", lambda: detections((np.nan, 1.0, 5.0, 5.0), GOOD_BOX), 0),
    ("association", "detection row negative size", lambda: detections((1.0, 1.0, -5.0, 5.0), GOOD_BOX), 0),
    ("association", "detection row zero height / inf", lambda: detections((1.0, 1.0, 5.0, 0.0), (np.inf, 1, 2, 2)), 0),
    ("association", "PointCloud2 missing fields", cloud_wrong_fields, 0),
    ("association", "PointCloud2 data shorter than rows", cloud_short_data, 0),
    *[(target, name, factory, offset) for target, factory in [
        ("detector", good_image), ("docking_tracker", good_image),
        ("association", lambda: detections(GOOD_BOX)), ("detector_compressed", good_compressed),
    ] for name, offset in [("valid input (control)", 0), ("stamp out of order (-10 s)", -10 * 10**9),
                           ("stamp jumps forward (+1 h)", HOUR_NS), ("valid input after the jump", 0)]],
]
FAULT_TARGETS = {  # node -> (topic, type)
    "detector": ("/flt/image", IMAGE), "docking_tracker": ("/fltd/image", IMAGE),
    "detector_compressed": ("/fltc/image", COMPRESSED), "association": ("/flta/detections", CLOUD),
}


EXTRA_COUNTERS = {"association": ("invalid detection rows", "track resets")}


def new_log_reasons(text: str) -> list[str]:
    return sorted(set(re.findall(r"rejected input: (.*)", text)))


def measure_faults(probe: Probe, settings: Settings, log_dir: Path) -> list[dict]:
    det = detector_parameters()
    specs = {"detector": node("detector_node", "flt", **det),
             "detector_compressed": node("detector_node", "fltc", **det, **{"node.compressed": True}),
             "association": node("association_node", "flta"),
             "docking_tracker": node("docking_tracker_node", "fltd", initial_box=[40.0, 30.0, 40.0, 40.0])}
    rows = []
    with Nodes(probe, log_dir, specs) as nodes:
        for name, (topic, type_name) in FAULT_TARGETS.items():
            qos = RELIABLE if type_name == CLOUD else qos_profile_sensor_data
            probe.connect(topic, type_name, qos)
        last = {name: probe.fresh_diag(nodes.fqn(name))[nodes.fqn(name)] for name in specs}
        per_node = {name: [f for f in FAULTS if f[0] == name] for name in specs}
        for step in itertools.zip_longest(*per_node.values()):  # the nodes are independent: one fault each at once
            step = [f for f in step if f is not None]
            log_before = {target: len(nodes.log(target)) for target, *_ in step}
            for _ in range(settings.fault_repeats):
                for target, _, factory, offset in step:
                    topic, type_name = FAULT_TARGETS[target]
                    qos = RELIABLE if type_name == CLOUD else qos_profile_sensor_data
                    probe.publish(topic, type_name, factory(), probe.now_ns() + offset, qos)
                time.sleep(0.2)  # keep-newest: one at a time, none skipped
            time.sleep(max(0.3, 2.1 - 0.2 * settings.fault_repeats))  # rejection warnings are throttled to 2 s
            fresh = probe.fresh_diag(*(nodes.fqn(target) for target, *_ in step))
            for target, fault, _, _ in step:
                now = fresh[nodes.fqn(target)]
                reasons = [k[len("rejected: "):] for k in now if k.startswith("rejected: ")
                           and as_int(now[k]) > as_int(last[target].get(k))]
                reasons = reasons or new_log_reasons(nodes.log(target)[log_before[target]:])
                delta = counter_delta(last[target], now, COUNTERS + EXTRA_COUNTERS.get(target, ()))
                rows.append({"node": target, "fault": fault, "sent": settings.fault_repeats, **delta,
                             "reasons": reasons, "alive": nodes.running(target)})
                last[target] = now
                print(f"fault {target}: {fault}: {delta} {reasons[:1]} alive={rows[-1]['alive']}", flush=True)
        for name in specs:
            code = nodes.procs[name].process.poll()
            if code is not None:
                rows.append({"node": name, "fault": "(process exited)", "exit_code": code, "alive": False,
                             "log_tail": nodes.log(name)[-1500:]})
    order = list(specs)
    return sorted(rows, key=lambda r: order.index(r["node"]))  # stable: each node's faults in sending order


# ---------------------------------------------------------------------------------- report
def md_table(header: list[str], rows: list[list]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join("" if v is None else str(v) for v in row) + " |" for row in rows]
    return lines


def latency_rows(results: dict) -> list[dict]:
    return results.get("latency", []) + results.get("latency_builtin", [])


def markdown(results: dict) -> str:
    s = results["settings"]
    model = results["detector_model"]
    out = ["## Pipeline: load and faults (`bench/pipeline.py`)", "",
           f"Nodes as separate processes (`NodeProcess`, like `ros2 run`), DDS domain {results['domain_id']}, "
           f"{'quick' if s['quick'] else 'full'} run on {results['machine']} (2 shared cores: noisy). "
           f"Detector model: {model}.", *results.get("notes", []), "",
           "### End-to-end latency (image stamp at publish → output received)", "",
           f"Images published from the bench process for {s['stream_s']} s per row (rendered scenario frames), "
           "stamped with the wall clock; `in node` = handled + skipped (keep-newest slot), `lost` = published "
           "but never reached the node (best-effort transport). Transport `profile`: the shipped "
           "`config/fastdds_large_images.xml` (32 MB shared-memory segments), as every make command sets it; "
           "`builtin`: Fast DDS without a profile (512 KB segments: larger images go over UDP in fragments).", ""]
    out += md_table(["transport", "pipeline", "size", "Hz in", "published", "in node", "handled", "skipped", "lost",
                     "outputs", "p50 ms", "p95 ms", "p99 ms", "processing p50 ms", "state at end"],
                    [[r.get("transport", "profile"), r["pipeline"], r["size"], r["rate_hz"], r["published"],
                      r["in_node"], r["handled"], r["skipped"], r["lost_in_transport"], r["outputs"],
                      r["latency_ms"]["p50"], r["latency_ms"]["p95"], r["latency_ms"]["p99"],
                      ", ".join(f"{k} {v}" for k, v in r["processing_ms_p50"].items()),
                      ", ".join(f"{k}: {v}" for k, v in r.get("state", {}).items())]
                     for r in latency_rows(results)])
    m = results["memory"]
    out += ["", f"### Memory over a {m['duration_s']:.0f} s replay loop (`mcap_play --loop`, {m['bag_frames']} frames "
            f"at 25 Hz, ~{m['passes']} passes)", ""]
    out += md_table(["node", "RSS start MB", "RSS end MB", "RSS max MB", "floor first / last tenth MB",
                     "slope MB/min", "after warm-up", "floor after warm-up", "time jumps", "processed", "skipped",
                     "rejected", "alive"],
                    [[n, v["rss_start_mb"], v["rss_end_mb"], v["rss_max_mb"],
                      f"{v.get('rss_floor_first_mb')} / {v.get('rss_floor_last_mb')}", v["slope_mb_per_min"],
                      v["slope_after_warmup_mb_per_min"], v.get("floor_slope_after_warmup_mb_per_min"), v["time_jumps"],
                      v["processed"], v["skipped"], v["rejected"], m["alive"][n]] for n, v in m["nodes"].items()])
    out += ["", "Floor: the smallest RSS sample of each tenth of the run (a frame's working memory comes and goes; "
            "a leak raises the floor). Slopes are least-squares fits over the samples (warm-up: first 20 %)."]
    r = results["restart"]
    out += ["", "### association_node restarted mid-stream (player and `mcap_record` running)", ""]
    out += md_table(["measure", "value"], [[k, v] for k, v in r.items()])
    out += ["", "### Faults: each sent to a running node; counters are the /diagnostics deltas", ""]
    out += md_table(["node", "fault", "sent", "received", "processed", "rejected", "time jumps", "skipped", "reason",
                     "alive"],
                    [[f["node"], f["fault"], f.get("sent"), f.get("received"), f.get("processed"), f.get("rejected"),
                      f.get("time_jumps"), f.get("skipped"), (f.get("reasons") or [""])[0][:90].replace("|", "/"),
                      f["alive"]] for f in results["faults"]])
    return "\n".join(out) + "\n"


def plot(results: dict) -> None:
    import matplotlib.pyplot as plt  # noqa: PLC0415

    PLOTS.mkdir(parents=True, exist_ok=True)
    rows = latency_rows(results)
    transports = sorted({r.get("transport", "profile") for r in rows})
    fig, axes = plt.subplots(len(transports), len(PIPELINES), figsize=(12, 3.6 * len(transports)), sharey=True,
                             squeeze=False)
    for row_axes, transport in zip(axes, transports):
        for ax, pipeline in zip(row_axes, PIPELINES):
            mine = [r for r in rows if r["pipeline"] == pipeline and r.get("transport", "profile") == transport]
            x = np.arange(len(mine))
            for i, q in enumerate(("p50", "p95", "p99")):
                ax.bar(x + (i - 1) * 0.27, [r["latency_ms"][q] or 0 for r in mine], 0.27, label=q)
            ax.set_xticks(x, [f"{r['size']}\n{r['rate_hz']} Hz\n{r['handled']}/{r['published']}" for r in mine],
                          fontsize=7)
            ax.set_title(f"{pipeline}, transport {transport}", fontsize=9)
            ax.set_yscale("log")
        row_axes[0].set_ylabel("stamp → output [ms]")
    axes[0][0].legend(fontsize=8)
    fig.text(0.5, 0.005, "x: size, input rate, frames handled / published", ha="center", fontsize=8)
    fig.tight_layout()
    fig.savefig(PLOTS / "pipeline_latency.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, v in results["memory"]["nodes"].items():
        t, mb = np.array(v["samples"]).T
        ax.plot(t / 60.0, mb, label=f"{name} (floor {v.get('floor_slope_after_warmup_mb_per_min')} MB/min after warm-up)")
    ax.set_xlabel("minutes of replay loop")
    ax.set_ylabel("RSS [MB]")
    ax.set_title(f"RSS under mcap_play --loop ({results['memory']['passes']} passes)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(PLOTS / "pipeline_rss.png", dpi=110)
    plt.close(fig)


def measure(args, settings: Settings, log_dir: Path) -> dict:
    """The wanted measurements in this process (one transport); returns them by name."""
    wanted = args.only or ["latency", "memory", "restart", "faults"]
    out = {}
    probe = Probe()
    try:
        bag = uav_bag(log_dir / "loop.mcap", settings.loop_bag_frames) if {"memory", "restart"} & set(wanted) else None
        if "latency" in wanted:
            rows = measure_latency(probe, settings, log_dir)
            out["latency" if args.transport == "profile" else "latency_builtin"] = [
                {"transport": args.transport, "detector_model": detector_parameters()["model"], **r} for r in rows]
        if "memory" in wanted:
            out["memory"] = measure_memory(probe, settings, log_dir, bag)
        if "restart" in wanted:
            out["restart"] = measure_restart(probe, settings, log_dir, bag)
        if "faults" in wanted:
            out["faults"] = measure_faults(probe, settings, log_dir)
    finally:
        probe.close()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs (a few minutes)")
    parser.add_argument("--only", nargs="+", choices=["latency", "memory", "restart", "faults"], default=None)
    parser.add_argument("--transport", choices=TRANSPORTS, default="profile",
                        help="profile: the shipped Fast DDS profile (as make sets it); builtin: Fast DDS defaults")
    args = parser.parse_args()
    settings = Settings.make(args.quick)
    RESULTS.mkdir(parents=True, exist_ok=True)
    log_dir = Path(tempfile.mkdtemp(prefix="bench_pipeline_"))
    transport = use_transport(args.transport)
    print(f"logs and bags in {log_dir}; ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}", flush=True)
    json_path = RESULTS / "pipeline.json"
    results = json.loads(json_path.read_text()) if args.only and json_path.exists() else {}  # keep the others
    results.update({"settings": vars(settings), "domain_id": os.environ["ROS_DOMAIN_ID"],
                    "machine": f"{platform.machine()}, {os.cpu_count()} cores", "log_dir": str(log_dir),
                    "detector_model": detector_parameters()["model"],
                    f"transport_{args.transport}": transport})
    started = time.monotonic()
    results.update(measure(args, settings, log_dir))
    results["elapsed_s"] = round(time.monotonic() - started, 1)
    json_path.write_text(json.dumps(results, indent=1, default=str))
    if args.only is None and args.transport == "profile":
        # Fast DDS reads its profile once per process: the built-in transport rows come from a child run
        subprocess.run([sys.executable, __file__, "--only", "latency", "--transport", "builtin",
                        *(["--quick"] if args.quick else [])], check=False)
        results = json.loads(json_path.read_text())
    if all(k in results for k in ("latency", "memory", "restart", "faults")):
        (RESULTS / "pipeline.md").write_text(markdown(results))
        plot(results)
    print(f"done in {time.monotonic() - started:.0f} s: {RESULTS / 'pipeline.md'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
