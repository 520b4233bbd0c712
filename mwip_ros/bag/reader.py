"""Read rosbag2 MCAP bags with the ``mcap`` library alone (no rclpy, no message decoding).

``bag`` is a bag directory (its ``metadata.yaml`` lists the files; without one every
``*.mcap`` in it is read, in the order of their ``_<n>`` suffix) or a single ``.mcap`` file.

* :func:`raw_messages` yields ``(log_time_ns, topic, cdr_bytes)`` in log-time order, the
  files of a split bag merged; decoding the bytes is the message layer's job;
* :func:`topic_counts` and :func:`topic_types` read the MCAP summaries;
* :func:`mcap_files` and :func:`read_metadata` find the files and ``metadata.yaml``.

Chunk CRCs are checked on every read: damaged data is never handed out as messages.
:func:`check` finds every damaged chunk of a bag up front (the tools that replay or
re-simulate a bag call it before they start); a read that meets one raises
:class:`~.errors.BagError` naming the file and the chunk's byte offset, and a file that
cannot be read at all (a recording cut short) raises one that suggests ``mwip_bag_repair``.
"""
from __future__ import annotations

import heapq
import re
import struct
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple, Union

import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import breakup_chunk

from mwip_ros.params.errors import bounded
from mwip_ros.yamlio import YamlRefused, load_yaml, open_regular

from .errors import BagError

__all__ = ["check", "damaged_chunks", "mcap_files", "raw_messages", "read_metadata", "topic_counts",
           "topic_qos", "topic_types"]

PathLike = Union[str, Path]
_UNREADABLE = (McapError, struct.error, EOFError, ValueError)


def _file_index(path: Path) -> Tuple[int, str]:
    m = re.search(r"_(\d+)\.mcap$", path.name)
    return (int(m.group(1)) if m else 0, path.name)


