"""A rosbag2-compatible MCAP bag writer (what Jazzy's ``ros2 bag record -s mcap`` writes).

A bag is a directory ``<bag_dir>/`` holding ``<basename>_0.mcap`` and ``metadata.yaml``:

* the MCAP file has profile ``ros2``; one Schema per message type (encoding ``ros2msg``,
  name e.g. ``sensor_msgs/msg/JointState``, data = the rosbag2 message definition, see
  :mod:`mwip_ros.bag.schema`); one Channel per topic (message encoding ``cdr``) with the
  metadata ``offered_qos_profiles`` (the YAML text rosbag2 writes) and ``topic_type_hash``
  (``RIHS01_...``); one Message per sample (log time = receive time, data = CDR bytes);
  a Metadata record ``rosbag2`` whose ``serialized_metadata`` is the bag metadata, as
  rosbag2 writes it at open and at close;
* ``metadata.yaml`` is rosbag2 metadata version 9 (written at close, atomically).

Chunks are written to the file as soon as they are full, so a recording cut by
``kill -9`` loses at most its last, unfinished chunk; :mod:`mwip_ros.bag.repair` makes
such a file whole again.

As with rosbag2's MCAP plugin, zstd compresses each chunk inside the MCAP file, so
``metadata.yaml`` says ``compression_format: ""`` and ``compression_mode: ""``.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Union

import yaml
from mcap.writer import CompressionType, Writer

from .schema import BagError, message_definition, type_hash as installed_type_hash

METADATA_VERSION = 9
STORAGE_IDENTIFIER = "mcap"
SERIALIZATION_FORMAT = "cdr"
ROS_DISTRO = "jazzy"
DEFAULT_CHUNK_SIZE = 1 << 20
EMPTY_STARTING_TIME = 2 ** 63 - 1  # what rosbag2 writes for a bag without messages


def _library_string() -> str:
    try:
        from importlib.metadata import version
        return f"mwip_ros/{version('mwip_ros')}"
    except Exception:
        return "mwip_ros"


# --- QoS profiles, rendered the way rosbag2 (Jazzy, metadata version 9) renders them ---------

HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
LIVELINESS = {0: "system_default", 1: "automatic", 2: "manual_by_node", 3: "manual_by_topic", 4: "unknown",
              5: "best_available"}
_POLICIES = {"history": HISTORY, "reliability": RELIABILITY, "durability": DURABILITY, "liveliness": LIVELINESS}
_QOS_KEYS = ("history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
             "liveliness_lease_duration", "avoid_ros_namespace_conventions")
_TIME_KEYS = ("deadline", "lifespan", "liveliness_lease_duration")


def _duration_map(value: Any) -> Dict[str, int]:
    """rclpy Duration / nanoseconds / {'sec','nsec'} -> {'sec': s, 'nsec': ns} (rmw_time_t)."""
    if isinstance(value, Mapping):
        return {"sec": int(value.get("sec", 0)), "nsec": int(value.get("nsec", 0))}
    ns = int(getattr(value, "nanoseconds", value))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _policy_name(kind: str, value: Any) -> str:
    names = _POLICIES[kind]
    if isinstance(value, str):
        v = value.strip().lower()
        if v.isdigit():
            return names.get(int(v), "unknown")
        return v
    return names.get(int(value), "unknown")


def qos_profile_dict(profile: Any) -> Dict[str, Any]:
    """One QoS profile (rclpy ``QoSProfile``, or a dict as in metadata version 8 or 9) as the
    ordered dict rosbag2 version 9 writes: policy names as strings, durations as sec/nsec."""
    get = (lambda k, d=None: profile.get(k, d)) if isinstance(profile, Mapping) \
        else (lambda k, d=None: getattr(profile, k, d))
    out: Dict[str, Any] = {}
    for key in _QOS_KEYS:
        value = get(key)
        if key in _POLICIES:
            out[key] = _policy_name(key, 0 if value is None else value)
        elif key == "depth":
            out[key] = int(value or 0)
        elif key in _TIME_KEYS:
            out[key] = _duration_map(0 if value is None else value)
        else:
            out[key] = bool(value)
    return out


def _emit(value: Any, indent: int, lines: List[str], key: Optional[str] = None) -> None:
    """Block-style YAML the way yaml-cpp's Dump lays it out (rosbag2 uses yaml-cpp)."""
    pad = " " * indent
    prefix = f"{pad}{key}:" if key is not None else None
    if isinstance(value, Mapping):
        if not value:
            lines.append(f"{prefix} ~" if prefix else f"{pad}~")
            return
        if prefix:
            lines.append(prefix)
            for k, v in value.items():
                _emit(v, indent + 2, lines, k)
        else:
            for k, v in value.items():
                _emit(v, indent, lines, k)
        return
    if isinstance(value, (list, tuple)):
        if prefix:
            lines.append(prefix)
            inner = indent + 2
        else:
            inner = indent
        if not value:
            lines.append(" " * inner + "[]")
            return
        for item in value:
            sub: List[str] = []
            _emit(item, inner + 2, sub)
            first = sub[0]
            lines.append(" " * inner + "- " + first[inner + 2:])
            lines.extend(sub[1:])
        return
    text = _scalar(value)
    lines.append(f"{prefix} {text}" if prefix else f"{pad}{text}")


