"""Scenario bags and a live in-process pipeline for the integration tests (no launch)."""
from __future__ import annotations

import threading
import time
from pathlib import Path

from aircraft_docking_tracker.io.bag import BagReader, BagWriter
from aircraft_docking_tracker.io.mcap_play import Player, PlayOptions
from aircraft_docking_tracker.io.mcap_record import Recorder
from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
from aircraft_docking_tracker.scenarios.make_scenario import write_docking_bag, write_uav_bag
from aircraft_docking_tracker.scenarios.uav import UavScene, UavSceneConfig

from ros_helpers import ros_context, spin_until


def docking_bag(path: Path, seed: int = 4, frames: int = 90, **overrides) -> Path:
    scene = DockingScene(DockingSceneConfig(frames=frames, **overrides), seed=seed)
    write_docking_bag(scene, path, progress=False)
    return path


def uav_bag(path: Path, seed: int = 3, frames: int = 120, **overrides) -> Path:
    scene = UavScene(UavSceneConfig(frames=frames, **overrides), seed=seed)
    write_uav_bag(scene, path, detections=True, progress=False)
    return path


def first_polygon_box(bag: Path) -> list[float]:
    """The axis-aligned box [x, y, w, h] of the first ground-truth polygon: the initial box."""
    for _, msg, _ in BagReader(bag).ros_messages(["ground_truth/polygon"]):
        xs = [p.x for p in msg.polygon.points]
        ys = [p.y for p in msg.polygon.points]
        return [min(xs), min(ys), max(xs) - min(xs), max(ys) - min(ys)]
    raise AssertionError("no ground_truth/polygon in the bag")


def run_live(node_factories, bag: Path, out: Path, namespace: str, record_topics: list[str],
             play_topics: list[str], rate: float = 1.0, expect: dict[str, int] | None = None,
             timeout_s: float = 120.0):
    """Start nodes (factories taking a context) in ``namespace``, play ``bag`` into it, record.

    After playing, waits until every ``expect`` topic has its count of messages, then until the
    recording has been quiet for a second. Returns the nodes (destroyed) for their statistics
    and the player's report. Every node, the player and the recorder
    share one isolated context; the executor spins in a background thread.
    """
    prefix = f"/{namespace}/"
    with ros_context() as (ctx, executor):
        import rclpy

        nodes = [factory(ctx) for factory in node_factories]
        rec_node = rclpy.create_node("test_recorder", context=ctx)
        play_node = rclpy.create_node("test_player", context=ctx)
        for node in (*nodes, rec_node):
            executor.add_node(node)
        writer = BagWriter(out)
        recorder = Recorder(rec_node, writer, topics=[prefix + t for t in record_topics])
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            reader = BagReader(bag)
            player = Player(play_node, reader, PlayOptions(rate=rate, topics=play_topics,
                                                           remap={t: prefix + t for t in play_topics},
                                                           wait_for_subscribers_s=20.0))
            # every recorded topic has a publisher now (nodes, player): subscribe before playing
            assert spin_until(_Noop(), lambda: (recorder.discover(), len(recorder.subscriptions) == len(record_topics))[1],
                              timeout_s=20), f"recorder found only {sorted(recorder.subscriptions)}"
            report = player.run()
            expected = {prefix + t: n for t, n in (expect or {}).items()}
            spin_until(_Noop(), lambda: all(writer.topic_counts.get(t, 0) >= n for t, n in expected.items()),
                       timeout_s=timeout_s)
            quiet = {"count": -1, "since": time.monotonic()}

            def settled() -> bool:
                if writer.message_count != quiet["count"]:
                    quiet["count"], quiet["since"] = writer.message_count, time.monotonic()
                return time.monotonic() - quiet["since"] > 1.0

            spin_until(_Noop(), settled, timeout_s=timeout_s)
        finally:
            writer.close()
            executor.shutdown(timeout_sec=2.0)
            for node in (*nodes, rec_node, play_node):
                node.destroy_node()
    return nodes, report


class _Noop:
    """An 'executor' for spin_until when a background thread already spins."""

    @staticmethod
    def spin_once(timeout_sec: float = 0.0) -> None:
        import time

        time.sleep(timeout_sec)