def read_metadata(bag_dir: PathLike) -> Optional[Dict[str, Any]]:
    """The ``rosbag2_bagfile_information`` of ``<bag_dir>/metadata.yaml``, or None if there is none."""
    path = Path(bag_dir) / "metadata.yaml"
    if not path.is_file():
        return None
    try:
        doc = load_yaml(path, "metadata.yaml")   # bounded: size, no aliases, nodes, depth (mwip_ros.yamlio)
    except YamlRefused as exc:
        raise BagError(f"{path} refused: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise BagError(f"{path} is not valid YAML: {bounded(str(exc))}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BagError(f"cannot read {path}: {exc}") from None
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise BagError(f"{path} has no 'rosbag2_bagfile_information' mapping")
    return info


def mcap_files(bag: PathLike) -> List[Path]:
    """The MCAP files of a bag directory in recording order (or ``[bag]`` for an .mcap file)."""
    bag = Path(bag)
    if bag.is_file():
        return [bag]
    if not bag.is_dir():
        raise BagError(f"no such bag: {bag}")
    info = read_metadata(bag)
    if info and info.get("relative_file_paths"):
        files = [bag / Path(p).name for p in info["relative_file_paths"]]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise BagError(f"bag {bag}: files listed in metadata.yaml are missing: {', '.join(missing)}")
        return files
    files = sorted(bag.glob("*.mcap"), key=_file_index)
    if not files:
        raise BagError(f"bag {bag} has no .mcap file")
    return files


def _cut_short(path: Path, exc: Exception) -> BagError:
    return BagError(f"cannot read {path}: {exc} (a recording cut short? try mwip_bag_repair)")


def damaged_chunks(path: Path) -> List[int]:
    """Byte offsets of the chunks of one MCAP file whose data fails its CRC (or does not decompress).

    Needs the file's summary (its chunk index); raises BagError for a file without one."""
    summary = _summary(path)
    if summary is None:
        raise _cut_short(path, "no summary")
    bad = []
    with _open(path) as fh:
        for index in summary.chunk_indexes:
            try:
                fh.seek(index.chunk_start_offset + 9)  # opcode (1) and record length (8)
                breakup_chunk(Chunk.read(ReadDataStream(fh)), validate_crc=True)
            except Exception:  # bad CRC, bad compression, bad framing: the data is not what was written
                bad.append(index.chunk_start_offset)
    return bad


def check(bag: PathLike) -> None:
    """Raise BagError naming the file and byte offset of the first damaged chunk of ``bag``, if any."""
    for path in mcap_files(bag):
        bad = damaged_chunks(path)
        if bad:
            raise _damaged(path, bad)


def _damaged(path: Path, bad: List[int]) -> BagError:
    where = ", ".join(str(b) for b in bad[:5]) + (" ..." if len(bad) > 5 else "")
    return BagError(f"{path}: {len(bad)} damaged chunk(s) (CRC mismatch) at byte {where}; the data in them is "
                    f"not what was recorded (mwip_bag_repair {path.parent} keeps every other chunk)")


def _file_messages(path: Path, topics: Optional[List[str]],
                   log_time_order: bool = True) -> Iterator[Tuple[int, str, bytes]]:
    """One file's ``(log_time_ns, topic, cdr_bytes)``, chunk CRCs checked, in log-time order or (False) in
    the order they were written; a damaged or cut file raises BagError naming it."""
    with _open(path) as fh:
        try:
            reader = make_reader(fh, validate_crcs=True)
            for _schema, channel, message in reader.iter_messages(topics=topics, log_time_order=log_time_order):
                yield message.log_time, channel.topic, bytes(message.data)
        except _UNREADABLE as exc:
            try:
                bad = damaged_chunks(path)
            except BagError:
                bad = []
            raise (_damaged(path, bad) if bad else _cut_short(path, exc)) from None


def raw_messages(bag: PathLike, topics: Optional[Iterable[str]] = None) -> Iterator[Tuple[int, str, bytes]]:
    """``(log_time_ns, topic, cdr_bytes)`` of every message in log-time order: the exact recorded bytes.

    ``topics`` limits the output to those topic names; the files of a split bag are merged."""
    wanted = None if topics is None else list(topics)
    streams = [_file_messages(path, wanted) for path in mcap_files(bag)]
    yield from streams[0] if len(streams) == 1 else heapq.merge(*streams, key=lambda m: m[0])


def _open(path: Path):
    """An MCAP file opened for reading: a regular file (mwip_ros.yamlio.open_regular), else BagError naming it."""
    try:
        return open_regular(path, "MCAP file")
    except OSError as exc:
        raise BagError(f"cannot read {path}: {exc.strerror or exc}") from None


def _summary(path: Path):
    """The file's MCAP summary, or None when it has none (or it cannot be read)."""
    with _open(path) as fh:
        try:
            return make_reader(fh).get_summary()
        except _UNREADABLE:
            return None


def topic_counts(bag: PathLike) -> Dict[str, int]:
    """Messages per topic (topics without messages included when the bag lists them)."""
    counts: Dict[str, int] = {}
    for path in mcap_files(bag):
        summary = _summary(path)
        if summary is not None and summary.statistics is not None:
            for cid, channel in summary.channels.items():
                counts[channel.topic] = counts.get(channel.topic, 0) + \
                    summary.statistics.channel_message_counts.get(cid, 0)
            continue
        with _open(path) as fh:  # no summary: count by scanning
            try:
                for _schema, channel, _message in make_reader(fh).iter_messages(log_time_order=False):
                    counts[channel.topic] = counts.get(channel.topic, 0) + 1
            except _UNREADABLE as exc:
                raise _cut_short(path, exc) from None
    return counts


def _channels(bag: PathLike):
    """(summary, channel) for every channel of every MCAP file of ``bag``, from the files' summaries."""
    for path in mcap_files(bag):
        summary = _summary(path)
        if summary is None:
            raise BagError(f"{path} has no summary (a recording cut short? try mwip_bag_repair)")
        for channel in summary.channels.values():
            yield summary, channel


def topic_qos(bag: PathLike) -> Dict[str, list]:
    """Topic -> the recorded publishers' QoS profiles (v9 dicts; the channels' ``offered_qos_profiles``)."""
    from .metadata import parse_qos_yaml
    out: Dict[str, list] = {}
    for _summary_, channel in _channels(bag):
        out.setdefault(channel.topic, []).extend(parse_qos_yaml(channel.metadata.get("offered_qos_profiles")))
    return out


def topic_types(bag: PathLike) -> Dict[str, str]:
    """Topic -> message type name, from the MCAP channels and schemas."""
    types: Dict[str, str] = {}
    for summary, channel in _channels(bag):
        schema = summary.schemas.get(channel.schema_id)
        types[channel.topic] = schema.name if schema else ""
    return types