_PLAIN_SAFE = re.compile(r"^[A-Za-z0-9_./][A-Za-z0-9_./+\-]*$")


def _scalar(value: Any) -> str:
    if value is None:
        return "~"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    s = str(value)
    if s == "":
        return '""'
    if _PLAIN_SAFE.match(s):
        try:
            if yaml.safe_load(s) == s:
                return s
        except yaml.YAMLError:
            pass
    return json.dumps(s)  # a JSON string is a valid YAML double-quoted scalar


def dump_yaml(value: Any) -> str:
    """``value`` as block YAML laid out like yaml-cpp (no trailing newline)."""
    lines: List[str] = []
    _emit(value, 0, lines)
    return "\n".join(lines)


def qos_profiles_yaml(profiles: Iterable[Any]) -> str:
    """The ``offered_qos_profiles`` channel-metadata string rosbag2 (Jazzy) writes for a topic:
    ``YAML::Dump`` of the list of profiles, e.g. ``- history: unknown\\n  depth: 0\\n  reliability:
    reliable\\n ... \\n  avoid_ros_namespace_conventions: false``; ``[]`` for no profiles."""
    return dump_yaml([qos_profile_dict(p) for p in profiles])


def parse_qos_yaml(text: Optional[str]) -> List[Dict[str, Any]]:
    """A channel's ``offered_qos_profiles`` (v8 integers or v9 names) -> list of v9 profile dicts."""
    if text is None or not str(text).strip():
        return []
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise BagError(f"offered_qos_profiles is not valid YAML: {exc}") from None
    if doc is None:
        return []
    if not isinstance(doc, list) or not all(isinstance(p, Mapping) for p in doc):
        raise BagError(f"offered_qos_profiles must be a YAML list of profiles, got {text!r}")
    return [qos_profile_dict(p) for p in doc]


# --- metadata.yaml -----------------------------------------------------------------------------

@dataclass
class TopicInfo:
    name: str
    type: str
    offered_qos_profiles: List[Dict[str, Any]] = field(default_factory=list)
    type_description_hash: str = ""
    message_count: int = 0
    serialization_format: str = SERIALIZATION_FORMAT


@dataclass
class FileInfo:
    path: str
    message_count: int = 0
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None

    def add(self, log_time_ns: int) -> None:
        self.message_count += 1
        self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
        self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)

    @property
    def starting_time(self) -> int:
        return EMPTY_STARTING_TIME if self.start_ns is None else self.start_ns

    @property
    def duration(self) -> int:
        return 0 if self.start_ns is None else self.end_ns - self.start_ns


