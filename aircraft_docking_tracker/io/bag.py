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

import heapq
import importlib
import json
import os
import re
import shutil
import struct
import sys
import threading
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterable, Iterator

import yaml
from mcap.exceptions import McapError
from mcap.data_stream import ReadDataStream
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
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


def header_stamp_ns(cdr: bytes) -> int:
    """Header stamp [ns] of a serialised message that starts with ``std_msgs/Header`` (little-endian CDR), read
    without deserialising the rest (an image's pixels)."""
    if len(cdr) < 12:
        raise BagError("message too short to hold a header")
    sec, nanosec = struct.unpack_from("<iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


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


MAX_REPLAY_DEPTH = 100_000  # a recorded queue depth above this is damaged metadata


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
    if not isinstance(items, list) or not items or not all(isinstance(i, dict) for i in items):
        return None  # damaged metadata: the QoS is unknown, as if none were recorded

    def is_(item, key, name, number):
        value = item.get(key)
        return value == number if isinstance(value, int) else str(value).lower() == name

    def depth_of(item) -> int | None:
        value = item.get("depth", 0) or 0
        return value if isinstance(value, int) and 0 <= value <= MAX_REPLAY_DEPTH else None

    depths = [depth_of(i) for i in items]
    if None in depths:
        return None
    reliable = all(is_(i, "reliability", "reliable", 1) for i in items)
    transient = all(is_(i, "durability", "transient_local", 1) for i in items)
    depth = max(depths) or 10
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


# ----------------------------------------------------------------------------------------------
# writing
@dataclass
class _TopicState:
    type_name: str
    qos: list[dict]
    definition: str | None = None  # schema text to write (None: the installed .msg files)
    hash: str | None = None
    channel_id: int = -1  # in the open file
    count: int = 0


@dataclass
class _FileState:
    """One ``.mcap`` of the bag as it is written: what rosbag2's metadata ``files`` lists."""

    path: Path
    start_ns: int | None = None
    end_ns: int | None = None
    count: int = 0

    def info(self) -> dict:
        start = self.start_ns or 0
        duration = (self.end_ns - start) if self.end_ns is not None else 0
        return {"path": self.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration}, "message_count": self.count}


