"""Repair a bag whose recording was cut short (``kill -9``, power loss, a full disk).

Such an MCAP file has no summary and no footer, and may end inside a chunk.  ``repair``
reads its records in order, keeps the schemas, channels, metadata, attachments and
messages of every complete record (each chunk whose bytes are all there and whose CRC,
when it has one, checks out), writes a new complete MCAP file in its place (the original
is kept beside it as ``<name>.mcap.broken``) and rebuilds ``metadata.yaml`` from what
was saved (creating it when the recorder died before writing it; each topic's QoS and
type hash come from the channel metadata).

Command line::

    mwip_bag_repair BAG_DIR_OR_MCAP [--dry-run]

Exit codes: 0 repaired (or nothing to repair), 1 nothing could be recovered, 2 usage error.
"""
from __future__ import annotations

import argparse
import mmap
import os
import struct
import sys
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

import yaml
from mcap.data_stream import ReadDataStream
from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer

from .reader import mcap_files, read_metadata
from .schema import BagError
from .writer import (
    DEFAULT_CHUNK_SIZE, ROS_DISTRO, FileInfo, TopicInfo, _FileSink, bag_metadata, dump_yaml, parse_qos_yaml,
    write_metadata_yaml,
)

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_METADATA, OP_ATTACHMENT, OP_DATA_END = 0x0C, 0x09, 0x0F
KNOWN_OPCODES = set(range(0x01, 0x10))
EXIT_OK, EXIT_NOTHING, EXIT_USAGE = 0, 1, 2


@dataclass
class FileRepair:
    """What happened to one MCAP file."""

    path: Path
    was_complete: bool = False
    repaired: bool = False
    backup: Optional[Path] = None
    messages_saved: int = 0
    topic_counts: Dict[str, int] = field(default_factory=dict)
    bytes_discarded: int = 0
    file_size: int = 0
    chunks_saved: int = 0
    chunks_discarded: int = 0
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
            what = f"{f.path}: cut short ({f.problem}); {verb} {f.messages_saved} messages " \
                   f"from {f.chunks_saved} complete chunk(s), discarded {f.bytes_discarded} of {f.file_size} bytes"
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


# --- scanning ---------------------------------------------------------------------------------

