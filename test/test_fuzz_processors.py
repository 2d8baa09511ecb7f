"""Fuzz the processors and the parameter validation (issue 16): seeded, bounded in time.

Random and mutated ``Image`` (every encoding, wrong steps, short or long data, huge claimed sizes),
``CompressedImage`` (valid PNG / JPEG / BMP, bit flips, truncations, headers claiming huge sizes,
decompression bombs, garbage), ``PointCloud2`` detections (NaN, inf, huge values, wrong fields,
offsets, steps, lengths; thousands of rows), ``docking/init`` polygons and stamps that go backwards
are thrown at each node's processor through ``process_guarded`` (what the nodes and the offline
runner call); random parameter values at ``config.from_mapping`` and at live nodes' start-up.

Asserted: no exception escapes, no internal error (a bug) is counted, every input is either
processed or rejected with a counted reason, the peak memory stays bounded, and a node's reported
parameters are what it runs. The seed is ``ADT_FUZZ_SEED`` (default 16); each part stops after
``ADT_FUZZ_SECONDS`` (default 4 s) or its input count, whichever comes first, but not before a minimum
count (a busy machine makes a run slower, never weaker; pytest-timeout
catches a hang).
"""
from __future__ import annotations

import dataclasses
import functools
import os
import struct
import time

import cv2
import numpy as np
import pytest
from memory_helpers import peak_rss_mb, reset_peak_rss, rss_mb
from geometry_msgs.msg import Point32, PolygonStamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import CompressedImage, Image, PointCloud2, PointField
from std_msgs.msg import Header

from aircraft_docking_tracker import docking_tracker_node
from aircraft_docking_tracker.io.bag import ns_to_stamp
from aircraft_docking_tracker.scenarios import faults
from aircraft_docking_tracker.config import ConfigError, from_mapping
from aircraft_docking_tracker.images import LAYOUTS, ENCODINGS
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, table_to_cloud
from aircraft_docking_tracker.ros.processing import ProcessingStats, process_guarded
from multi_target_tracker import association_node, detector_node

from ros_helpers import ros_context

# garbage bytes make signalling NaNs and overflowing casts: numpy warns, the processors cope
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

SEED = int(os.environ.get("ADT_FUZZ_SEED", "16"))
SECONDS = float(os.environ.get("ADT_FUZZ_SECONDS", "4"))
SPECS = {"detector": detector_node.SPEC, "association": association_node.SPEC,
         "docking_tracker": docking_tracker_node.SPEC}
NODES = {"detector": detector_node.DetectorNode, "association": association_node.AssociationNode,
         "docking_tracker": docking_tracker_node.DockingTrackerNode}