def bag_metadata(topics: Sequence[TopicInfo], files: Sequence[FileInfo], *, compression_format: str = "",
                 compression_mode: str = "", custom_data: Optional[Mapping[str, str]] = None,
                 ros_distro: str = ROS_DISTRO) -> Dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping (metadata version 9), keys in rosbag2's order."""
    starts = [f.start_ns for f in files if f.start_ns is not None]
    ends = [f.end_ns for f in files if f.end_ns is not None]
    start = min(starts) if starts else None
    return {
        "version": METADATA_VERSION,
        "storage_identifier": STORAGE_IDENTIFIER,
        "duration": {"nanoseconds": (max(ends) - start) if start is not None else 0},
        "starting_time": {"nanoseconds_since_epoch": start if start is not None else EMPTY_STARTING_TIME},
        "message_count": sum(f.message_count for f in files),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": [qos_profile_dict(p) for p in t.offered_qos_profiles],
                    "type_description_hash": t.type_description_hash,
                },
                "message_count": t.message_count,
            }
            for t in topics
        ],
        "compression_format": compression_format,
        "compression_mode": compression_mode,
        "relative_file_paths": [f.path for f in files],
        "files": [
            {
                "path": f.path,
                "starting_time": {"nanoseconds_since_epoch": f.starting_time},
                "duration": {"nanoseconds": f.duration},
                "message_count": f.message_count,
            }
            for f in files
        ],
        "custom_data": dict(custom_data) if custom_data else None,
        "ros_distro": ros_distro,
    }


def metadata_yaml_text(info: Mapping[str, Any]) -> str:
    """The text of ``metadata.yaml`` for a ``bag_metadata()`` mapping."""
    return dump_yaml({"rosbag2_bagfile_information": info}) + "\n"


def write_metadata_yaml(bag_dir: Union[str, Path], info: Mapping[str, Any]) -> Path:
    """Write ``<bag_dir>/metadata.yaml`` atomically (temporary file, fsync, rename)."""
    bag_dir = Path(bag_dir)
    final = bag_dir / "metadata.yaml"
    tmp = bag_dir / f".metadata.yaml.{os.getpid()}.tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(metadata_yaml_text(info))
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, final)
    return final


# --- the writer --------------------------------------------------------------------------------

class _FileSink:
    """Unbuffered output for mcap's Writer: every record group it writes (a whole chunk, say)
    reaches the OS at once, so a killed process leaves every finished chunk in the file."""

    def __init__(self, path: Path):
        self._fh = open(path, "xb", buffering=0)
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        done = 0
        while done < len(view):
            done += self._fh.write(view[done:])
        self._pos += done
        return done

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def close(self, sync: bool = True) -> None:
        if self._fh.closed:
            return
        if sync:
            try:
                os.fsync(self._fh.fileno())
            except OSError:  # pragma: no cover
                pass
        self._fh.close()


def _compression(value: Optional[str]) -> CompressionType:
    v = (value or "").strip().lower()
    if v in ("", "none"):
        return CompressionType.NONE
    if v == "zstd":
        return CompressionType.ZSTD
    raise BagError(f"unsupported compression {value!r}: use '' (none) or 'zstd'")