class _Scan:
    """Walk the records of an MCAP file in order, yielding the usable ones.

    After the walk: ``complete`` (footer and closing magic present), ``good_end`` (offset
    after the last usable record), ``problem`` (why the walk stopped early), chunk counts,
    the compression used and the largest chunk.
    """

    def __init__(self, path: Path, buf):
        self.path = path
        self.buf = buf
        self.size = len(buf)
        self.header: Optional[Header] = None
        self.complete = False
        self.data_end = False
        self.good_end = 0
        self.skipped_bytes = 0
        self.problem = ""
        self.chunks_saved = 0
        self.chunks_discarded = 0
        self.compression = ""
        self.max_chunk = 0

    def records(self) -> Iterator[Any]:
        buf, size = self.buf, self.size
        if size < len(MAGIC) or bytes(buf[:len(MAGIC)]) != MAGIC:
            self.problem = "not an MCAP file (no MCAP magic at the start)"
            return
        pos = len(MAGIC)
        self.good_end = pos
        while True:
            if pos + 9 > size:
                self.problem = "ends without a footer" if pos == size else "ends inside a record header"
                return
            opcode = buf[pos]
            (length,) = struct.unpack_from("<Q", buf, pos + 1)
            if opcode not in KNOWN_OPCODES and opcode < 0x80:
                self.problem = f"unknown record opcode 0x{opcode:02x} at byte {pos} (garbage from here on)"
                return
            end = pos + 9 + length
            if end > size:
                self.problem = f"ends inside a {_op_name(opcode)} record at byte {pos}"
                return
            body = bytes(buf[pos + 9:end])
            record_start, pos = pos, end
            if opcode == OP_HEADER:
                if self.header is not None:
                    self.problem = f"a second Header record at byte {record_start}"
                    return
                self.header = Header.read(_stream(body))
            elif self.header is None:
                self.problem = "the first record is not a Header"
                return
            elif opcode == OP_CHUNK:
                try:
                    chunk = Chunk.read(_stream(body))
                    inner = breakup_chunk(chunk, validate_crc=True)
                except Exception:  # damaged: bad CRC, bad compression, bad framing inside
                    self.chunks_discarded += 1
                    self.skipped_bytes += end - record_start
                    continue
                self.chunks_saved += 1
                self.compression = self.compression or chunk.compression
                self.max_chunk = max(self.max_chunk, chunk.uncompressed_size)
                yield from inner
            elif opcode in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_METADATA, OP_ATTACHMENT):
                try:
                    if opcode == OP_SCHEMA:
                        rec = Schema.read(_stream(body))
                    elif opcode == OP_CHANNEL:
                        rec = Channel.read(_stream(body))
                    elif opcode == OP_MESSAGE:
                        rec = Message.read(_stream(body), length)
                    elif opcode == OP_METADATA:
                        rec = Metadata.read(_stream(body))
                    else:
                        rec = Attachment.read(_stream(body))
                except Exception:
                    self.skipped_bytes += end - record_start
                    continue
                yield rec
            elif opcode == OP_DATA_END:
                self.data_end = True
                self.good_end = end
                # The summary section follows; a file is complete when its footer and
                # closing magic are there.
                self.complete = self._has_footer()
                if not self.complete:
                    self.problem = "ends after its data section without a valid footer"
                return
            elif opcode == OP_FOOTER:  # a file without a DataEnd record
                self.good_end = end
                self.complete = bytes(buf[end:end + len(MAGIC)]) == MAGIC
                if not self.complete:
                    self.problem = "footer without the closing magic"
                return
            # Indexes and unknown user records inside the data section: skipped, not lost.
            self.good_end = pos

    def _has_footer(self) -> bool:
        buf, size = self.buf, self.size
        if size < len(MAGIC) * 2 + 9 + 20:
            return False
        if bytes(buf[size - len(MAGIC):]) != MAGIC:
            return False
        footer = size - len(MAGIC) - 29
        return buf[footer] == OP_FOOTER and struct.unpack_from("<Q", buf, footer + 1)[0] == 20

    @property
    def bytes_discarded(self) -> int:
        return (0 if self.complete else self.size - self.good_end) + self.skipped_bytes


def _stream(body: bytes) -> ReadDataStream:
    return ReadDataStream(BytesIO(body))


def _op_name(opcode: int) -> str:
    from mcap.opcode import Opcode
    try:
        return Opcode(opcode).name.title().replace("_", "")
    except ValueError:
        return f"0x{opcode:02x}"


class _Collected:
    """Schemas, channels and per-channel counts/times of the usable records of one file."""

    def __init__(self):
        self.schemas: Dict[int, Schema] = {}
        self.channels: Dict[int, Channel] = {}
        self.counts: Dict[int, int] = {}
        self.file = FileInfo("")
        self.orphans = 0
        self.rosbag2_metadata: Optional[str] = None


def _open_buffer(path: Path):
    fh = open(path, "rb")
    size = os.fstat(fh.fileno()).st_size
    if size == 0:
        fh.close()
        return None, b""
    mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    fh.close()
    return mm, mm


