"""Read rosbag2 MCAP bags without rclpy (mcap + mcap_ros2's CDR decoder).

``read_messages(bag)`` yields ``(topic, type_name, log_time_ns, msg)`` in log-time order,
where ``msg`` is a decoded message object with attribute access (``msg.position``,
``msg.header.stamp.sec``); ``topic_counts(bag)`` gives the messages per topic.  ``bag``
is a bag directory (its ``metadata.yaml`` lists the files; without one every ``*.mcap``
in it is read) or a single ``.mcap`` file.
"""
from __future__ import annotations

import heapq
import re
import struct
from contextlib import ExitStack
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple, Union

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader

from .schema import BagError

PathLike = Union[str, Path]


def _file_index(path: Path) -> Tuple[int, str]:
    m = re.search(r"_(\d+)\.mcap$", path.name)
    return (int(m.group(1)) if m else 0, path.name)


def read_metadata(bag_dir: PathLike) -> Optional[Dict[str, Any]]:
    """The ``rosbag2_bagfile_information`` of ``<bag_dir>/metadata.yaml``, or None if there is none."""
    path = Path(bag_dir) / "metadata.yaml"
    if not path.is_file():
        return None
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise BagError(f"{path} is not valid YAML: {exc}") from None
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


def _merged(bag: PathLike, per_file) -> Iterator:
    """Merge per-file streams of ``(log_time, ...)`` tuples into one log-time ordered stream."""
    with ExitStack() as stack:
        streams = [per_file(f, stack) for f in mcap_files(bag)]
        yield from streams[0] if len(streams) == 1 else heapq.merge(*streams, key=lambda x: x[0])


def _cut_short(path: Path, exc: Exception) -> BagError:
    return BagError(f"cannot read {path}: {exc} (a recording cut short? try mwip_bag_repair)")


def read_messages(bag_dir: PathLike, topics: Optional[Iterable[str]] = None
                  ) -> Iterator[Tuple[str, str, int, Any]]:
    """Yield ``(topic, type_name, log_time_ns, message)`` for every message, in log-time order."""
    from mcap_ros2.decoder import DecoderFactory

    wanted = None if topics is None else list(topics)

    def decoded(path: Path, stack: ExitStack):
        reader = make_reader(stack.enter_context(open(path, "rb")), decoder_factories=[DecoderFactory()])
        try:
            for schema, channel, message, msg in reader.iter_decoded_messages(topics=wanted, log_time_order=True):
                yield message.log_time, channel.topic, schema.name if schema else "", msg
        except McapError as exc:
            raise _cut_short(path, exc) from None

    for log_time, topic, type_name, msg in _merged(bag_dir, decoded):
        yield topic, type_name, log_time, msg


def raw_messages(bag: PathLike, topics: Optional[Iterable[str]] = None) -> Iterator[Tuple[int, str, bytes]]:
    """``(log_time_ns, topic, cdr_bytes)`` of every message in log-time order: the exact recorded bytes."""
    wanted = None if topics is None else list(topics)

    def raw(path: Path, stack: ExitStack):
        reader = make_reader(stack.enter_context(open(path, "rb")))
        try:
            for _schema, channel, message in reader.iter_messages(topics=wanted, log_time_order=True):
                yield message.log_time, channel.topic, bytes(message.data)
        except McapError as exc:
            raise _cut_short(path, exc) from None

    yield from _merged(bag, raw)


def topic_counts(bag_dir: PathLike) -> Dict[str, int]:
    """Messages per topic (topics without messages included when the bag lists them)."""
    counts: Dict[str, int] = {}
    for path in mcap_files(bag_dir):
        with open(path, "rb") as fh:
            try:
                summary = make_reader(fh).get_summary()
            except (McapError, struct.error, EOFError, ValueError):
                summary = None
            if summary is not None and summary.statistics is not None:
                for cid, channel in summary.channels.items():
                    counts[channel.topic] = counts.get(channel.topic, 0) + \
                        summary.statistics.channel_message_counts.get(cid, 0)
                continue
        # No summary: count by scanning.
        with open(path, "rb") as fh:
            try:
                for _schema, channel, _message in make_reader(fh).iter_messages(log_time_order=False):
                    counts[channel.topic] = counts.get(channel.topic, 0) + 1
            except (McapError, struct.error, EOFError) as exc:
                raise BagError(f"cannot read {path}: {exc} (a recording cut short? try mwip_bag_repair)") \
                    from None
    return counts


def topic_types(bag_dir: PathLike) -> Dict[str, str]:
    """Topic -> message type name, from the MCAP channels and schemas."""
    types: Dict[str, str] = {}
    for path in mcap_files(bag_dir):
        with open(path, "rb") as fh:
            try:
                summary = make_reader(fh).get_summary()
            except (McapError, struct.error, EOFError, ValueError) as exc:
                raise BagError(f"cannot read {path}: {exc}") from None
        if summary is None:
            raise BagError(f"{path} has no summary (a recording cut short? try mwip_bag_repair)")
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            types[channel.topic] = schema.name if schema else ""
    return types


__all__ = ["mcap_files", "read_messages", "read_metadata", "topic_counts", "topic_types"]
