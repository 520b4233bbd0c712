"""A rosbag2-compatible MCAP bag writer (what Jazzy's ``ros2 bag record -s mcap`` writes).

A bag is a directory ``<bag_dir>/`` holding ``<basename>_0.mcap`` (a split bag: ``<basename>_1.mcap``, ... too)
and ``metadata.yaml``:

* the MCAP file has profile ``ros2``; one Schema per message type (encoding ``ros2msg``,
  name e.g. ``sensor_msgs/msg/JointState``, data = the rosbag2 message definition, see
  :mod:`mwip_ros.bag.schema`); one Channel per topic (message encoding ``cdr``) with the
  metadata ``offered_qos_profiles`` (the YAML text rosbag2 writes) and ``topic_type_hash``
  (``RIHS01_...``); one Message per sample (log time = receive time, data = CDR bytes);
  a Metadata record ``rosbag2`` whose ``serialized_metadata`` is the bag metadata, as
  rosbag2 writes it at open and at close;
* ``metadata.yaml`` is rosbag2 metadata version 9 (written at close, atomically; its
  contents and the QoS YAML are built in :mod:`mwip_ros.bag.metadata`).

Chunks are written to the file as soon as they are full (``chunk_size`` bytes) or span
``max_chunk_duration`` seconds of log time, whichever comes first: the chunk being filled
lives in memory, so a recording cut by ``kill -9`` loses it, at most the last
``max_chunk_duration`` (0.5 s by default) of the run; :mod:`mwip_ros.bag.repair` makes such
a file whole again (and saves the complete records of a chunk cut short on disk, e.g. by a
full disk or a power loss).

Splitting, as rosbag2's ``max_bagfile_size`` and ``max_bagfile_duration`` (0: none): before a message is written,
the file being written is finished and the next one started when it already holds more than ``max_bagfile_size``
bytes on disk (the chunk being filled is not yet there) or the message's log time is more than
``max_bagfile_duration`` seconds past the file's first message.  Each file is a whole MCAP file of its own (its
schemas and a channel for every topic known so far, its own summary, its own ``rosbag2`` record), and
``metadata.yaml`` lists them all (``relative_file_paths`` and ``files``: path, starting time, duration and messages
of each), as rosbag2 writes a split bag; the readers (:mod:`.reader`) take every file of it as one run.  The
writer's memory then stays bounded on a run of days: what an MCAP writer keeps for its summary (the index of every
chunk) belongs to one file.

As with rosbag2's MCAP plugin, zstd compresses each chunk inside the MCAP file, so
``metadata.yaml`` says ``compression_format: ""`` and ``compression_mode: ""``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Union

from mcap.writer import CompressionType, Writer

from .errors import BagError
from .metadata import (
    ROS_DISTRO, SERIALIZATION_FORMAT, FileInfo, TopicInfo, bag_metadata, dump_yaml, parse_qos_yaml,
    write_metadata_yaml,
)
from .schema import message_definition, type_hash as installed_type_hash

__all__ = ["DEFAULT_CHUNK_SIZE", "DEFAULT_MAX_CHUNK_DURATION", "BagWriter", "FileSink"]

DEFAULT_CHUNK_SIZE = 1 << 20
DEFAULT_MAX_CHUNK_DURATION = 0.5  # [s of log time]: what a kill -9 of the recorder loses at most


def _library_string() -> str:
    try:
        from importlib.metadata import version
        return f"mwip_ros/{version('mwip_ros')}"
    except Exception:
        return "mwip_ros"


class FileSink:
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

    A chunk is written once it holds ``chunk_size`` bytes (uncompressed) or spans
    ``max_chunk_duration`` seconds of log time (None: no time bound), whichever comes first.

    >>> with BagWriter("bags/run1", compression="zstd") as bag:
    ...     bag.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos_yaml, type_hash)
    ...     bag.write("/joint_states", cdr_bytes, log_time_ns)
    """

    def __init__(self, bag_dir: Union[str, Path], compression: Optional[str] = None,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, *, custom_data: Optional[Mapping[str, str]] = None,
                 ros_distro: str = ROS_DISTRO, library: Optional[str] = None,
                 max_chunk_duration: Optional[float] = DEFAULT_MAX_CHUNK_DURATION, max_bagfile_size: int = 0,
                 max_bagfile_duration: float = 0.0):
        self.path = Path(bag_dir)
        if str(bag_dir).strip() == "":
            raise BagError("bag directory must not be empty")
        compression_type = _compression(compression)
        if not isinstance(chunk_size, int) or isinstance(chunk_size, bool) or chunk_size < 1:
            raise BagError(f"chunk_size must be a positive integer number of bytes, got {chunk_size!r}")
        if max_chunk_duration is not None and not (isinstance(max_chunk_duration, (int, float))
                                                   and not isinstance(max_chunk_duration, bool)
                                                   and max_chunk_duration > 0):
            raise BagError(f"max_chunk_duration must be a positive number of seconds or None, "
                           f"got {max_chunk_duration!r}")
        if not (isinstance(max_bagfile_size, int) and not isinstance(max_bagfile_size, bool)
                and max_bagfile_size >= 0):
            raise BagError(f"max_bagfile_size must be a whole number of bytes >= 0 (0: no splitting), got "
                           f"{max_bagfile_size!r}")
        if not (isinstance(max_bagfile_duration, (int, float)) and not isinstance(max_bagfile_duration, bool)
                and 0 <= max_bagfile_duration < float("inf")):
            raise BagError(f"max_bagfile_duration must be a number of seconds >= 0 (0: no splitting), got "
                           f"{max_bagfile_duration!r}")
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
        self.max_chunk_duration = max_chunk_duration
        self._max_chunk_ns = None if max_chunk_duration is None else int(round(max_chunk_duration * 1e9))
        self._chunk_first_ns: Optional[int] = None  # log time of the first message in the chunk being filled
        self.custom_data = dict(custom_data or {})
        self.ros_distro = ros_distro
        self.max_bagfile_size = max_bagfile_size
        self.max_bagfile_duration = max_bagfile_duration
        self._max_file_ns = int(round(max_bagfile_duration * 1e9))
        self._compression_type = compression_type
        self._library = library or _library_string()
        self._files: List[FileInfo] = []
        self._topics: Dict[str, TopicInfo] = {}
        self._definitions: Dict[str, str] = {}   # type name -> its schema's text, for every file
        self._channel_meta: Dict[str, dict] = {}  # topic -> its channel's metadata, for every file
        self._closed = False
        self._open_file()

    def _open_file(self) -> None:
        """Start the next MCAP file, ``<basename>_<n>.mcap``: its header, its ``rosbag2`` record, the schemas and
        channels of every topic known so far."""
        self.relative_path = f"{self.path.name}_{len(self._files)}.mcap"
        self.mcap_path = self.path / self.relative_path
        self._sink = FileSink(self.mcap_path)
        self._file = FileInfo(self.relative_path)
        self._files.append(self._file)
        self._channels: Dict[str, int] = {}
        self._schemas: Dict[str, int] = {}
        self._chunk_first_ns = None
        self._writer = Writer(self._sink, chunk_size=self.chunk_size, compression=self._compression_type)
        self._writer.start(profile="ros2", library=self._library)
        self._write_bag_metadata_record()
        for name, t in self._topics.items():
            self._register(name, t.type, t.serialization_format)

    def _register(self, name: str, type_name: str, serialization_format: str) -> int:
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=self._definitions[type_name].encode("utf-8"))
        self._channels[name] = self._writer.register_channel(
            topic=name, message_encoding=serialization_format, schema_id=self._schemas[type_name],
            metadata=self._channel_meta[name])
        return self._channels[name]

    def _finish_file(self) -> None:
        try:
            self._write_bag_metadata_record()
            self._writer.finish()
        finally:
            self._sink.close()

    def _should_split(self, log_time_ns: int) -> bool:
        """rosbag2's rule: the file has messages and is past ``max_bagfile_size`` on disk, or this message is past
        ``max_bagfile_duration`` after its first."""
        f = self._file
        if f.start_ns is None:
            return False
        return ((self.max_bagfile_size > 0 and self._sink.tell() > self.max_bagfile_size)
                or (self._max_file_ns > 0 and log_time_ns - f.start_ns > self._max_file_ns))

    @property
    def file_count(self) -> int:
        """How many files the bag has so far (one more after each split)."""
        return len(self._files)

    @property
    def files(self) -> List[str]:
        """The bag's files so far (relative to its directory), in recording order."""
        return [f.path for f in self._files]

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
        if type_name not in self._definitions:
            self._definitions[type_name] = definition if definition is not None else message_definition(type_name)
        self._channel_meta[name] = {"offered_qos_profiles": dump_yaml(profiles), "topic_type_hash": type_hash}
        channel_id = self._register(name, type_name, serialization_format)
        self._topics[name] = TopicInfo(name, type_name, profiles, type_hash, 0, serialization_format)
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
        if self._should_split(log_time_ns):
            self._finish_file()
            self._open_file()
            channel_id = self._channels[topic]
        written = self._sink.tell()
        self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=bytes(data),
                                 publish_time=log_time_ns if publish_time_ns is None else int(publish_time_ns),
                                 sequence=int(sequence) & 0xFFFFFFFF)
        self._topics[topic].message_count += 1
        self._file.add(log_time_ns)
        self._bound_chunk(log_time_ns, chunk_written=self._sink.tell() != written)

    def _bound_chunk(self, log_time_ns: int, chunk_written: bool) -> None:
        """Write the chunk being filled once it spans ``max_chunk_duration`` of log time."""
        if chunk_written:  # full: the mcap writer wrote it, this message included
            self._chunk_first_ns = None
        elif self._chunk_first_ns is None:
            self._chunk_first_ns = log_time_ns
        elif self._max_chunk_ns is not None and abs(log_time_ns - self._chunk_first_ns) >= self._max_chunk_ns:
            self._writer.flush()  # finishes the chunk (and its message indexes) and writes it
            self._chunk_first_ns = None

    # -- state --

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def message_count(self) -> int:
        return sum(f.message_count for f in self._files)

    @property
    def topic_counts(self) -> Dict[str, int]:
        return {name: t.message_count for name, t in self._topics.items()}

    @property
    def start_time_ns(self) -> Optional[int]:
        starts = [f.start_ns for f in self._files if f.start_ns is not None]
        return min(starts) if starts else None

    @property
    def end_time_ns(self) -> Optional[int]:
        ends = [f.end_ns for f in self._files if f.end_ns is not None]
        return max(ends) if ends else None

    def metadata(self) -> Dict[str, Any]:
        """The bag's metadata (``rosbag2_bagfile_information``) as it stands now."""
        return bag_metadata(list(self._topics.values()), self._files, custom_data=self.custom_data,
                            ros_distro=self.ros_distro)

    # -- closing --

    def close(self) -> Path:
        """Finish the MCAP file and write ``metadata.yaml``; returns the bag directory. Idempotent."""
        if self._closed:
            return self.path
        self._closed = True
        self._finish_file()
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