class BagWriter:
    """Write a rosbag2-compatible MCAP file (``x.mcap``) or bag directory (any other path).

    Thread-safe: several subscription callbacks may write at once. :meth:`flush` closes the open
    chunk and pushes it to disk: a recorder calls it periodically, so a hard kill loses little.

    ``atomic``: write under a temporary name beside the output and move it into place only when
    :meth:`close` succeeds; an exception inside ``with`` (or :meth:`abort`) leaves no output at all
    and the previous file, if any, untouched. For tools that derive a bag from other data.

    ``max_bytes`` / ``max_duration_ns`` (directory output only, as ``ros2 bag record
    --max-bag-size / --max-bag-duration``): start ``<name>_<k+1>.mcap`` once the open file reaches
    that size or time span; ``metadata.yaml`` lists every file, and is rewritten at each split so
    that a hard-killed recording still names all its files.
    """

    def __init__(self, path: str | Path, *, compression: str = "zstd", chunk_size: int = 1 << 20,
                 overwrite: bool = False, atomic: bool = False, max_bytes: int = 0, max_duration_ns: int = 0):
        path = Path(path)
        kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in kind:
            raise BagError(f"compression must be one of {sorted(kind)}, not {compression!r}")
        self.directory = None if path.suffix == ".mcap" else path
        self.file_path = path if self.directory is None else path / f"{path.name}_0.mcap"
        if (max_bytes or max_duration_ns) and self.directory is None:
            raise BagError(f"{path}: splitting by size or duration needs a bag directory output (no .mcap suffix)")
        if max_bytes < 0 or max_duration_ns < 0:
            raise BagError("max_bytes and max_duration_ns must be >= 0")
        target = self.directory or self.file_path
        if target.exists() and not overwrite:
            raise BagError(f"{target} exists already")
        if self.directory is not None and self.directory.exists() and not self.directory.is_dir():
            raise BagError(f"{self.directory} exists and is not a directory")
        self.atomic = atomic
        self.max_bytes = int(max_bytes)
        self.max_duration_ns = int(max_duration_ns)
        self._compression = kind[compression]
        self.compression = compression
        self.chunk_size = chunk_size
        # where the files are written: the output itself, or a hidden sibling moved into place on close
        if atomic:
            self._staging = target.parent / f".{target.name}.partial-{os.getpid()}-{id(self):x}"
            if self._staging.exists():
                shutil.rmtree(self._staging) if self._staging.is_dir() else self._staging.unlink()
        else:
            self._staging = None
        self._write_dir = (self._staging if self.directory is not None else None) if atomic else self.directory
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, _TopicState] = {}
        self._files: list[_FileState] = []
        self._lock = threading.Lock()
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.bytes_written = 0
        self.closed = False
        self._open_file()

    # -- files
    def _physical(self, index: int) -> Path:
        """Where file ``index`` of the bag is being written."""
        if self.directory is None:
            return self._staging if self.atomic else self.file_path
        return self._write_dir / f"{self.directory.name}_{index}.mcap"

    def _open_file(self) -> None:
        index = len(self._files)
        physical = self._physical(index)
        physical.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(physical, "wb")  # noqa: SIM115 (closed in _finish_file())
        self._writer = Writer(self._stream, chunk_size=self.chunk_size, compression=self._compression,
                              index_types=IndexType.ALL)
        self._writer.start(profile="ros2", library=LIBRARY)
        self._schemas = {}
        name = physical.name if self.directory is not None else self.file_path.name
        self._files.append(_FileState(Path(name)))
        self._pending = 0  # payload bytes since the stream last grew (the open chunk, roughly)
        self._last_tell = self._stream.tell()
        for topic, state in self._topics.items():
            self._register(topic, state)
        if self.directory is not None and index > 0:
            self._write_metadata_yaml()

    def _finish_file(self) -> None:
        info = self._rosbag2_metadata()
        self._writer.add_metadata("rosbag2", {
            "serialized_metadata": yaml.safe_dump(info, sort_keys=False), "ROS_DISTRO": ROS_DISTRO})
        self._writer.finish()
        self._stream.close()

    def _should_split(self, log_time_ns: int) -> bool:
        current = self._files[-1]
        if current.count == 0:
            return False
        if self.max_duration_ns and log_time_ns - current.start_ns >= self.max_duration_ns:
            return True
        if self.max_bytes:
            tell = self._stream.tell()
            if tell != self._last_tell:
                self._last_tell, self._pending = tell, 0
            return tell + self._pending >= self.max_bytes
        return False

    def _write_metadata_yaml(self) -> None:
        (self._write_dir / "metadata.yaml").write_text(
            yaml.safe_dump({"rosbag2_bagfile_information": self._rosbag2_metadata()}, sort_keys=False))

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None and self.atomic:
            self.abort()
        else:
            self.close()

    @property
    def files(self) -> list[Path]:
        """The bag's files (final paths), in order."""
        if self.directory is None:
            return [self.file_path]
        return [self.directory / f.path.name for f in self._files]

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    @property
    def topic_counts(self) -> dict[str, int]:
        return {name: t.count for name, t in self._topics.items()}

    def add_topic(self, topic: str, type_name: str, qos: Iterable[dict] | None = None, *,
                  definition: str | None = None, type_hash_: str | None = None) -> None:
        """Declare a topic (done implicitly by the first write); ``qos``: dicts as qos_to_dict.

        ``definition`` (and ``type_hash_``): the schema text to store instead of the installed
        ``.msg`` files' — what a tool copying a bag passes, so that types not installed here, or
        of another version, are copied faithfully.
        """
        with self._lock:
            self._add_topic_locked(topic, type_name, qos, definition, type_hash_)

    def add_topic_like(self, info: "TopicInfo", name: str | None = None) -> None:
        """Declare a topic exactly as recorded in another bag (type, schema text, QoS, hash)."""
        self.add_topic(name or info.name, info.type_name, info.qos_list, definition=info.definition or None,
                       type_hash_=info.type_hash or None)

    def _add_topic_locked(self, topic: str, type_name: str, qos: Iterable[dict] | None,
                          definition: str | None = None, hash_: str | None = None) -> _TopicState:
        state = self._topics.get(topic)
        if state is not None:
            if state.type_name != type_name:
                raise BagError(f"topic {topic} is {state.type_name}, cannot also write {type_name}")
            return state
        if definition is None:
            definition = message_definition(type_name)  # BagError when the type is not installed
        state = _TopicState(type_name, list(qos) if qos else [default_qos_dict()], definition,
                            hash_ if hash_ is not None else type_hash(type_name))
        self._register(topic, state)
        self._topics[topic] = state
        return state

    def _register(self, topic: str, state: _TopicState) -> None:
        """Schema (once per type and file) and channel of ``topic`` in the open file."""
        key = f"{state.type_name}\n{state.definition}"
        if key not in self._schemas:
            self._schemas[key] = self._writer.register_schema(
                name=state.type_name, encoding="ros2msg", data=state.definition.encode())
        metadata = {
            "offered_qos_profiles": yaml.safe_dump(state.qos, sort_keys=False).strip(),
            "topic_type_hash": state.hash or "",
        }
        state.channel_id = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self._schemas[key], metadata=metadata)

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
            if (self.max_bytes or self.max_duration_ns) and self._should_split(log_time_ns):
                self._finish_file()
                self._open_file()
            self._writer.add_message(channel_id=state.channel_id, log_time=log_time_ns, data=bytes(data),
                                     publish_time=int(publish_time_ns if publish_time_ns is not None else log_time_ns),
                                     sequence=state.count)
            state.count += 1
            self.bytes_written += len(data)
            self._pending += len(data)
            current = self._files[-1]
            current.count += 1
            current.start_ns = log_time_ns if current.start_ns is None else min(current.start_ns, log_time_ns)
            current.end_ns = log_time_ns if current.end_ns is None else max(current.end_ns, log_time_ns)
            self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
            self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)

    def flush(self) -> None:
        """Close the open chunk and push it to disk (what a hard kill keeps)."""
        with self._lock:
            if not self.closed:
                self._writer.flush()

    def close(self) -> None:
        """Write the summary, the rosbag2 metadata record and (directory mode) metadata.yaml;
        an atomic writer then moves its files into place."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            self._finish_file()
            if self.directory is not None:
                self._write_metadata_yaml()
            if self.atomic:
                self._commit()

    def abort(self) -> None:
        """Stop without an output: an atomic writer removes what it wrote (a plain one finishes
        the file, as :meth:`close`: a partial recording is still worth keeping)."""
        if not self.atomic:
            self.close()
            return
        with self._lock:
            if self.closed:
                return
            self.closed = True
            try:
                self._stream.close()
            finally:
                if self._staging.is_dir():
                    shutil.rmtree(self._staging, ignore_errors=True)
                elif self._staging.exists():
                    self._staging.unlink()

    def _commit(self) -> None:
        if self.directory is None:
            os.replace(self._staging, self.file_path)
            return
        self.directory.mkdir(parents=True, exist_ok=True)
        # the bag's own files only: an existing directory may hold other things
        for old in self.directory.glob(f"{glob_escape(self.directory.name)}_*.mcap"):
            old.unlink()
        for f in self._files:
            os.replace(self._staging / f.path.name, self.directory / f.path.name)
        os.replace(self._staging / "metadata.yaml", self.directory / "metadata.yaml")
        shutil.rmtree(self._staging, ignore_errors=True)

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
                                    "offered_qos_profiles": t.qos, "type_description_hash": t.hash or ""},
                 "message_count": t.count}
                for name, t in self._topics.items()],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [f.path.name for f in self._files],
            "files": [f.info() for f in self._files],
            "custom_data": {},
            "ros_distro": ROS_DISTRO,
        }


def glob_escape(text: str) -> str:
    """``text`` with glob wildcards escaped (a bag named ``run[1]``)."""
    return re.sub(r"([*?\[])", r"[\1]", text)


# ----------------------------------------------------------------------------------------------
# reading
@dataclass
class TopicInfo:
    name: str
    type_name: str
    count: int = 0
    qos_text: str = ""
    type_hash: str = ""
    definition: str = ""  # the recorded schema text (ros2msg)

    @property
    def qos(self):
        """The replay QoS profile (rclpy), from the recorded offered profiles."""
        return qos_from_metadata(self.qos_text)

    @property
    def qos_list(self) -> list[dict] | None:
        """The recorded offered QoS profiles as dicts (None when absent or unreadable)."""
        try:
            items = yaml.safe_load(self.qos_text) if self.qos_text else None
        except yaml.YAMLError:
            return None
        return items if isinstance(items, list) and all(isinstance(i, dict) for i in items) else None


@dataclass
class BagMessage:
    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes = field(repr=False)

    def deserialize(self):
        """The ROS message; BagError when the type is not installed or the bytes do not decode."""
        from rclpy.serialization import deserialize_message  # noqa: PLC0415

        cls = get_message_class(self.type_name)
        try:
            return deserialize_message(self.data, cls)
        except Exception as exc:  # rclpy raises RMWError (a RuntimeError) on bad CDR  # noqa: BLE001
            raise BagError(f"a {self.type_name} message on {self.topic} at {self.log_time_ns} ns does not "
                           f"deserialise ({exc})") from None


# What reading damaged or hostile bytes can raise from the mcap library and its decompressors
# (zstandard.ZstdError derives from Exception only; lz4 raises RuntimeError).
_READ_ERRORS = (McapError, EOFError, ValueError, OSError, KeyError, IndexError, struct.error, RuntimeError,
                MemoryError, OverflowError, TypeError, AttributeError)
try:  # pragma: no cover - zstandard is an mcap dependency
    from zstandard import ZstdError
    _READ_ERRORS = _READ_ERRORS + (ZstdError,)
except ImportError:  # pragma: no cover
    pass


def bag_files(path: str | Path) -> list[Path]:
    """The ``.mcap`` files of a bag: the file itself, or a directory's files in order (as listed in
    its ``metadata.yaml``, else sorted by their ``_<k>`` index)."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such file or bag directory")
    if not path.is_dir():
        return [path]
    meta = path / "metadata.yaml"
    listed: list[Path] = []
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
            listed = [path / Path(str(p)).name for p in info.get("relative_file_paths", []) or []]
        except (yaml.YAMLError, KeyError, TypeError, AttributeError, UnicodeDecodeError) as exc:
            raise BagError(f"{meta}: unreadable rosbag2 metadata ({exc})") from None
        if any(p.suffix != ".mcap" for p in listed):
            raise BagError(f"{path}: storage is not MCAP ({', '.join(p.name for p in listed)}); "
                           f"convert it with `ros2 bag convert`")
        missing = [p.name for p in listed if not p.is_file()]
        if missing:
            raise BagError(f"{path}: metadata.yaml lists files that are missing: {', '.join(missing)}")
    # a file metadata.yaml does not list (a recorder killed before it rewrote the list) is read too
    def index(p: Path) -> tuple[int, str]:
        tail = p.stem.rsplit("_", 1)
        return (int(tail[1]) if len(tail) == 2 and tail[1].isdigit() else 1 << 30, p.name)
    extra = sorted((p for p in path.glob("*.mcap") if p.is_file() and p not in listed), key=index)
    files = listed + extra
    if not files:
        raise BagError(f"{path}: a directory with no .mcap file")
    return files