# ------------------------------------------------------------------------------------- inputs
class Inputs:
    """Random and mutated messages from one seeded generator."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)
        self.k = 0

    def header(self) -> Header:
        self.k += 1
        r = self.rng.random()
        stamp = int(1e9 + self.k * 3e7) if r < 0.85 else int(self.rng.integers(0, 2**40))  # jumps both ways
        return Header(stamp=ns_to_stamp(stamp), frame_id=self.rng.choice(["cam", "", "x" * 300]))

    def pixels(self, dtype, shape):
        if np.dtype(dtype).kind == "f":
            a = self.rng.normal(0, 1e3 if self.rng.random() < 0.3 else 1, shape).astype(dtype)
            a.flat[self.rng.integers(0, a.size, 3)] = self.rng.choice([np.nan, np.inf, -np.inf])
            return a
        info = np.iinfo(dtype)
        return self.rng.integers(info.min, int(info.max) + 1, shape, dtype=dtype)

    def image(self) -> Image:
        rng = self.rng
        encoding = str(rng.choice(ENCODINGS)) if rng.random() < 0.9 else str(rng.choice(["bgr9", "", "rgb8 ", "💥"]))
        layout = LAYOUTS.get(encoding, LAYOUTS["mono8"])
        h, w = (int(v) for v in rng.integers(1, 72, 2))
        if encoding.startswith(("yuv", "uyvy")):
            w += w % 2
        item = np.dtype(layout.dtype).itemsize
        row = w * layout.channels * item
        step = row + int(rng.choice([0, 0, 0, 1, 3, 64]))
        data = np.zeros((h, step), np.uint8)
        data[:, :row] = self.pixels(layout.dtype, (h, w * layout.channels)).view(np.uint8).reshape(h, row)
        data = data.tobytes()
        msg = Image(header=self.header(), height=h, width=w, encoding=encoding, step=step,
                    is_bigendian=int(rng.random() < 0.2))
        mutation = rng.random()
        if mutation < 0.1:
            data = data[:int(rng.integers(0, len(data)))]                      # truncated
        elif mutation < 0.15:
            data += bytes(int(rng.integers(1, 500)))                           # trailing bytes
        elif mutation < 0.2:
            msg.step = int(rng.integers(0, row + 1))                           # short or zero step
        elif mutation < 0.25:
            msg.height, msg.width = int(rng.choice([0, 1, 40000, 2**31])), int(rng.choice([0, 1, 40000, 2**31]))
        elif mutation < 0.3:
            msg.step = int(rng.choice([2**31, 2**32 - 1]))
        elif mutation < 0.33:                                                  # claims 10.2 MP, carries it
            msg.height, msg.width, msg.encoding = 2000, 5100, "mono8"
            msg.step, data = 5100, bytes(2000 * 5100)
        msg.data = data
        return msg

    def encoded(self) -> bytes:
        rng = self.rng
        h, w = (int(v) for v in rng.integers(1, 64, 2))
        channels = int(rng.choice([1, 3]))
        pixels = self.pixels(np.uint8, (h, w, channels) if channels == 3 else (h, w))
        ext = str(rng.choice([".png", ".jpg", ".bmp"]))
        return cv2.imencode(ext, pixels)[1].tobytes()

    def compressed(self) -> CompressedImage:
        rng = self.rng
        data = bytearray(self.encoded())
        mutation = rng.random()
        if mutation < 0.15:
            for _ in range(int(rng.integers(1, 20))):                           # bit flips
                i = int(rng.integers(0, len(data)))
                data[i] ^= 1 << int(rng.integers(0, 8))
        elif mutation < 0.25:
            data = data[:int(rng.integers(0, len(data)))]
        elif mutation < 0.35 and data[:4] == b"\x89PNG":                         # header claims a huge image
            data[16:24] = struct.pack(">II", *(int(v) for v in rng.integers(1, 2**31 - 1, 2)))
        elif mutation < 0.4:
            data = bytearray(rng.integers(0, 256, int(rng.integers(0, 300)), dtype=np.uint8).tobytes())
        elif mutation < 0.45:
            data = bytearray(png_bomb(*BOMB_SIZES[int(rng.integers(0, len(BOMB_SIZES)))]))
        elif mutation < 0.47 and data[:4] == b"\x89PNG":                        # a chunk length lies
            data[33:37] = struct.pack(">I", int(rng.integers(2**20, 2**31)))
        elif mutation < 0.5 and data[:2] == b"\xff\xd8":
            data = data[:2] + b"\xff\xc0\x00\x11\x08" + struct.pack(">HH", 65000, 65000) + data[2:]
        return CompressedImage(header=self.header(), format=str(rng.choice(["jpeg", "png", "", "bgr8; jpeg"])),
                               data=bytes(data))

    def cloud(self) -> PointCloud2:
        rng = self.rng
        n = int(rng.choice([0, 1, 3, 10, 40, 2000]))
        table = np.zeros(n, DETECTION_DTYPE)
        for name in ("x", "y"):
            table[name] = rng.uniform(-50, 700, n)
        for name in ("w", "h"):
            table[name] = rng.uniform(-5, 200, n)
        table["score"] = rng.normal(0, 3, n)
        table["class_id"] = rng.integers(-3, 5, n)
        if n and rng.random() < 0.4:
            for _ in range(int(rng.integers(1, 5))):
                name = str(rng.choice(["x", "y", "w", "h", "score"]))
                table[name][int(rng.integers(0, n))] = rng.choice([np.nan, np.inf, -np.inf, 3e38, -3e38, 0.0])
        msg = table_to_cloud(table, self.header())
        mutation = rng.random()
        if mutation < 0.08:
            msg.data = msg.data[:int(rng.integers(0, len(msg.data) + 1))]
        elif mutation < 0.14:
            msg.fields = [PointField(name=f.name, offset=int(rng.integers(0, 40)), datatype=int(rng.integers(0, 10)),
                                     count=int(rng.integers(0, 3))) for f in msg.fields]
        elif mutation < 0.18:
            msg.fields = msg.fields[:int(rng.integers(0, len(msg.fields)))]
        elif mutation < 0.22:
            msg.point_step = int(rng.choice([0, 1, 8, 2**31]))
        elif mutation < 0.26:
            msg.width, msg.height = int(rng.choice([0, 5, 2**31])), int(rng.choice([0, 1, 7]))
        elif mutation < 0.3:
            msg.is_bigendian = True
        return msg

    def polygon(self) -> PolygonStamped:
        rng = self.rng
        n = int(rng.choice([0, 1, 2, 3, 4, 4, 4, 5, 50]))
        values = rng.uniform(-20, 80, (n, 2))
        if n and rng.random() < 0.2:
            values[int(rng.integers(0, n)), int(rng.integers(0, 2))] = rng.choice([np.nan, np.inf, 1e30])
        msg = PolygonStamped(header=self.header())
        msg.polygon.points = [Point32(x=float(x), y=float(y)) for x, y in values]
        return msg


BOMB_SIZES = [(3500, 3000), (6000, 5000)]    # 10.5 and 30 MP of zeros, some ten kB each


png_bomb = functools.lru_cache(maxsize=None)(faults.png_bomb)


def message_for(inputs: Inputs, type_name: str):
    if type_name.endswith("/Image"):
        return inputs.image()
    if type_name.endswith("/CompressedImage"):
        return inputs.compressed()
    if type_name.endswith("/PointCloud2"):
        return inputs.cloud()
    return inputs.polygon()


def build(name: str, node_values: dict | None = None):
    spec = SPECS[name]
    configs = {prefix: cls() for prefix, cls in spec.configs.items()}
    if node_values:
        configs["node."] = dataclasses.replace(configs["node."], **node_values)
    return spec.build(configs)


def throw(processor, inputs: Inputs, count: int, seconds: float, minimum: int = 200) -> tuple[ProcessingStats, int]:
    """Feed up to ``count`` random messages on the processor's input topics, at least ``minimum`` of them
    however long they take (``seconds`` bounds only the rest: a busy machine makes a run slower, never
    weaker); check each is accounted for."""
    stats = ProcessingStats()
    processor.on_rejected = stats.reject
    topics = sorted(processor.inputs.items())
    deadline = time.monotonic() + seconds
    sent = 0
    while sent < count and (sent < minimum or time.monotonic() < deadline):
        topic, type_name = topics[int(inputs.rng.integers(0, len(topics)))]
        msg = message_for(inputs, type_name)
        before = (stats.processed, stats.rejected_total)
        outputs = process_guarded(processor, topic, msg, stats)      # must never raise
        sent += 1
        assert stats.processed == before[0] + 1 or stats.rejected_total > before[1], (topic, msg)
        for out_topic, _ in outputs:
            assert out_topic in processor.outputs
    return stats, sent


# ------------------------------------------------------------------------------------- tests
@pytest.mark.parametrize("name, node_values", [
    ("detector", {}), ("detector", {"compressed": True, "annotate_image": True}),
    ("association", {}), ("docking_tracker", {}),
    ("docking_tracker", {"compressed": True, "annotate_image": True})])
def test_processors_survive_random_and_mutated_messages(name, node_values):
    if name == "association":
        processor = association_node.AssociationProcessor(
            output=association_node.AssociationOutputConfig(annotate_image=True))
    else:
        processor = build(name, node_values)
    reset_peak_rss()
    rss0 = rss_mb()
    stats, sent = throw(processor, Inputs(SEED + len(name) + len(node_values)), 3000, SECONDS)
    print(f"{name} {node_values}: {sent} messages, {stats.processed} processed, {stats.rejected_total} rejected, "
          f"{len(stats.rejected)} kinds")
    internal = {r: c for r, c in stats.rejected.items() if "internal error" in r}
    assert not internal, internal
    assert sent >= 200, sent                     # thousands in all over the five runs (bounded by SECONDS)
    assert stats.rejected_total > 0 and stats.processed > 0, stats.rejected
    assert len(stats.rejected) <= 64             # reasons are counted by kind, memory bounded
    # peak memory: a decoded bomb alone would be >= 12 GB, one lying PNG chunk length 512 MB
    assert peak_rss_mb() - rss0 < 400, (rss0, peak_rss_mb())


def random_value(rng, default, spec):
    """A random value for one parameter: in range, beyond it, NaN/inf, wrong types, odd strings."""
    choice = rng.random()
    if choice < 0.15:
        return rng.choice([float("nan"), float("inf"), -float("inf"), 1e30, -1e30])
    if choice < 0.25:
        return [None, "", " ", "upright ", "opencv", "both", [1, 2, 3], [float("nan")] * 4, True, -1, 2**40][
            int(rng.integers(0, 11))]
    if spec.choices and choice < 0.6:
        return spec.choices[int(rng.integers(0, len(spec.choices)))]
    if isinstance(default, bool):
        return bool(rng.random() < 0.5)
    if isinstance(default, (int, float)):
        low = spec.low if spec.low is not None else -1e6
        high = spec.high if spec.high is not None else 1e6
        span = high - low
        value = rng.uniform(low - 0.1 * span, high + 0.1 * span) if choice < 0.8 else rng.uniform(low, low + 0.05 * span)
        return int(round(value)) if isinstance(default, int) else float(value)
    if isinstance(default, (list, tuple)):
        n = int(rng.choice([0, 2, 4, 4, 4, 5]))
        return [float(v) for v in rng.uniform(-20, 60, n)]
    if isinstance(default, str):
        return default + rng.choice(["", " ", "x", ".json"])
    return default


def small_frames(rng, n=3):
    frames = []
    for k in range(n):
        grey = rng.integers(0, 256, (48, 64), dtype=np.uint8)
        msg = Image(header=Header(stamp=ns_to_stamp(int(1e9 + k * 1e8))), height=48, width=64, encoding="mono8",
                    step=64, data=grey.tobytes())
        frames.append(msg)
    return frames


def test_configuration_validation_refuses_or_builds_a_working_processor():
    """Random values for random fields of every node's configs: ``from_mapping`` either refuses with
    ConfigError or the processor builds and handles frames without an internal error."""
    from aircraft_docking_tracker.config import spec_of  # noqa: PLC0415

    rng = np.random.default_rng(SEED)
    deadline = time.monotonic() + SECONDS
    tried = refused = 0
    while tried < 3000 and (tried < 100 or time.monotonic() < deadline):    # >= 100 however slow
        name = str(rng.choice(sorted(SPECS)))
        spec = SPECS[name]
        configs, ok = {}, True
        for prefix, cls in spec.configs.items():
            fields = dataclasses.fields(cls)
            values = {}
            for f in (fields[int(i)] for i in rng.integers(0, len(fields), int(rng.integers(0, 3)))):
                if f.name in ("threads",):   # a thread pool per trial is pointless work
                    continue
                values[f.name] = random_value(rng, getattr(cls(), f.name), spec_of(f))
            try:
                configs[prefix] = from_mapping(cls, values)
            except ConfigError as exc:
                assert str(exc) and all(isinstance(n, str) for n in exc.fields)
                ok = False
                break
        tried += 1
        if not ok:
            refused += 1
            continue
        processor = spec.build(configs)
        stats = ProcessingStats()
        processor.on_rejected = stats.reject
        for msg in small_frames(rng, 2):
            topic = next(iter(processor.latest_only), None)
            if topic is None or processor.inputs.get(topic) != "sensor_msgs/msg/Image":
                break
            process_guarded(processor, topic, msg, stats)
        internal = {r: c for r, c in stats.rejected.items() if "internal error" in r}
        assert not internal, (name, configs, internal)
    print(f"configs: {tried} tried, {refused} refused")
    assert tried >= 100 and 0 < refused < tried, (tried, refused)


def assert_reports_what_runs(node, name, from_ros, context) -> None:
    for prefix, cls in SPECS[name].configs.items():
        cfg = node.config(prefix)
        for f in dataclasses.fields(cls):
            param = node._parameters[prefix + f.name]
            running = getattr(cfg, f.name)
            if param.type_ == Parameter.Type.NOT_SET:
                assert running in ([], ()), (prefix + f.name, running)
                continue
            reported = from_ros(param.value, getattr(cls(), f.name))
            assert reported == running or (isinstance(running, (list, tuple)) and list(reported) == list(running)), \
                (prefix + f.name, reported, running, context)


@pytest.mark.ros
def test_nodes_report_the_parameters_they_run_under_random_overrides():
    """Start each node with random overrides (bad ones among them), then set them again at runtime:
    it starts and keeps running, and for every field the parameter reports the value its config holds."""
    from aircraft_docking_tracker.config import spec_of  # noqa: PLC0415
    from aircraft_docking_tracker.ros.node_base import _from_ros  # noqa: PLC0415

    rng = np.random.default_rng(SEED + 1)
    deadline = time.monotonic() + SECONDS
    started = 0
    with ros_context() as (ctx, _):
        while started < 30 and (started < 3 or time.monotonic() < deadline):  # >= 3 however slow
            name = str(rng.choice(sorted(NODES)))
            overrides = []
            for prefix, cls in SPECS[name].configs.items():
                fields = dataclasses.fields(cls)
                for f in (fields[int(i)] for i in rng.integers(0, len(fields), 2)):
                    value = random_value(rng, getattr(cls(), f.name), spec_of(f))
                    if value is None or (isinstance(value, list) and not value) or f.name == "threads":
                        continue
                    if isinstance(value, list) and len({type(v) for v in value}) > 1:
                        continue
                    overrides.append(Parameter(prefix + f.name, value=value))
            node = NODES[name](context=ctx, parameter_overrides=overrides)
            started += 1
            try:
                assert_reports_what_runs(node, name, _from_ros, overrides)
                for p in overrides[:6]:       # the same random values again, now at runtime, one by one
                    try:
                        node.set_parameters([p])
                    except Exception as exc:  # noqa: BLE001 - rclpy raises on a type change or a read-only
                        # (start-up only) parameter; either is a refusal
                        assert "type" in str(exc).lower() or "read-only" in str(exc).lower(), exc
                    assert_reports_what_runs(node, name, _from_ros, [p])
                node.diagnostic_status()
            finally:
                node.destroy_node()
    assert started >= 3