def _walk(path: Path, sink: Optional["_Rewriter"]) -> Tuple[_Scan, _Collected]:
    mm, buf = _open_buffer(path)
    try:
        scan = _Scan(path, buf)
        got = _Collected()
        for rec in scan.records():
            if isinstance(rec, Schema):
                got.schemas.setdefault(rec.id, rec)
                if sink:
                    sink.schema(rec)
            elif isinstance(rec, Channel):
                if rec.id not in got.channels:
                    got.channels[rec.id] = rec
                    got.counts.setdefault(rec.id, 0)
                    if sink:
                        sink.channel(rec)
            elif isinstance(rec, Message):
                if rec.channel_id not in got.channels:
                    got.orphans += 1
                    continue
                got.counts[rec.channel_id] += 1
                got.file.add(rec.log_time)
                if sink:
                    sink.message(rec)
            elif isinstance(rec, Metadata):
                if rec.name == "rosbag2":
                    got.rosbag2_metadata = rec.metadata.get("serialized_metadata")
                elif sink:
                    sink.metadata(rec)
            elif isinstance(rec, Attachment):
                if sink:
                    sink.attachment(rec)
        return scan, got
    finally:
        if mm is not None:
            mm.close()


class _Rewriter:
    """Writes the usable records into a new MCAP file, remapping schema and channel ids."""

    def __init__(self, path: Path, compression: str, chunk_size: int, profile: str, library: str):
        self.path = path
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}.get(compression, CompressionType.NONE)
        self._sink = _FileSink(path)
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
        files = sorted(target.glob("*.mcap"))
    return target, files


def _free_backup_name(path: Path) -> Path:
    candidate = path.with_name(path.name + ".broken")
    n = 1
    while candidate.exists():
        candidate = path.with_name(f"{path.name}.broken.{n}")
        n += 1
    return candidate