class _McapFile:
    """One ``.mcap`` file of a bag: its topics, and its messages in log-time order.

    A file whose summary is missing or unreadable (a recorder killed hard) is read sequentially
    up to its last complete record. A chunk that does not decode (a damaged disk, a cut file) is
    skipped and reported in ``error``; reading never raises once the file is open.
    """

    def __init__(self, path: Path):
        self.path = path
        self.truncated = False
        self.error: str | None = None
        self.skipped_chunks = 0
        self.size = path.stat().st_size
        with open(path, "rb") as stream:
            magic = stream.read(8)
            if magic[:5] != b"\x89MCAP":
                raise BagError(f"{path}: not an MCAP file")
            stream.seek(0)
            try:
                reader = SeekingReader(stream, validate_crcs=True, record_size_limit=self.size)
                header = reader.get_header()
                summary = reader.get_summary()
            except _READ_ERRORS as exc:
                summary, header = None, None
                self.error = f"no readable summary ({exc})"
        if header is not None and header.profile != "ros2":
            raise BagError(f"{path}: MCAP profile is {header.profile!r}, not a ROS 2 bag ('ros2')")
        self.topics: dict[str, TopicInfo] = {}
        self._summary = summary
        if summary is None or not summary.channels:
            self._summary = None
            self.truncated = True
            self._scan_sequentially()
        else:
            stats = summary.statistics
            counts = stats.channel_message_counts if stats else {}
            for channel in summary.channels.values():
                self._add_channel(channel, summary.schemas.get(channel.schema_id), counts.get(channel.id, 0))
            self.start_ns = stats.message_start_time if stats else 0
            self.end_ns = stats.message_end_time if stats else 0
            if not summary.chunk_indexes:  # no messages, or messages outside chunks: read in file order
                self._summary = None

    def _add_channel(self, channel, schema, count: int) -> None:
        if channel.message_encoding != "cdr":
            raise BagError(f"{self.path}: topic {channel.topic} is {channel.message_encoding!r}, not cdr")
        definition = ""
        if schema is not None:
            definition = bytes(schema.data).decode("utf-8", errors="replace")
        self.topics[channel.topic] = TopicInfo(
            channel.topic, schema.name if schema else "", count,
            channel.metadata.get("offered_qos_profiles", ""), channel.metadata.get("topic_type_hash", ""),
            definition)

    def _iter_sequential(self) -> Iterator[tuple[Any, Any, Any]]:
        with open(self.path, "rb") as stream:
            reader = NonSeekingReader(stream, validate_crcs=True, record_size_limit=self.size)
            try:
                yield from reader.iter_messages(log_time_order=False)
            except _READ_ERRORS as exc:
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
                if self.error is None:     # read to its end undamaged: mcap_record stopped before any message
                    raise BagError(f"{self.path}: holds no message (an empty recording)")
                raise BagError(f"{self.path}: truncated MCAP with no readable message ({self.error})")
            self.start_ns = self.end_ns = 0

    def raw(self, topics: set[str] | None, start_ns: int | None, end_ns: int | None) -> Iterator[BagMessage]:
        """Messages in log-time order (a truncated file: in file order, re-sorted within a window)."""
        def wanted(channel, message) -> bool:
            return ((topics is None or channel.topic in topics)
                    and (start_ns is None or message.log_time >= start_ns)
                    and (end_ns is None or message.log_time < end_ns))

        def item(schema, channel, message) -> BagMessage:
            return BagMessage(channel.topic, schema.name if schema else "", message.log_time,
                              message.publish_time, message.data)

        if self._summary is None:
            # bounded reordering: memory stays flat however long the damaged recording is
            heap: list = []
            for n, (schema, channel, message) in enumerate(self._iter_sequential()):
                if wanted(channel, message):
                    heapq.heappush(heap, (message.log_time, n, item(schema, channel, message)))
                    if len(heap) > 256:
                        yield heapq.heappop(heap)[2]
            while heap:
                yield heapq.heappop(heap)[2]
            return
        yield from self._indexed(topics, start_ns, end_ns, wanted, item)

    def _indexed(self, topics, start_ns, end_ns, wanted, item) -> Iterator[BagMessage]:
        """The chunk index, chunk by chunk (as mcap's SeekingReader), skipping chunks that do not decode."""
        summary = self._summary
        channel_ids = {cid for cid, c in summary.channels.items() if topics is None or c.topic in topics}
        heap: list = []
        for k, index in enumerate(summary.chunk_indexes):
            if start_ns is not None and index.message_end_time < start_ns:
                continue
            if end_ns is not None and index.message_start_time >= end_ns:
                continue
            if index.message_index_offsets and not channel_ids.intersection(index.message_index_offsets):
                continue
            heapq.heappush(heap, (index.message_start_time, 0, k, 0, index))
        everything = start_ns is None and end_ns is None
        delivered = 0
        with open(self.path, "rb") as stream:
            while heap:
                log_time, kind, k, n, payload = heapq.heappop(heap)
                if kind == 1:
                    delivered += 1
                    yield payload
                    continue
                try:
                    if payload.chunk_start_offset + 9 > self.size or payload.chunk_length > self.size:
                        raise BagError("chunk index points outside the file")
                    stream.seek(payload.chunk_start_offset + 1 + 8)
                    chunk = Chunk.read(ReadDataStream(stream))
                    records = breakup_chunk(chunk, validate_crc=True)
                    batch = []
                    for m, record in enumerate(records):
                        if not isinstance(record, Message):
                            continue
                        channel = summary.channels.get(record.channel_id)
                        if channel is None or record.channel_id not in channel_ids or not wanted(channel, record):
                            continue
                        schema = summary.schemas.get(channel.schema_id)
                        batch.append((record.log_time, 1, k, m, item(schema, channel, record)))
                except (BagError, *_READ_ERRORS) as exc:
                    self.skipped_chunks += 1
                    self.error = (f"{self.skipped_chunks} damaged chunk(s) skipped "
                                  f"(last at byte {payload.chunk_start_offset}: {exc})")
                    continue
                for entry in batch:
                    heapq.heappush(heap, entry)
        expected = sum(t.count for name, t in self.topics.items() if topics is None or name in topics)
        if everything and delivered != expected and self.error is None:
            # a damaged index or statistics record: the summary promised other messages than were found
            self.error = f"the summary lists {expected} messages, {delivered} were found"