class BagWriter:
    """Write a rosbag2 bag (MCAP storage) into a new directory.

    >>> with BagWriter("bags/run1", compression="zstd") as bag:
    ...     bag.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos_yaml, type_hash)
    ...     bag.write("/joint_states", cdr_bytes, log_time_ns)
    """

    def __init__(self, bag_dir: Union[str, Path], compression: Optional[str] = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, *, custom_data: Optional[Mapping[str, str]] = None,
                 ros_distro: str = ROS_DISTRO, library: Optional[str] = None):
        self.path = Path(bag_dir)
        if str(bag_dir).strip() == "":
            raise BagError("bag directory must not be empty")
        compression_type = _compression(compression)
        if not isinstance(chunk_size, int) or isinstance(chunk_size, bool) or chunk_size < 1:
            raise BagError(f"chunk_size must be a positive integer number of bytes, got {chunk_size!r}")
        if self.path.exists() or self.path.is_symlink():
            raise BagError(f"bag directory {self.path} already exists; refusing to overwrite it "
                           f"(choose a new output path)")
        if self.path.name in ("", ".", ".."):
            raise BagError(f"bag directory {self.path} has no usable name")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.mkdir()
        except FileExistsError:
            raise BagError(f"bag directory {self.path} already exists; refusing to overwrite it") from None
        except OSError as exc:
            raise BagError(f"cannot create bag directory {self.path}: {exc.strerror or exc}") from None
        self.compression = "zstd" if compression_type is CompressionType.ZSTD else ""
        self.chunk_size = chunk_size
        self.custom_data = dict(custom_data or {})
        self.ros_distro = ros_distro
        self.relative_path = f"{self.path.name}_0.mcap"
        self.mcap_path = self.path / self.relative_path
        self._file = FileInfo(self.relative_path)
        self._topics: Dict[str, TopicInfo] = {}
        self._channels: Dict[str, int] = {}
        self._schemas: Dict[str, int] = {}
        self._closed = False
        self._sink = _FileSink(self.mcap_path)
        self._writer = Writer(self._sink, chunk_size=chunk_size, compression=compression_type)
        self._writer.start(profile="ros2", library=library or _library_string())
        self._write_bag_metadata_record()

    # -- topics and messages --

    def add_topic(self, name: str, type_name: str, qos_yaml: Optional[str] = "", type_hash: Optional[str] = "",
                  *, definition: Optional[str] = None, serialization_format: str = SERIALIZATION_FORMAT) -> int:
        """Register a topic (MCAP channel, and its type's schema once); returns the channel id.

        ``qos_yaml`` is the publishers' offered QoS as rosbag2 writes it (see
        :func:`qos_profiles_yaml`; '' = none known); ``type_hash`` the ``RIHS01_...`` hash
        ('' = take the installed type's).  Registering a topic again with the same type
        returns its channel id.
        """
        self._check_open()
        if not name:
            raise BagError("topic name must not be empty")
        if name in self._topics:
            if self._topics[name].type != type_name:
                raise BagError(f"topic {name!r} already added with type {self._topics[name].type!r}, "
                               f"not {type_name!r}")
            return self._channels[name]
        profiles = parse_qos_yaml(qos_yaml)
        type_hash = type_hash or installed_type_hash(type_name)
        if type_name not in self._schemas:
            text = definition if definition is not None else message_definition(type_name)
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=text.encode("utf-8"))
        channel_id = self._writer.register_channel(
            topic=name, message_encoding=serialization_format, schema_id=self._schemas[type_name],
            metadata={"offered_qos_profiles": dump_yaml(profiles), "topic_type_hash": type_hash})
        self._topics[name] = TopicInfo(name, type_name, profiles, type_hash, 0, serialization_format)
        self._channels[name] = channel_id
        return channel_id

    def has_topic(self, name: str) -> bool:
        return name in self._topics

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: Optional[int] = None,
              sequence: int = 0) -> None:
        """Append one serialized (CDR) message; ``log_time_ns`` is its receive time."""
        self._check_open()
        channel_id = self._channels.get(topic)
        if channel_id is None:
            raise BagError(f"topic {topic!r} was not added to bag {self.path} (call add_topic first)")
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise BagError(f"log time of a message on {topic!r} is negative: {log_time_ns}")
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=bytes(data),
                                 publish_time=log_time_ns if publish_time_ns is None else int(publish_time_ns),
                                 sequence=int(sequence) & 0xFFFFFFFF)
        self._topics[topic].message_count += 1
        self._file.add(log_time_ns)

    # -- state --

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def message_count(self) -> int:
        return self._file.message_count

    @property
    def topic_counts(self) -> Dict[str, int]:
        return {name: t.message_count for name, t in self._topics.items()}

    @property
    def start_time_ns(self) -> Optional[int]:
        return self._file.start_ns

    @property
    def end_time_ns(self) -> Optional[int]:
        return self._file.end_ns

    def metadata(self) -> Dict[str, Any]:
        """The bag's metadata (``rosbag2_bagfile_information``) as it stands now."""
        return bag_metadata(list(self._topics.values()), [self._file], custom_data=self.custom_data,
                            ros_distro=self.ros_distro)

    # -- closing --

    def close(self) -> Path:
        """Finish the MCAP file and write ``metadata.yaml``; returns the bag directory. Idempotent."""
        if self._closed:
            return self.path
        self._closed = True
        try:
            self._write_bag_metadata_record()
            self._writer.finish()
        finally:
            self._sink.close()
        write_metadata_yaml(self.path, self.metadata())
        return self.path

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f"bag {self.path} is already closed")

    def _write_bag_metadata_record(self) -> None:
        self._writer.add_metadata("rosbag2", {"serialized_metadata": dump_yaml(self.metadata())})


__all__ = [
    "BagError", "BagWriter", "FileInfo", "TopicInfo", "bag_metadata", "dump_yaml", "metadata_yaml_text",
    "parse_qos_yaml", "qos_profile_dict", "qos_profiles_yaml", "write_metadata_yaml",
]
