"""Repair a bag whose recording was cut short (``kill -9``, power loss, a full disk).

Such an MCAP file has no summary and no footer, and may end inside a chunk.  :func:`repair`
walks its records with :mod:`.scan` (the ``mcap`` library's stream reader, bounded and
resumable), keeps the schemas, channels, metadata, attachments and messages of every
complete record (each chunk whose bytes are all there and whose CRC, when it has one,
checks out; a damaged chunk in the middle is skipped and the walk goes on; of the chunk
the file ends inside, every record that is complete and passes the structural checks of
:func:`.scan.cut_chunk_records`), writes a new complete MCAP file in its place (the
original is kept beside it as ``<name>.mcap.broken``) and rebuilds ``metadata.yaml`` from
what was saved (creating it when the recorder died before writing it; each topic's QoS
and type hash come from the channel metadata, else from the old ``metadata.yaml``), its
``custom_data`` kept and the entry :data:`~.metadata.REPAIRED_KEY` added: one line saying
how many messages were kept, up to which log time, and what was lost (:func:`repaired_note`).

:class:`RepairResult` says what was saved per file and topic; its :meth:`~RepairResult.report`
is what the ``mwip_bag_repair`` command (:mod:`mwip_ros.cli.bag_repair`) prints.

A little over 300 lines: the result and its report, the rewrite and the metadata rebuild
are one job sharing private helpers; the record walk, the part that reads damaged bytes,
is :mod:`.scan`.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import yaml
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from mwip_ros.yamlio import load_yaml

from .errors import BagError
from .metadata import (REPAIRED_KEY, ROS_DISTRO, TopicInfo, bag_metadata, dump_yaml, parse_qos_yaml,
                       write_metadata_yaml)
from .reader import _file_index, mcap_files, read_metadata
from .scan import Collected, walk
from .writer import DEFAULT_CHUNK_SIZE, FileSink

__all__ = ["FileRepair", "RepairResult", "repair", "repaired_note"]


@dataclass
class FileRepair:
    """What happened to one MCAP file."""

    path: Path
    was_complete: bool = False  # complete and undamaged: nothing to repair
    cut_short: bool = False  # no footer (else: complete, with damaged records)
    repaired: bool = False
    backup: Optional[Path] = None
    messages_saved: int = 0
    topic_counts: Dict[str, int] = field(default_factory=dict)
    bytes_discarded: int = 0
    file_size: int = 0
    chunks_saved: int = 0
    chunks_discarded: int = 0
    cut_chunk_messages: int = 0  # messages saved from the chunk the file ends inside
    lost_until_ns: Optional[int] = None  # that chunk's last log time, when messages of it were lost
    start_ns: Optional[int] = None  # log times of the first and last message saved
    end_ns: Optional[int] = None
    messages_orphaned: int = 0
    problem: str = ""
    error: str = ""


@dataclass
class RepairResult:
    """The outcome of :func:`repair`."""

    target: Path
    bag_dir: Optional[Path]
    files: List[FileRepair] = field(default_factory=list)
    metadata_written: bool = False
    metadata_path: Optional[Path] = None
    dry_run: bool = False

    @property
    def topic_counts(self) -> Dict[str, int]:
        out: Dict[str, int] = {}
        for f in self.files:
            for t, n in f.topic_counts.items():
                out[t] = out.get(t, 0) + n
        return out

    @property
    def total_messages(self) -> int:
        return sum(f.messages_saved for f in self.files)

    @property
    def bytes_discarded(self) -> int:
        return sum(f.bytes_discarded for f in self.files)

    @property
    def needed_repair(self) -> bool:
        return any(not f.was_complete for f in self.files)

    @property
    def ok(self) -> bool:
        """False when a file needed repair and nothing could be recovered from it."""
        return not any(f.error for f in self.files)

    def report(self) -> str:
        lines = []
        verb = "would save" if self.dry_run else "saved"
        for f in self.files:
            if f.error:
                lines.append(f"{f.path}: {f.error}")
                continue
            if f.was_complete:
                lines.append(f"{f.path}: complete, {f.messages_saved} messages; nothing to repair")
                continue
            state = "cut short" if f.cut_short else "damaged"
            what = f"{f.path}: {state} ({f.problem}); {verb} {f.messages_saved} messages " \
                   f"from {f.chunks_saved} complete chunk(s)"
            if f.cut_chunk_messages:
                what += f" and {f.cut_chunk_messages} from the chunk it ends inside"
            what += f", discarded {f.bytes_discarded} of {f.file_size} bytes"
            if f.chunks_discarded:
                what += f" ({f.chunks_discarded} damaged chunk(s))"
            if f.messages_orphaned:
                what += f", {f.messages_orphaned} message(s) of unknown channels dropped"
            lines.append(what)
            if f.backup is not None:
                lines.append(f"  original kept as {f.backup}")
        counts = self.topic_counts
        width = max((len(t) for t in counts), default=0)
        for topic in sorted(counts):
            lines.append(f"  {topic:<{width}}  {counts[topic]}")
        lines.append(f"total: {self.total_messages} messages {verb}, {self.bytes_discarded} bytes discarded")
        if self.metadata_written:
            lines.append(f"wrote {self.metadata_path}")
        elif self.dry_run and self.bag_dir is not None and self.needed_repair:
            lines.append(f"would rewrite {self.bag_dir / 'metadata.yaml'}")
        return "\n".join(lines)


class _Rewriter:
    """Writes the usable records into a new MCAP file, remapping schema and channel ids."""

    def __init__(self, path: Path, compression: str, chunk_size: int, profile: str, library: str):
        self.path = path
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(compression, CompressionType.NONE)
        self._sink = FileSink(path)
        self._writer = Writer(self._sink, chunk_size=chunk_size, compression=comp)
        self._writer.start(profile=profile, library=library)
        self._schema_ids: Dict[int, int] = {0: 0}
        self._channel_ids: Dict[int, int] = {}

    def schema(self, rec: Schema) -> None:
        if rec.id not in self._schema_ids:
            self._schema_ids[rec.id] = self._writer.register_schema(rec.name, rec.encoding, rec.data)

    def channel(self, rec: Channel) -> None:
        if rec.id in self._channel_ids:
            return
        schema_id = self._schema_ids.get(rec.schema_id)
        if schema_id is None:  # schema lost: keep the channel, schemaless
            schema_id = 0
        self._channel_ids[rec.id] = self._writer.register_channel(
            rec.topic, rec.message_encoding, schema_id, dict(rec.metadata))

    def message(self, rec: Message) -> None:
        self._writer.add_message(self._channel_ids[rec.channel_id], rec.log_time, rec.data, rec.publish_time,
                                 rec.sequence)

    def metadata(self, rec: Metadata) -> None:
        self._writer.add_metadata(rec.name, dict(rec.metadata))

    def attachment(self, rec: Attachment) -> None:
        self._writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)

    def finish(self, bag_info: Optional[Dict[str, Any]]) -> None:
        try:
            if bag_info is not None:
                self._writer.add_metadata("rosbag2", {"serialized_metadata": dump_yaml(bag_info)})
            self._writer.finish()
        finally:
            self._sink.close()

    def abort(self) -> None:
        self._sink.close(sync=False)
        try:
            self.path.unlink()
        except OSError:
            pass


# --- bag level --------------------------------------------------------------------------------

def _bag_dir_for(target: Path) -> Tuple[Optional[Path], List[Path]]:
    """(bag directory or None, MCAP files to look at) for a bag dir or an .mcap path.

    An .mcap file inside a bag directory stands for the whole bag (so the rebuilt
    metadata.yaml still lists every file)."""
    if target.is_file():
        parent = target.parent
        in_bag = (parent / "metadata.yaml").is_file() or target.name.startswith(parent.name + "_")
        if not in_bag:
            return None, [target]
        target = parent
    try:
        files = mcap_files(target)
    except BagError:
        files = sorted(target.glob("*.mcap"), key=_file_index)
    return target, files


def _free_backup_name(path: Path) -> Path:
    candidate = path.with_name(path.name + ".broken")
    n = 1
    while candidate.exists():
        candidate = path.with_name(f"{path.name}.broken.{n}")
        n += 1
    return candidate


def _qos(value: Any) -> List[Dict[str, Any]]:
    """QoS profiles from channel metadata or an old metadata.yaml entry; [] when unusable."""
    try:
        return parse_qos_yaml(value)
    except BagError:
        return []


def _topics_from(collected: Sequence[Collected], old: Optional[Dict[str, Any]]) -> List[TopicInfo]:
    """The topics of the saved channels (QoS, type hash: channel metadata first, then the old
    metadata.yaml), then the topics only the old metadata.yaml knew, with no messages."""
    old_topics: Dict[str, Dict[str, Any]] = {}
    for entry in (old or {}).get("topics_with_message_count") or []:
        tm = (entry or {}).get("topic_metadata") or {}
        if tm.get("name"):
            old_topics[tm["name"]] = tm
    topics: Dict[str, TopicInfo] = {}
    for got in collected:
        for cid, ch in got.channels.items():
            info = topics.get(ch.topic)
            if info is None:
                schema = got.schemas.get(ch.schema_id)
                prior = old_topics.get(ch.topic, {})
                info = topics[ch.topic] = TopicInfo(
                    name=ch.topic,
                    type=schema.name if schema else str(prior.get("type", "")),
                    offered_qos_profiles=_qos(ch.metadata.get("offered_qos_profiles"))
                    or _qos(prior.get("offered_qos_profiles")),
                    type_description_hash=ch.metadata.get("topic_type_hash") or str(
                        prior.get("type_description_hash", "") or ""),
                    message_count=0,
                    serialization_format=ch.message_encoding or "cdr",
                )
            info.message_count += got.counts.get(cid, 0)
    for name, tm in old_topics.items():  # topics the old metadata knew but no saved chunk has
        if name not in topics:
            topics[name] = TopicInfo(name, str(tm.get("type", "")), _qos(tm.get("offered_qos_profiles")),
                                     str(tm.get("type_description_hash", "") or ""), 0,
                                     str(tm.get("serialization_format", "cdr") or "cdr"))
    return list(topics.values())


def _old_metadata(bag_dir: Optional[Path]) -> Optional[Dict[str, Any]]:
    if bag_dir is None:
        return None
    try:
        return read_metadata(bag_dir)
    except BagError:
        return None


def _distro(old: Optional[Dict[str, Any]]) -> str:
    return str((old or {}).get("ros_distro") or ROS_DISTRO)


def _repair_file(mcap_path: Path, old: Optional[Dict[str, Any]], dry_run: bool
                 ) -> Tuple[FileRepair, Optional[Collected]]:
    """Scan one file and, unless it is complete or this is a dry run, rewrite it.

    Returns what happened and the collected records (None when nothing could be saved)."""
    fr = FileRepair(path=mcap_path, file_size=mcap_path.stat().st_size)
    scan, got = walk(mcap_path)
    fr.was_complete, fr.cut_short, fr.problem = scan.intact, not scan.complete, scan.problem
    fr.chunks_saved, fr.chunks_discarded = scan.chunks_saved, scan.chunks_discarded
    fr.messages_orphaned = got.orphans
    fr.start_ns, fr.end_ns = got.file.start_ns, got.file.end_ns
    cut = scan.cut_chunk
    if cut is not None:
        fr.cut_chunk_messages = sum(1 for r in cut.records if isinstance(r, Message))
        if cut.end_time and (fr.end_ns is None or cut.end_time > fr.end_ns):
            fr.lost_until_ns = cut.end_time
    fr.bytes_discarded = scan.bytes_discarded
    if scan.header is None:
        fr.error = f"nothing could be recovered: {scan.problem or 'no MCAP header'}"
        return fr, None
    fr.topic_counts = got.topic_counts()
    fr.messages_saved = sum(fr.topic_counts.values())
    if not scan.intact and fr.messages_saved == 0:
        fr.error = (f"nothing could be recovered: {scan.problem}; no complete message "
                    f"({fr.file_size} bytes); left unchanged")
        return fr, None
    got.file.path = mcap_path.name
    if scan.intact or dry_run:
        return fr, got
    # Rewrite into a temporary file beside the original, then swap.
    tmp = mcap_path.with_name(f".{mcap_path.name}.repair.{os.getpid()}.tmp")
    library = (scan.header.library or "unknown") + " + mwip_bag_repair"
    chunk_size = max(scan.max_chunk, 1024) if scan.max_chunk else DEFAULT_CHUNK_SIZE
    rewriter = _Rewriter(tmp, scan.compression, chunk_size, scan.header.profile, library)
    try:
        walk(mcap_path, rewriter)
        rewriter.finish(bag_metadata(_topics_from([got], old), [got.file], ros_distro=_distro(old)))
    except BaseException:
        rewriter.abort()
        raise
    fr.backup = _free_backup_name(mcap_path)
    os.replace(mcap_path, fr.backup)
    os.replace(tmp, mcap_path)
    fr.repaired = True
    return fr, got


def _custom_data(old: Optional[Dict[str, Any]], collected: Sequence[Collected]) -> Dict[str, str]:
    """The ``custom_data`` to keep: the old metadata.yaml's, else that of the ``rosbag2``
    Metadata record in a file (what the recorder wrote at its start)."""
    if old is not None:
        return {str(k): str(v) for k, v in (old.get("custom_data") or {}).items()}
    for got in collected:
        try:
            doc = load_yaml(got.rosbag2_metadata or "", "rosbag2 metadata") or {}   # bounded (mwip_ros.yamlio)
            doc = doc.get("rosbag2_bagfile_information", doc)
            return {str(k): str(v) for k, v in (doc.get("custom_data") or {}).items()}
        except (yaml.YAMLError, AttributeError):
            continue
    return {}


def repaired_note(result: RepairResult) -> str:
    """The one line :func:`repair` stores under ``custom_data[REPAIRED_KEY]``: that the bag was
    repaired, how many messages were kept up to which log time (seconds from the first saved
    message), and what was lost where known, e.g. ``repaired after a cut: 1234 messages kept up
    to log time 7.215 s (from the bag's start); the 5120 bytes after that were incomplete
    (messages up to log time 7.480 s lost)``."""
    saved = [f for f in result.files if not f.error and f.start_ns is not None]
    start = min((f.start_ns for f in saved), default=None)
    end = max((f.end_ns for f in saved), default=None)
    broken = [f for f in result.files if not f.was_complete]
    cut = [f for f in broken if f.cut_short]
    kept = f"{result.total_messages} messages kept"
    if start is not None:
        kept += f" up to log time {(end - start) / 1e9:.3f} s (from the bag's start)"
    lost = []
    cut_bytes = sum(f.bytes_discarded for f in cut if not f.error)
    if cut:
        text = f"the {cut_bytes} bytes after that were incomplete" if cut_bytes else \
            "the file ends there, without its summary and footer"
        until = max((f.lost_until_ns for f in cut if f.lost_until_ns is not None), default=None)
        if until is not None and start is not None:
            text += f" (messages up to log time {(until - start) / 1e9:.3f} s lost)"
        lost.append(text)
    damaged = sum(f.chunks_discarded for f in broken)
    if damaged:
        lost.append(f"{damaged} damaged chunk(s) skipped")
    orphans = sum(f.messages_orphaned for f in broken)
    if orphans:
        lost.append(f"{orphans} message(s) of unknown channels dropped")
    unreadable = [f.path.name for f in result.files if f.error]
    if unreadable:
        lost.append("nothing recovered from " + ", ".join(unreadable))
    other = sum(f.bytes_discarded for f in broken if not f.cut_short)
    if not lost and other:
        lost.append(f"{other} damaged bytes skipped")
    how = "after a cut" if cut else "after damage"
    return f"repaired {how}: {kept}" + ("; " + "; ".join(lost) if lost else "")


def repair(path, dry_run: bool = False) -> RepairResult:
    """Repair the bag directory or MCAP file at ``path``; see the module docstring.

    Raises BagError when ``path`` does not exist or holds no ``.mcap`` file."""
    target = Path(path)
    if not target.exists():
        raise BagError(f"no such bag directory or MCAP file: {target}")
    bag_dir, files = _bag_dir_for(target)
    result = RepairResult(target=target, bag_dir=bag_dir, dry_run=dry_run)
    if not files:
        raise BagError(f"{target} contains no .mcap file; nothing to repair")
    old = _old_metadata(bag_dir)
    collected: List[Collected] = []
    for mcap_path in files:
        fr, got = _repair_file(mcap_path, old, dry_run)
        result.files.append(fr)
        if got is not None:
            collected.append(got)
    if not collected:
        return result
    if bag_dir is not None and not dry_run and (result.needed_repair or old is None):
        custom = _custom_data(old, collected)
        if result.needed_repair:
            custom[REPAIRED_KEY] = repaired_note(result)
        info = bag_metadata(
            _topics_from(collected, old), [got.file for got in collected],
            compression_format=str((old or {}).get("compression_format", "") or ""),
            compression_mode=str((old or {}).get("compression_mode", "") or ""),
            custom_data=custom or None,
            ros_distro=_distro(old))
        result.metadata_path = write_metadata_yaml(bag_dir, info)
        result.metadata_written = True
    return result