def _topics_from(collected: Sequence[_Collected], old: Optional[Dict[str, Any]]) -> List[TopicInfo]:
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
                try:
                    qos = parse_qos_yaml(ch.metadata.get("offered_qos_profiles"))
                except BagError:
                    qos = []
                if not qos and isinstance(prior.get("offered_qos_profiles"), (list, str)):
                    try:
                        prior_qos = prior["offered_qos_profiles"]
                        qos = parse_qos_yaml(prior_qos if isinstance(prior_qos, str) else yaml.safe_dump(prior_qos))
                    except BagError:
                        qos = []
                info = TopicInfo(
                    name=ch.topic,
                    type=schema.name if schema else str(prior.get("type", "")),
                    offered_qos_profiles=qos,
                    type_description_hash=ch.metadata.get("topic_type_hash") or str(
                        prior.get("type_description_hash", "") or ""),
                    message_count=0,
                    serialization_format=ch.message_encoding or "cdr",
                )
                topics[ch.topic] = info
            info.message_count += got.counts.get(cid, 0)
    for name, tm in old_topics.items():  # topics the old metadata knew but no saved chunk has
        if name not in topics:
            try:
                prior_qos = tm.get("offered_qos_profiles") or []
                qos = parse_qos_yaml(prior_qos if isinstance(prior_qos, str) else yaml.safe_dump(prior_qos))
            except BagError:
                qos = []
            topics[name] = TopicInfo(name, str(tm.get("type", "")), qos,
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


def repair(path, dry_run: bool = False) -> RepairResult:
    """Repair the bag directory or MCAP file at ``path``; see the module docstring."""
    target = Path(path)
    if not target.exists():
        raise BagError(f"no such bag directory or MCAP file: {target}")
    bag_dir, files = _bag_dir_for(target)
    result = RepairResult(target=target, bag_dir=bag_dir, dry_run=dry_run)
    if not files:
        raise BagError(f"{target} contains no .mcap file; nothing to repair")
    old = _old_metadata(bag_dir)
    collected: List[_Collected] = []
    file_infos: List[FileInfo] = []

    for mcap_path in files:
        fr = FileRepair(path=mcap_path)
        result.files.append(fr)
        fr.file_size = mcap_path.stat().st_size
        scan, got = _walk(mcap_path, None)
        fr.was_complete = scan.complete
        fr.problem = scan.problem
        fr.chunks_saved, fr.chunks_discarded = scan.chunks_saved, scan.chunks_discarded
        fr.messages_orphaned = got.orphans
        fr.bytes_discarded = scan.bytes_discarded
        fr.messages_saved = sum(got.counts.values())
        fr.topic_counts = {}
        for cid, n in got.counts.items():
            topic = got.channels[cid].topic
            fr.topic_counts[topic] = fr.topic_counts.get(topic, 0) + n
        if scan.header is None:
            fr.error = f"nothing could be recovered: {scan.problem or 'no MCAP header'}"
            fr.topic_counts, fr.messages_saved = {}, 0
            continue
        if not scan.complete and fr.messages_saved == 0:
            fr.error = (f"nothing could be recovered: {scan.problem}; no complete chunk "
                        f"({fr.file_size} bytes); left unchanged")
            continue
        collected.append(got)
        info = got.file
        info.path = mcap_path.name
        file_infos.append(info)
        if scan.complete or dry_run:
            continue
        # Rewrite into a temporary file beside the original, then swap.
        tmp = mcap_path.with_name(f".{mcap_path.name}.repair.{os.getpid()}.tmp")
        library = (scan.header.library or "unknown") + " + mwip_bag_repair"
        chunk_size = max(scan.max_chunk, 1024) if scan.max_chunk else DEFAULT_CHUNK_SIZE
        rewriter = _Rewriter(tmp, scan.compression, chunk_size, scan.header.profile, library)
        try:
            _walk(mcap_path, rewriter)
            topics = _topics_from([got], old)
            rewriter.finish(bag_metadata(topics, [info], ros_distro=_distro(old)))
        except BaseException:
            rewriter.abort()
            raise
        backup = _free_backup_name(mcap_path)
        os.replace(mcap_path, backup)
        os.replace(tmp, mcap_path)
        fr.backup = backup
        fr.repaired = True

    if not collected:
        return result
    if bag_dir is not None and not dry_run and (result.needed_repair or old is None):
        topics = _topics_from(collected, old)
        info = bag_metadata(
            topics, file_infos,
            compression_format=str((old or {}).get("compression_format", "") or ""),
            compression_mode=str((old or {}).get("compression_mode", "") or ""),
            custom_data=(old or {}).get("custom_data") or None,
            ros_distro=_distro(old))
        result.metadata_path = write_metadata_yaml(bag_dir, info)
        result.metadata_written = True
    return result


def _distro(old: Optional[Dict[str, Any]]) -> str:
    return str((old or {}).get("ros_distro") or ROS_DISTRO)


# --- command line -----------------------------------------------------------------------------

def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mwip_bag_repair",
        description="Recover the messages of a rosbag2 MCAP bag whose recording was cut short "
                    "(e.g. by kill -9): keeps every complete chunk, writes a complete MCAP file "
                    "(the original is kept as <name>.mcap.broken) and rebuilds metadata.yaml.",
        epilog="Exit codes: 0 repaired or nothing to repair, 1 nothing could be recovered, 2 usage error.")
    parser.add_argument("path", metavar="BAG_DIR_OR_MCAP", help="bag directory or .mcap file")
    parser.add_argument("--dry-run", action="store_true", help="report what would be saved; change nothing")
    args = parser.parse_args(argv)
    target = Path(args.path)
    if not target.exists():
        print(f"mwip_bag_repair: error: no such bag directory or MCAP file: {target}", file=sys.stderr)
        return EXIT_USAGE
    if target.is_file() and target.suffix != ".mcap":
        print(f"mwip_bag_repair: error: {target} is not an .mcap file (give a bag directory or an .mcap file)",
              file=sys.stderr)
        return EXIT_USAGE
    try:
        result = repair(target, dry_run=args.dry_run)
    except BagError as exc:
        print(f"mwip_bag_repair: error: {exc}", file=sys.stderr)
        return EXIT_NOTHING
    except OSError as exc:
        print(f"mwip_bag_repair: error: {exc}", file=sys.stderr)
        return EXIT_NOTHING
    print(result.report(), flush=True)
    if not result.ok:
        return EXIT_NOTHING
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
