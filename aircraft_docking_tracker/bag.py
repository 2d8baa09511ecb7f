"""rosbag2-compatible MCAP files: a small typed API over the ``mcap`` library.

What makes a file open in ``ros2 bag info`` / ``ros2 bag play`` (Jazzy), Foxglove and ``rosbags``:

* header profile ``ros2``; one ``ros2msg`` schema per type whose text is the type's ``.msg`` file
  followed by every dependency's, each after a line of 80 ``=`` and ``MSG: pkg/Name``
  (the format rosbag2's ``LocalMessageDefinitionSource`` writes);
* ``cdr`` message encoding (``rclpy.serialization``);
* channel metadata ``offered_qos_profiles`` (rosbag2 metadata version 9 YAML) and
  ``topic_type_hash`` (the RIHS01 hash from the type's installed ``.json`` description);
* zstd-compressed chunks with message indexes, statistics and summary offsets, and a ``rosbag2``
  metadata record; a bag *directory* (``metadata.yaml`` + ``<name>_0.mcap``) when the output path
  has no ``.mcap`` suffix, as ``ros2 bag record`` makes.

Reading accepts a file or a bag directory; a file whose summary is missing (a recorder killed
hard) is read sequentially up to its last complete record, and :func:`recover` rewrites it whole.
"""
from __future__ import annotations

import importlib
import json
import os
import re
import struct
import sys
import threading
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterable, Iterator

import yaml
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.writer import CompressionType, IndexType, Writer

ROS_DISTRO = "jazzy"
LIBRARY = "aircraft_docking_tracker"
SEPARATOR = "=" * 80
PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string", "wstring",
}
ROSBAG2_METADATA_VERSION = 9


class BagError(ValueError):
    """A file that is missing, not MCAP, not a ROS 2 bag, or unreadable; the message says which."""


# ----------------------------------------------------------------------------------------------
# time stamps
def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (or anything with sec, nanosec) to integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int):
    """Integer nanoseconds to ``builtin_interfaces/Time``."""
    from builtin_interfaces.msg import Time  # noqa: PLC0415

    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


# ----------------------------------------------------------------------------------------------
# message types
def type_name_of(msg_or_class: Any) -> str:
    """``sensor_msgs/msg/Image`` for an Image message or class."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    package = cls.__module__.split(".")[0]
    return f"{package}/msg/{cls.__name__}"


@lru_cache(maxsize=None)
def get_message_class(type_name: str):
    """The Python class of ``pkg/msg/Name`` (also accepts ``pkg/Name``)."""
    package, name = _split_type(type_name)
    try:
        module = importlib.import_module(f"{package}.msg")
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise BagError(f"message type {type_name} is not installed ({exc})") from None


def _split_type(type_name: str) -> tuple[str, str]:
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise BagError(f"not a message type name: {type_name!r}")


def _share_dirs() -> list[Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in dict.fromkeys(prefixes)]


def _interface_file(package: str, name: str, suffix: str) -> Path:
    for share in _share_dirs():
        candidate = share / package / "msg" / f"{name}{suffix}"
        if candidate.is_file():
            return candidate
    raise BagError(f"no {name}{suffix} for package {package} in AMENT_PREFIX_PATH or {sys.prefix}")


_TYPE_SUFFIX = re.compile(r"(\[[^\]]*\])?$")
_BOUND_SUFFIX = re.compile(r"<=\d+$")


def _dependencies(package: str, text: str) -> list[str]:
    """Non-primitive field types of a .msg text, as ``pkg/Name``, in order of appearance."""
    deps: list[str] = []
    for raw in text.splitlines():
        parts = raw.split("#", 1)[0].split(None, 1)
        if len(parts) < 2 or "=" in parts[1]:
            continue  # blank, comment, or a constant such as ``uint8 FOO=1``
        base = _BOUND_SUFFIX.sub("", _TYPE_SUFFIX.sub("", parts[0]))
        if base in PRIMITIVES:
            continue
        if base == "Header":
            base = "std_msgs/Header"
        elif "/" not in base:
            base = f"{package}/{base}"
        deps.append(base.replace("/msg/", "/"))
    return deps


@lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text: the type's .msg and all its dependencies, depth first."""
    package, name = _split_type(type_name)
    root = _interface_file(package, name, ".msg").read_text()
    parts = [root.rstrip("\n")]
    seen: set[str] = set()
    stack = list(reversed(_dependencies(package, root)))
    while stack:
        dep = stack.pop()
        if dep in seen:
            continue
        seen.add(dep)
        dep_package, dep_name = dep.split("/")
        text = _interface_file(dep_package, dep_name, ".msg").read_text()
        parts.append(f"{SEPARATOR}\nMSG: {dep}\n{text.rstrip(chr(10))}")
        stack.extend(reversed(_dependencies(dep_package, text)))
    return "\n".join(parts) + "\n"


@lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """The RIHS01 type hash that Jazzy advertises for ``type_name`` ('' where unknown)."""
    package, name = _split_type(type_name)
    try:
        data = json.loads(_interface_file(package, name, ".json").read_text())
    except (BagError, ValueError):
        return ""
    full = f"{package}/msg/{name}"
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return entry.get("hash_string", "")
    return ""


# ----------------------------------------------------------------------------------------------
# QoS in rosbag2's metadata format (version 9: names, not numbers)
_INFINITE = {"sec": 2147483647, "nsec": 4294967295}
_UNSET = {"sec": 0, "nsec": 0}


def qos_to_dict(qos: Any) -> dict:
    """An ``rclpy.qos.QoSProfile`` as rosbag2 writes it in ``offered_qos_profiles``."""
    def duration(d) -> dict:
        ns = d.nanoseconds if hasattr(d, "nanoseconds") else int(d)
        if ns <= 0 or ns >= 2**63 - 1:
            return dict(_INFINITE) if ns else dict(_UNSET)
        return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}

    return {
        "history": qos.history.name.lower(),
        "depth": int(qos.depth),
        "reliability": qos.reliability.name.lower(),
        "durability": qos.durability.name.lower(),
        "deadline": duration(qos.deadline),
        "lifespan": duration(qos.lifespan),
        "liveliness": qos.liveliness.name.lower(),
        "liveliness_lease_duration": duration(qos.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


def default_qos_dict(reliable: bool = True, transient_local: bool = False, depth: int = 10) -> dict:
    """The dict of a plain keep-last profile (what a file written offline claims was offered)."""
    return {
        "history": "keep_last", "depth": depth,
        "reliability": "reliable" if reliable else "best_effort",
        "durability": "transient_local" if transient_local else "volatile",
        "deadline": dict(_UNSET), "lifespan": dict(_UNSET), "liveliness": "automatic",
        "liveliness_lease_duration": dict(_UNSET), "avoid_ros_namespace_conventions": False,
    }


def qos_from_metadata(text: str | None):
    """The ``rclpy.qos.QoSProfile`` to replay a topic with, from ``offered_qos_profiles`` text.

    Follows ``ros2 bag play``: reliable only if every recorded publisher was reliable, transient
    local only if every one was; keep-last with the largest depth. None when nothing is known.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: PLC0415

    if not text:
        return None
    try:
        items = yaml.safe_load(text) or []
    except yaml.YAMLError:
        return None
    if not isinstance(items, list) or not items:
        return None

    def is_(item, key, name, number):
        value = item.get(key)
        return value == number if isinstance(value, int) else str(value).lower() == name

    reliable = all(is_(i, "reliability", "reliable", 1) for i in items)
    transient = all(is_(i, "durability", "transient_local", 1) for i in items)
    depth = max(int(i.get("depth", 0) or 0) for i in items) or 10
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


# ----------------------------------------------------------------------------------------------
# writing
@dataclass
class _TopicState:
    channel_id: int
    type_name: str
    qos: list[dict]
    count: int = 0


class BagWriter:
    """Write a rosbag2-compatible MCAP file (``x.mcap``) or bag directory (any other path).

    Thread-safe: several subscription callbacks may write at once. :meth:`flush` closes the open
    chunk and pushes it to disk: a recorder calls it periodically, so a hard kill loses little.
    """

    def __init__(self, path: str | Path, *, compression: str = "zstd", chunk_size: int = 1 << 20,
                 overwrite: bool = False):
        path = Path(path)
        if path.suffix == ".mcap":
            self.directory = None
            self.file_path = path
        else:
            self.directory = path
            self.file_path = path / f"{path.name}_0.mcap"
        if (self.directory or self.file_path).exists() and not overwrite:
            raise BagError(f"{self.directory or self.file_path} exists already")
        self.file_path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.file_path, "wb")  # noqa: SIM115 (closed in close())
        kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in kind:
            raise BagError(f"compression must be one of {sorted(kind)}, not {compression!r}")
        self.compression = compression
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=kind[compression],
                              index_types=IndexType.ALL)
        self._writer.start(profile="ros2", library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, _TopicState] = {}
        self._lock = threading.Lock()
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.bytes_written = 0
        self.closed = False

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    @property
    def topic_counts(self) -> dict[str, int]:
        return {name: t.count for name, t in self._topics.items()}

    def add_topic(self, topic: str, type_name: str, qos: Iterable[dict] | None = None) -> None:
        """Declare a topic (done implicitly by the first write); ``qos``: dicts as qos_to_dict."""
        with self._lock:
            self._add_topic_locked(topic, type_name, qos)

    def _add_topic_locked(self, topic: str, type_name: str, qos: Iterable[dict] | None) -> _TopicState:
        state = self._topics.get(topic)
        if state is not None:
            if state.type_name != type_name:
                raise BagError(f"topic {topic} is {state.type_name}, cannot also write {type_name}")
            return state
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=message_definition(type_name).encode())
        qos_list = list(qos) if qos else [default_qos_dict()]
        metadata = {
            "offered_qos_profiles": yaml.safe_dump(qos_list, sort_keys=False).strip(),
            "topic_type_hash": type_hash(type_name),
        }
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self._schemas[type_name], metadata=metadata)
        state = self._topics[topic] = _TopicState(channel_id, type_name, qos_list)
        return state

    def write(self, topic: str, msg: Any, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Serialise ``msg`` to CDR and append it."""
        from rclpy.serialization import serialize_message  # noqa: PLC0415

        self.write_serialized(topic, type_name_of(msg), serialize_message(msg), log_time_ns, publish_time_ns)

    def write_serialized(self, topic: str, type_name: str, data: bytes, log_time_ns: int,
                         publish_time_ns: int | None = None, qos: Iterable[dict] | None = None) -> None:
        """Append one CDR-serialised message."""
        log_time_ns = int(log_time_ns)
        with self._lock:
            if self.closed:
                raise BagError("write after close")
            state = self._add_topic_locked(topic, type_name, qos)
            self._writer.add_message(channel_id=state.channel_id, log_time=log_time_ns, data=bytes(data),
                                     publish_time=int(publish_time_ns if publish_time_ns is not None else log_time_ns),
                                     sequence=state.count)
            state.count += 1
            self.bytes_written += len(data)
            self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
            self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)

    def flush(self) -> None:
        """Close the open chunk and push it to disk (what a hard kill keeps)."""
        with self._lock:
            if not self.closed:
                self._writer.flush()

    def close(self) -> None:
        """Write the summary, the rosbag2 metadata record and (directory mode) metadata.yaml."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            info = self._rosbag2_metadata()
            self._writer.add_metadata("rosbag2", {
                "serialized_metadata": yaml.safe_dump(info, sort_keys=False), "ROS_DISTRO": ROS_DISTRO})
            self._writer.finish()
            self._stream.close()
            if self.directory is not None:
                (self.directory / "metadata.yaml").write_text(
                    yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False))

    def _rosbag2_metadata(self) -> dict:
        start = self.start_ns or 0
        duration = (self.end_ns - start) if self.end_ns is not None else 0
        return {
            "version": ROSBAG2_METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self.message_count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": name, "type": t.type_name, "serialization_format": "cdr",
                                    "offered_qos_profiles": t.qos, "type_description_hash": type_hash(t.type_name)},
                 "message_count": t.count}
                for name, t in self._topics.items()],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.file_path.name],
            "files": [{"path": self.file_path.name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": self.message_count}],
            "custom_data": {},
            "ros_distro": ROS_DISTRO,
        }


# ----------------------------------------------------------------------------------------------
# reading
@dataclass
class TopicInfo:
    name: str
    type_name: str
    count: int = 0
    qos_text: str = ""
    type_hash: str = ""

    @property
    def qos(self):
        """The replay QoS profile (rclpy), from the recorded offered profiles."""
        return qos_from_metadata(self.qos_text)


@dataclass
class BagMessage:
    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes = field(repr=False)

    def deserialize(self):
        from rclpy.serialization import deserialize_message  # noqa: PLC0415

        return deserialize_message(self.data, get_message_class(self.type_name))


def _resolve_bag_file(path: Path) -> Path:
    if not path.exists():
        raise BagError(f"{path}: no such file or bag directory")
    if path.is_dir():
        meta = path / "metadata.yaml"
        if meta.is_file():
            try:
                info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
                files = [path / Path(p).name for p in info.get("relative_file_paths", [])]
            except (yaml.YAMLError, KeyError, TypeError) as exc:
                raise BagError(f"{meta}: unreadable rosbag2 metadata ({exc})") from None
        else:
            files = sorted(path.glob("*.mcap"))
        files = [f for f in files if f.suffix == ".mcap" and f.is_file()]
        if not files:
            raise BagError(f"{path}: a directory with no .mcap file")
        if len(files) > 1:
            raise BagError(f"{path}: split bags ({len(files)} files) are not supported; pass one file")
        return files[0]
    return path


class BagReader:
    """Read a rosbag2 MCAP file or bag directory.

    ``truncated`` is True for a file with no summary (a recording that was killed): its messages
    are then read sequentially up to the last complete record.
    """

    def __init__(self, path: str | Path):
        self.path = _resolve_bag_file(Path(path))
        self.truncated = False
        self.error: str | None = None
        with open(self.path, "rb") as stream:
            magic = stream.read(8)
            if magic[:5] != b"\x89MCAP":
                raise BagError(f"{self.path}: not an MCAP file")
            stream.seek(0)
            try:
                reader = SeekingReader(stream)
                header = reader.get_header()
                summary = reader.get_summary()
            except (McapError, EOFError, ValueError, OSError, struct.error) as exc:
                summary, header = None, None
                self.error = str(exc)
        if header is not None and header.profile != "ros2":
            raise BagError(f"{self.path}: MCAP profile is {header.profile!r}, not a ROS 2 bag ('ros2')")
        self.topics: dict[str, TopicInfo] = {}
        self._summary = summary
        if summary is None or not summary.channels:
            self.truncated = True
            self._scan_sequentially()
        else:
            stats = summary.statistics
            counts = stats.channel_message_counts if stats else {}
            for channel in summary.channels.values():
                self._add_channel(channel, summary.schemas.get(channel.schema_id), counts.get(channel.id, 0))
            self.start_ns = stats.message_start_time if stats else 0
            self.end_ns = stats.message_end_time if stats else 0

    def _add_channel(self, channel, schema, count: int) -> None:
        if channel.message_encoding != "cdr":
            raise BagError(f"{self.path}: topic {channel.topic} is {channel.message_encoding!r}, not cdr")
        self.topics[channel.topic] = TopicInfo(
            channel.topic, schema.name if schema else "", count,
            channel.metadata.get("offered_qos_profiles", ""), channel.metadata.get("topic_type_hash", ""))

    def _iter_sequential(self) -> Iterator[tuple[Any, Any, Any]]:
        with open(self.path, "rb") as stream:
            reader = NonSeekingReader(stream)
            try:
                yield from reader.iter_messages(log_time_order=False)
            except (McapError, EOFError, ValueError, OSError, KeyError, struct.error) as exc:
                self.error = f"stopped at a damaged or incomplete record: {exc}"

    def _scan_sequentially(self) -> None:
        counts: dict[str, int] = {}
        self.start_ns, self.end_ns = None, None
        for schema, channel, message in self._iter_sequential():
            if channel.topic not in self.topics:
                self._add_channel(channel, schema, 0)
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            t = message.log_time
            self.start_ns = t if self.start_ns is None else min(self.start_ns, t)
            self.end_ns = t if self.end_ns is None else max(self.end_ns, t)
        for name, n in counts.items():
            self.topics[name].count = n
        if self.start_ns is None:
            if not self.topics:
                raise BagError(f"{self.path}: truncated MCAP with no readable message ({self.error})")
            self.start_ns = self.end_ns = 0

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def duration_ns(self) -> int:
        return int(self.end_ns - self.start_ns)

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in log-time order; ``end_ns`` exclusive."""
        wanted = set(topics) if topics is not None else None
        if self.truncated:
            rows = [(s, c, m) for s, c, m in self._iter_sequential()
                    if (wanted is None or c.topic in wanted)
                    and (start_ns is None or m.log_time >= start_ns) and (end_ns is None or m.log_time < end_ns)]
            rows.sort(key=lambda r: r[2].log_time)
            source: Iterable = rows
            for schema, channel, message in source:
                yield BagMessage(channel.topic, schema.name if schema else "", message.log_time,
                                 message.publish_time, message.data)
            return
        with open(self.path, "rb") as stream:
            reader = SeekingReader(stream)
            kwargs = {}
            if start_ns is not None:
                kwargs["starting_at"] = start_ns
            if end_ns is not None:
                kwargs["ending_before"] = end_ns
            try:
                for schema, channel, message in reader.iter_messages(
                        topics=sorted(wanted) if wanted is not None else None, log_time_order=True, **kwargs):
                    yield BagMessage(channel.topic, schema.name if schema else "", message.log_time,
                                     message.publish_time, message.data)
            except (McapError, EOFError, struct.error) as exc:
                raise BagError(f"{self.path}: damaged chunk ({exc})") from None

    def ros_messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                     end_ns: int | None = None) -> Iterator[tuple[str, Any, int]]:
        """``(topic, deserialised message, log_time_ns)`` in log-time order."""
        for item in self.messages(topics, start_ns, end_ns):
            yield item.topic, item.deserialize(), item.log_time_ns

    def describe(self) -> str:
        """A ``ros2 bag info``-like summary."""
        lines = [f"Files:             {self.path}",
                 f"Duration:          {self.duration_ns / 1e9:.3f}s",
                 f"Messages:          {self.message_count}" + ("  (truncated file)" if self.truncated else ""),
                 "Topic information:"]
        for info in sorted(self.topics.values(), key=lambda t: t.name):
            lines.append(f"  Topic: {info.name} | Type: {info.type_name} | Count: {info.count} | "
                         f"Serialization Format: cdr")
        return "\n".join(lines)


def recover(src: str | Path, dst: str | Path) -> int:
    """Rewrite a (possibly truncated) bag as a complete, indexed file; returns messages kept."""
    reader = BagReader(src)
    with BagWriter(dst) as writer:
        for info in reader.topics.values():
            qos = yaml.safe_load(info.qos_text) if info.qos_text else None
            writer.add_topic(info.name, info.type_name, qos if isinstance(qos, list) else None)
        for item in reader.messages():
            writer.write_serialized(item.topic, item.type_name, item.data, item.log_time_ns, item.publish_time_ns)
        return writer.message_count
