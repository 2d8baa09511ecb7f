"""``run_offline``: the nodes' processors over a bag, without DDS, into an output bag.

    run_offline scene.mcap out.mcap --nodes detector association
    run_offline docking.mcap out.mcap --nodes detector docking_tracker --params-file config/docking.yaml

Input messages are taken in log-time order and handed to every processor that subscribes to their
topic, through the same ``processing.process_guarded`` the live nodes use; each output is written
with its input's log time and handed on at once to the processors that consume it (detector ->
association, detector -> docking tracker), so the run is deterministic and equals a live run in
which no frame was skipped. The output bag holds every input and every output topic; where the
input bag already has a topic that a processor of the run publishes (say ``detections`` made from
ground truth, and the detector runs too), the run's own output replaces it.

The output may not be the input (same path, a symbolic or hard link, or a directory holding it:
refused) and appears only when the run completes. Split bags (a rosbag2 directory of several
``.mcap`` files) are read as one; a truncated or damaged input is read as far as it goes, with a
warning; topics of types not installed here are copied with their recorded schema.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

from .io.bag import BagError, BagReader, BagWriter, check_outputs, get_message_class
from .config import ConfigError, tool_parameters
from .ros.processing import MessageProcessor, ProcessingStats, ProcessorSpec, process_guarded

LOG = logging.getLogger(__name__)

# node name -> module with a SPEC (ProcessorSpec); the YAML file of each is config/<name>.yaml
NODE_MODULES = {
    "detector": "multi_target_tracker.detector_node",
    "association": "multi_target_tracker.association_node",
    "docking_tracker": "aircraft_docking_tracker.docking_tracker_node",
}


def processor_spec(node: str) -> ProcessorSpec:
    if node not in NODE_MODULES:
        raise ValueError(f"unknown node {node!r}; choose from {', '.join(NODE_MODULES)}")
    return importlib.import_module(NODE_MODULES[node]).SPEC


def build_processor(node: str, params_file: str | Path | None = None,
                    overrides: dict[str, Any] | None = None) -> MessageProcessor:
    """The processor of ``node`` configured from a ROS 2 parameter file (default: the package's)."""
    spec = processor_spec(node)
    parameters = tool_parameters(params_file, f"{node}.yaml", spec.node_name)
    parameters.update(overrides or {})
    processor = spec.build(spec.configs_from_parameters(parameters))
    for level, note in processor.start_up_notes:
        LOG.log(level, note)
    return processor


@dataclass
class OfflineRun:
    """Feeds messages through a set of processors; collects outputs and statistics."""

    processors: dict[str, MessageProcessor]
    stats: dict[str, ProcessingStats] = field(default_factory=dict)

    def __post_init__(self):
        self.stats = {name: ProcessingStats() for name in self.processors}
        for name, processor in self.processors.items():
            processor.on_rejected = self.stats[name].reject

    def feed(self, topic: str, msg: Any) -> list[tuple[str, Any]]:
        """Deliver one message; return every (topic, message) it caused, depth first."""
        produced: list[tuple[str, Any]] = []
        for name, processor in self.processors.items():
            if topic not in processor.inputs:
                continue
            for out_topic, out_msg in process_guarded(processor, topic, msg, self.stats[name]):
                produced.append((out_topic, out_msg))
                produced.extend(self.feed(out_topic, out_msg))
        return produced


def _relative(topic: str, namespace: str) -> str:
    ns = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    return topic[len(ns):] if topic.startswith(ns) else topic.lstrip("/")


def _same_type(a: str, b: str) -> bool:
    return a.replace("/msg/", "/") == b.replace("/msg/", "/")


def check_input_types(reader: BagReader, processors: dict[str, MessageProcessor], namespace: str = "") -> None:
    """Refuse, before anything is written, a bag whose topic a processor reads carries another
    type, or a type not installed here (the run would stop at its first message)."""
    for name, info in reader.topics.items():
        topic = _relative(name, namespace)
        for node, processor in processors.items():
            expected = processor.inputs.get(topic)
            if expected is None:
                continue
            if not _same_type(info.type_name, expected):
                raise BagError(f"{reader.bag_path}: topic {name} is {info.type_name or 'of no type'}, "
                               f"but {node} reads {topic} as {expected}")
            get_message_class(info.type_name)  # BagError: not installed


def _warn(text: str) -> None:
    print(f"run_offline: warning: {text}", file=sys.stderr)


def run(input_bag: str | Path, output_bag: str | Path, nodes: Iterable[str],
        params_file: str | Path | None = None, namespace: str = "", progress: bool = True,
        processors: dict[str, MessageProcessor] | None = None, warn: Callable[[str], None] = _warn) -> OfflineRun:
    """Run ``nodes`` over ``input_bag`` and write ``output_bag`` (inputs and outputs).

    The output is never one of the input's files (refused), and appears only when the run
    completes (written under a temporary name, then moved into place): a run stopped by an error
    leaves no partial bag. Topics of types not installed here are copied with their recorded
    schema. A truncated or damaged input is read as far as it goes, with a ``warn``-ing; a message
    that does not deserialise is counted as a rejection of every processor that reads its topic.
    """
    reader = BagReader(input_bag)
    check_outputs([output_bag], [*reader.files, reader.bag_path], "run_offline")
    runner = OfflineRun(processors or {n: build_processor(n, params_file) for n in nodes})
    check_input_types(reader, runner.processors, namespace)
    if reader.problem:
        warn(reader.problem)
    prefix = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    try:
        from tqdm import tqdm  # noqa: PLC0415
        bar = tqdm(total=reader.message_count, unit="msg", desc="run_offline", disable=not progress)
    except ImportError:  # pragma: no cover
        bar = None
    produced = {t for p in runner.processors.values() for t in p.outputs}
    replaced = sorted(t for t in reader.topics if _relative(t, namespace) in produced)
    if replaced and progress:
        print(f"run_offline: the run's own outputs replace the bag's {', '.join(replaced)}", file=sys.stderr)
    damaged_before = reader.error
    undecodable = 0
    with BagWriter(output_bag, overwrite=True, atomic=True) as writer:
        for info in reader.topics.values():
            if info.name not in replaced:
                writer.add_topic_like(info)
        for item in reader.messages():
            if bar is not None:
                bar.update(1)
            if item.topic in replaced:
                continue
            writer.write_serialized(item.topic, item.type_name, item.data, item.log_time_ns, item.publish_time_ns)
            topic = _relative(item.topic, namespace)
            readers = [n for n, p in runner.processors.items() if topic in p.inputs]
            if not readers:
                continue
            try:
                msg = item.deserialize()
            except BagError as exc:
                for name in readers:
                    runner.stats[name].reject(f"undecodable {topic} message")
                undecodable += 1
                if undecodable <= 3:
                    warn(f"{exc}; skipped" + (" (further ones are counted, not shown)" if undecodable == 3 else ""))
                continue
            for out_topic, out_msg in runner.feed(topic, msg):
                writer.write(prefix + out_topic, out_msg, item.log_time_ns)
    if bar is not None:
        bar.close()
    if reader.error and reader.error != damaged_before:
        warn(reader.problem)
    return runner


def main(args: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="run_offline", description=__doc__.split("\n\n")[0])
    parser.add_argument("input", help="input bag (.mcap file or rosbag2 directory)")
    parser.add_argument("output", help="output bag: .mcap file or directory (replaced when the run completes; "
                                          "never one of the input's files)")
    parser.add_argument("--nodes", nargs="+", default=["detector", "association"], choices=sorted(NODE_MODULES),
                        help="processors to run (default: detector association)")
    parser.add_argument("--params-file", default=None,
                        help="ROS 2 parameter file with a section per node (default: the package's config/<node>.yaml)")
    parser.add_argument("--namespace", default="", help="camera namespace of the bag's topics (e.g. cam0)")
    parser.add_argument("--no-progress", action="store_true")
    ns = parser.parse_args(args)
    try:
        runner = run(ns.input, ns.output, ns.nodes, ns.params_file, ns.namespace, progress=not ns.no_progress)
    except (BagError, ConfigError, ValueError) as exc:
        print(f"run_offline: {exc}", file=sys.stderr)
        return 2
    for name, stats in runner.stats.items():
        print(f"{name}: {stats.processed} processed, {stats.rejected_total} rejected, "
              f"{stats.time_jumps} time jumps" + "".join(f"\n  rejected: {r} x{c}" for r, c in stats.rejected.items()))
    print(f"run_offline: wrote {ns.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