class BagReader:
    """Read a rosbag2 MCAP file or bag directory, split bags included (several ``.mcap`` files,
    as ``ros2 bag record --max-bag-size`` writes), merged in log-time order.

    ``truncated`` is True when a file has no summary (a recording that was killed): its messages
    are then read sequentially up to the last complete record. Damaged chunks are skipped. Both
    are reported by :attr:`problem` (None for a sound bag), which the tools print as a warning.
    """

    def __init__(self, path: str | Path):
        self.bag_path = Path(path)
        self.files = bag_files(self.bag_path)
        self._parts: list[_McapFile] = []
        self.unreadable_files: list[str] = []  # of a split bag: files that do not open (the others are read)
        for f in self.files:
            try:
                self._parts.append(_McapFile(f))
            except BagError as exc:
                if len(self.files) == 1:
                    raise
                self.unreadable_files.append(str(exc))
        if not self._parts:
            raise BagError(f"{self.bag_path}: no file of the bag can be read ({'; '.join(self.unreadable_files)})")
        self.path = self.files[0] if len(self.files) == 1 else self.bag_path
        self.topics: dict[str, TopicInfo] = {}
        for part in self._parts:
            for name, info in part.topics.items():
                known = self.topics.get(name)
                if known is None:
                    self.topics[name] = TopicInfo(**vars(info))
                elif known.type_name != info.type_name:
                    raise BagError(f"{self.bag_path}: topic {name} is {known.type_name} in one file and "
                                   f"{info.type_name} in {part.path.name}")
                else:
                    known.count += info.count
        starts = [p.start_ns for p in self._parts if p.start_ns or p.end_ns]
        ends = [p.end_ns for p in self._parts if p.start_ns or p.end_ns]
        self.start_ns = min(starts) if starts else 0
        self.end_ns = max(ends) if ends else 0

    @property
    def truncated(self) -> bool:
        return any(p.truncated for p in self._parts)

    @property
    def error(self) -> str | None:
        errors = [f"{p.path.name}: {p.error}" if len(self.files) > 1 else p.error
                  for p in self._parts if p.error] + [f"skipped {e}" for e in self.unreadable_files]
        return "; ".join(errors) if errors else None

    @property
    def problem(self) -> str | None:
        """What is wrong with the bag, in words (None if nothing): say it before trusting the data.

        Known once the bag is open for a missing summary; damaged chunks are found while reading,
        so check again after iterating.
        """
        if not self.truncated and not self.error:
            return None
        if self.truncated:
            return (f"{self.bag_path} is truncated ({self.error or 'no summary'}): a recording killed hard? "
                    f"Read up to its last complete chunk ({self.message_count} messages); "
                    f"`mcap_record --recover IN OUT` rewrites it whole for indexed readers (ros2 bag, rosbags)")
        return f"{self.bag_path} is damaged: {self.error}; the rest was read"

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def duration_ns(self) -> int:
        return int(self.end_ns - self.start_ns)

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in log-time order; ``end_ns`` exclusive. Never raises on damaged data: what
        cannot be read is skipped and reported by :attr:`problem`."""
        wanted = set(topics) if topics is not None else None
        streams = [p.raw(wanted, start_ns, end_ns) for p in self._parts]
        if len(streams) == 1:
            yield from streams[0]
        else:
            yield from heapq.merge(*streams, key=lambda m: m.log_time_ns)

    def ros_messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                     end_ns: int | None = None) -> Iterator[tuple[str, Any, int]]:
        """``(topic, deserialised message, log_time_ns)`` in log-time order (BagError on bytes that
        do not deserialise)."""
        for item in self.messages(topics, start_ns, end_ns):
            yield item.topic, item.deserialize(), item.log_time_ns

    def describe(self) -> str:
        """A ``ros2 bag info``-like summary."""
        files = ", ".join(str(f) for f in self.files)
        lines = [f"Files:             {files}",
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
    check_outputs([dst], reader.files + [reader.bag_path], "mcap_record --recover")
    with BagWriter(dst, atomic=True) as writer:
        for info in reader.topics.values():
            writer.add_topic_like(info)
        for item in reader.messages():
            writer.write_serialized(item.topic, item.type_name, item.data, item.log_time_ns, item.publish_time_ns)
        return writer.message_count


# ----------------------------------------------------------------------------------------------
# outputs that would destroy inputs
def _inside(path: Path, folder: Path) -> bool:
    try:
        path.relative_to(folder)
        return True
    except ValueError:
        return False


def check_outputs(outputs: Iterable[str | Path | None], inputs: Iterable[str | Path], tool: str = "") -> None:
    """Refuse (``BagError``) an output that is, or would overwrite, one of the inputs.

    ``inputs``: the files a tool reads (a bag's files and its directory, a frame folder's frames);
    an output is a file or a bag directory, refused too when it is a directory holding an input. Symbolic links and hard links count as the same file. ``None`` and ``-`` (stdout)
    outputs are ignored.
    """
    resolved_inputs = [Path(raw).resolve() for raw in inputs if Path(raw).exists()]
    for raw in outputs:
        if raw is None or str(raw) == "-":
            continue
        out = Path(raw).resolve()
        candidates = [out]
        if out.suffix != ".mcap" and not (out.exists() and out.is_file()):
            candidates += [out / f"{out.name}_0.mcap", out / "metadata.yaml"]
        for inp in resolved_inputs:
            same = any(c == inp for c in candidates)
            same = same or (out.exists() and inp.exists() and os.path.samefile(out, inp))
            # an output directory holding an input, or an input directory holding the output file
            same = same or (out.is_dir() and _inside(inp, out))
            if same:
                who = f"{tool}: " if tool else ""
                raise BagError(f"{who}output {raw} would overwrite the input {inp}; choose another output")
