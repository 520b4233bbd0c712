"""Walk an MCAP file that may be cut short or damaged, keeping every usable record.

The walk is the ``mcap`` library's own :class:`~mcap.stream_reader.StreamReader` (record
framing, every record type, padding, the closing magic after the footer) with chunks
emitted whole and opened by :func:`~mcap.stream_reader.breakup_chunk` (decompression,
CRC check, the records inside).  Around it, :class:`Scan` adds what a damaged file needs
and the library leaves to its caller:

* **bounds**: the file is handed to the reader through :class:`_Source`, which refuses a
  read past the end of the file (a record cut short: the walk stops there) or past the
  end of the record being read (a damaged length field inside it: that record is
  skipped), instead of returning the short read the library would parse as data;
* **resumption**: a damaged chunk (bad CRC, bad compression) is skipped and the walk goes
  on; so is any other record that cannot be parsed, by starting a new reader right after
  it, since its length in the record header is still good;
* **garbage**: an unknown opcode below 0x80 (the MCAP range reserved for the format
  itself) means the rest is not MCAP, e.g. the zeros a file system leaves after a crash;
  the library would skip it as a user record and walk on through the garbage;
* **the cut chunk**: a file that ends inside a Chunk record still holds that chunk's
  header and the start of its records.  :func:`cut_chunk_records` decodes them (an
  uncompressed chunk as it is; zstd and lz4 by streaming decompression, which gives the
  bytes of every complete block) up to the last complete record.  There is no usable CRC,
  so each record is checked by its structure instead and decoding stops at the first
  that fails: Schema, Channel or Message opcodes only, a length inside the bytes there
  are, fields that parse within that length, a Message of a channel already defined whose
  log time lies in the chunk header's time range.  Trailing zero bytes are not trusted
  (what a file system leaves after a crash).

:class:`_Walker` learns each record's byte offsets by overriding the reader's private
``_read_record`` hook; the reader keeps its public ``records`` loop.  :func:`walk` feeds the
usable records of a file to an optional sink (the repair's rewriter) and collects their
schemas, channels and per-channel message counts.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Set, Tuple

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import MAGIC_SIZE, StreamReader, breakup_chunk, read_magic

from mwip_ros.yamlio import open_regular

from .metadata import FileInfo

try:
    import zstandard
except ImportError:  # pragma: no cover - a requirement, but optional to the mcap library too
    zstandard = None
try:
    import lz4.frame as lz4_frame
except ImportError:  # pragma: no cover
    lz4_frame = None

__all__ = ["Collected", "CutChunk", "Scan", "cut_chunk_records", "walk"]

_KNOWN_OPCODES = frozenset(int(op) for op in Opcode)
_USABLE = (Schema, Channel, Message, Metadata, Attachment)


class _Truncated(Exception):
    """The file ends before the record being read does."""


class _Overrun(ValueError):
    """A field runs past the end of its record (a damaged length inside the record)."""


class _Garbage(ValueError):
    """An opcode no MCAP writer uses: the bytes from here on are not MCAP records."""


class _Source:
    """The file as the reader sees it: a read past the end of the file, or past ``limit``
    (the end of the record being read, when set), raises instead of coming back short."""

    def __init__(self, fh, size: int, pos: int):
        fh.seek(pos)
        self._fh = fh
        self.size = size
        self.pos = pos
        self.limit: Optional[int] = None

    def read(self, n: int) -> bytes:
        if self.pos + n > (self.size if self.limit is None else self.limit):
            raise _Truncated() if self.limit is None else _Overrun()
        data = self._fh.read(n)
        self.pos += len(data)
        return data


class _Walker(StreamReader):
    """StreamReader that records where each record starts and ends, and bounds its reads.

    ``start``/``end``/``opcode`` describe the record being (or last) read; ``parsed_to`` is
    the end of the last record read whole."""

    def __init__(self, source: _Source):
        super().__init__(source, skip_magic=True, emit_chunks=True, validate_crcs=False, record_size_limit=None)
        self.source = source
        self.start = self.end = self.parsed_to = source.pos
        self.opcode: Optional[int] = None

    def _read_record(self, opcode: int, length: int):
        src = self.source
        self.opcode, self.start, self.end = opcode, src.pos - 9, src.pos + length
        if self.end > src.size:
            raise _Truncated()
        if opcode < 0x80 and opcode not in _KNOWN_OPCODES:
            raise _Garbage()
        src.limit = self.end
        try:
            record = super()._read_record(opcode, length)
        finally:
            src.limit = None
        self.parsed_to = self.end
        return record

    @property
    def in_record(self) -> bool:
        """Whether the last failure happened inside a record (not in a record header)."""
        return self.parsed_to < self.end


def _op_name(opcode: Optional[int]) -> str:
    try:
        return Opcode(opcode).name.title().replace("_", "")
    except ValueError:
        return f"0x{opcode:02x}"


_CHUNK_FIXED = struct.Struct("<QQQII")  # start time, end time, uncompressed size, CRC, compression length
_IN_CHUNK = {int(Opcode.SCHEMA): Schema, int(Opcode.CHANNEL): Channel, int(Opcode.MESSAGE): Message}
_MAX_COMPRESSION_NAME = 64
_PIECE = 4096  # compressed bytes fed to a streaming decompressor at a time


@dataclass
class CutChunk:
    """What :func:`cut_chunk_records` made of a chunk the file ends inside.

    ``records``: the complete records decoded, in order; ``used``: how many bytes of the
    chunk record's body (after its 9-byte opcode and length) they account for (exact for an
    uncompressed chunk, within 4 KiB of compressed data otherwise); ``start_time`` and
    ``end_time``: the chunk header's message time range (0, 0 when the header is cut);
    ``compression``; ``stop``: why decoding stopped."""

    records: List[Any] = field(default_factory=list)
    used: int = 0
    start_time: int = 0
    end_time: int = 0
    compression: str = ""
    stop: str = ""


def _decompress_prefix(compression: str, data: bytes) -> Tuple[bytes, List[Tuple[int, int]]]:
    """The uncompressed bytes a prefix of a compressed chunk gives, and [(input bytes fed,
    output bytes so far)] after each piece (to map output positions back to input).

    Raises ValueError for a compression it cannot stream."""
    if compression == "":
        return data, [(len(data), len(data))]
    if compression == "zstd" and zstandard is not None:
        dec = zstandard.ZstdDecompressor().decompressobj()
    elif compression == "lz4" and lz4_frame is not None:
        dec = lz4_frame.LZ4FrameDecompressor()
    else:
        raise ValueError(f"cannot decode a cut chunk compressed with {compression!r}")
    out, marks = bytearray(), []
    for at in range(0, len(data), _PIECE):
        try:
            out += dec.decompress(data[at:at + _PIECE])
        except Exception:  # corrupt from here on: keep what came before
            break
        marks.append((min(at + _PIECE, len(data)), len(out)))
        if getattr(dec, "eof", False):
            break
    return bytes(out), marks


def cut_chunk_records(body: bytes, channels: Set[int]) -> CutChunk:
    """Decode the complete records of a chunk cut short; see the module docstring.

    ``body``: the bytes of the Chunk record there are, after its opcode and length;
    ``channels``: the channel ids defined before this chunk (a Channel record decoded here
    is added for the Messages after it).  Never raises for bad data: it stops instead."""
    cut = CutChunk()
    if len(body) < _CHUNK_FIXED.size:
        cut.stop = "the chunk header is cut"
        return cut
    start, end, size, _crc, name_len = _CHUNK_FIXED.unpack_from(body, 0)
    head = _CHUNK_FIXED.size + name_len + 8
    if name_len > _MAX_COMPRESSION_NAME or len(body) < head or start > end:
        cut.stop = "the chunk header is cut or damaged"
        return cut
    try:
        cut.compression = body[_CHUNK_FIXED.size:head - 8].decode("utf-8")
    except UnicodeDecodeError:
        cut.stop = "the chunk header is damaged"
        return cut
    cut.start_time, cut.end_time = start, end
    (data_len,) = struct.unpack_from("<Q", body, head - 8)
    data = body[head:head + data_len].rstrip(b"\0")  # zeros at the end: not trusted
    try:
        plain, marks = _decompress_prefix(cut.compression, data)
    except ValueError as exc:
        cut.stop = str(exc)
        return cut
    plain = plain[:size]
    known = set(channels)
    pos = 0
    while True:
        if pos + 9 > len(plain):
            cut.stop = "the next record is incomplete"
            break
        opcode, length = struct.unpack_from("<BQ", plain, pos)
        kind = _IN_CHUNK.get(opcode)
        if kind is None:
            cut.stop = f"opcode 0x{opcode:02x} cannot be in a chunk"
            break
        if pos + 9 + length > len(plain):
            cut.stop = "the next record is incomplete"
            break
        try:
            record = _parse_in_chunk(kind, plain[pos + 9:pos + 9 + length], length)
        except Exception:
            cut.stop = f"a {kind.__name__} record does not parse"
            break
        if isinstance(record, Message) and (record.channel_id not in known
                                            or not start <= record.log_time <= end):
            cut.stop = "a Message of an unknown channel or outside the chunk's time range"
            break
        if isinstance(record, Channel):
            known.add(record.id)
        cut.records.append(record)
        pos += 9 + length
    if pos:  # the input it took to produce the first ``pos`` bytes of output
        cut.used = head + (pos if cut.compression == "" else
                           next((fed for fed, got in marks if got >= pos), len(data)))
    return cut


def _parse_in_chunk(kind, raw: bytes, length: int):
    """One record of a cut chunk, from exactly its ``length`` bytes (a field running past
    them raises)."""
    if kind is Message:
        if length < 22:
            raise ValueError("a Message record shorter than its fixed fields")
        return Message.read(_BoundedStream(raw), length)
    return kind.read(_BoundedStream(raw))


class _BoundedStream(ReadDataStream):
    """A ReadDataStream over ``raw`` whose reads past the end raise instead of coming back short."""

    def __init__(self, raw: bytes):
        super().__init__(BytesIO(raw))
        self._left = len(raw)

    def read(self, length: int) -> bytes:
        if length > self._left:
            raise _Overrun()
        self._left -= length
        return super().read(length)


class Scan:
    """Walk the records of one MCAP file in order, yielding the usable ones (:meth:`records`).

    After the walk: ``header``; ``complete`` (data section, summary, footer and closing magic
    all read) and ``intact`` (complete, and no damaged record skipped); ``good_end`` (every
    byte before it was used or counted in ``skipped_bytes``); ``problem`` (why the walk
    stopped early, or what was damaged); the chunks saved and discarded, the chunk
    compression used and the largest uncompressed chunk; ``cut_chunk`` (a :class:`CutChunk`)
    when the file ends inside a chunk, whose complete records were yielded too.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self.size = self.path.stat().st_size
        self.header: Optional[Header] = None
        self.complete = False
        self.good_end = 0
        self.skipped_bytes = 0
        self.problem = ""
        self.chunks_saved = 0
        self.chunks_discarded = 0
        self.compression = ""
        self.max_chunk = 0
        self.cut_chunk: Optional[CutChunk] = None  # the chunk the file ends inside, when it does
        self._channel_ids: Set[int] = set()

    @property
    def intact(self) -> bool:
        """Complete, and no record of it had to be skipped."""
        return self.complete and not self.skipped_bytes

    @property
    def bytes_discarded(self) -> int:
        return (0 if self.complete else self.size - self.good_end) + self.skipped_bytes

    def records(self) -> Iterator[Any]:
        with open_regular(self.path, "MCAP file") as fh:   # a FIFO or a device is never read
            try:
                read_magic(ReadDataStream(_Source(fh, self.size, 0)))
            except Exception:
                self.problem = "not an MCAP file (no MCAP magic at the start)"
                return
            walker = _Walker(_Source(fh, self.size, MAGIC_SIZE))
            self.good_end = MAGIC_SIZE
            it = walker.records
            after_data = ""  # once the data section has ended: what a failure from then on means
            while True:
                try:
                    record = next(it)
                except StopIteration:
                    self.complete = True
                    if self.skipped_bytes:
                        self.problem = "records in its data section fail their checks"
                    return
                except Exception as exc:
                    if after_data:
                        self.problem = after_data
                        return
                    if not self._skip_damaged(walker, exc):
                        if isinstance(exc, _Truncated) and walker.opcode == Opcode.CHUNK and walker.in_record:
                            yield from self._open_cut_chunk(fh, walker)
                        return
                    walker = _Walker(_Source(fh, self.size, walker.end))
                    it = walker.records
                    continue
                if after_data:  # the summary section repeats what the data section has
                    continue
                if isinstance(record, Header):
                    if self.header is not None:
                        self.problem = f"a second Header record at byte {walker.start}"
                        return
                    self.header = record
                elif self.header is None:
                    self.problem = "the first record is not a Header"
                    return
                elif isinstance(record, DataEnd):
                    after_data = "ends after its data section without a valid footer"
                elif isinstance(record, Footer):  # a file without a DataEnd record
                    after_data = "footer without the closing magic"
                elif isinstance(record, Chunk):
                    yield from self._open_chunk(record, walker)
                elif isinstance(record, _USABLE):
                    if isinstance(record, Channel):
                        self._channel_ids.add(record.id)
                    yield record
                # Indexes and user records inside the data section: skipped, not lost.
                self.good_end = walker.parsed_to

    def _open_chunk(self, chunk: Chunk, walker: _Walker) -> Iterator[Any]:
        try:
            inner = breakup_chunk(chunk, validate_crc=True)
        except Exception:  # damaged: bad CRC, bad compression, bad framing inside
            self.chunks_discarded += 1
            self.skipped_bytes += walker.end - walker.start
            return
        self.chunks_saved += 1
        self.compression = self.compression or chunk.compression
        self.max_chunk = max(self.max_chunk, chunk.uncompressed_size)
        self._channel_ids.update(r.id for r in inner if isinstance(r, Channel))
        yield from inner

    def _open_cut_chunk(self, fh, walker: _Walker) -> Iterator[Any]:
        """The complete records of the chunk the file ends inside (see :func:`cut_chunk_records`)."""
        fh.seek(walker.start + 9)
        cut = self.cut_chunk = cut_chunk_records(fh.read(self.size - walker.start - 9), self._channel_ids)
        if not cut.records:
            return
        self.compression = self.compression or cut.compression
        self.good_end = walker.start + 9 + cut.used
        yield from cut.records

    def _skip_damaged(self, walker: _Walker, exc: Exception) -> bool:
        """After the reader failed: True to skip the damaged record and walk on, else set ``problem``."""
        self.good_end = walker.parsed_to
        if not walker.in_record:
            self.problem = "ends without a footer" if walker.parsed_to == self.size else \
                "ends inside a record header"
            return False
        if isinstance(exc, _Truncated):
            self.problem = f"ends inside a {_op_name(walker.opcode)} record at byte {walker.start}"
            return False
        if isinstance(exc, _Garbage):
            self.problem = f"unknown record opcode 0x{walker.opcode:02x} at byte {walker.start} " \
                           f"(garbage from here on)"
            return False
        if walker.opcode == Opcode.CHUNK:
            self.chunks_discarded += 1
        self.skipped_bytes += walker.end - walker.start
        self.good_end = walker.end
        return True


class Collected:
    """Schemas, channels and per-channel message counts and times of one file's usable records.

    ``orphans`` counts messages of channels the file never defined (dropped);
    ``rosbag2_metadata`` is the ``serialized_metadata`` of the ``rosbag2`` Metadata record."""

    def __init__(self):
        self.schemas: Dict[int, Schema] = {}
        self.channels: Dict[int, Channel] = {}
        self.counts: Dict[int, int] = {}
        self.file = FileInfo("")
        self.orphans = 0
        self.rosbag2_metadata: Optional[str] = None

    def topic_counts(self) -> Dict[str, int]:
        out: Dict[str, int] = {}
        for cid, n in self.counts.items():
            topic = self.channels[cid].topic
            out[topic] = out.get(topic, 0) + n
        return out


def walk(path: Path, sink: Any = None) -> Tuple[Scan, Collected]:
    """Scan ``path``; hand each usable record to ``sink`` (its ``schema``, ``channel``,
    ``message``, ``metadata`` and ``attachment`` methods), once per schema and channel id.

    The ``rosbag2`` Metadata record is collected, not handed on: the rewrite writes its own."""
    scan = Scan(path)
    got = Collected()
    for rec in scan.records():
        if isinstance(rec, Schema):
            if rec.id not in got.schemas:
                got.schemas[rec.id] = rec
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
        elif isinstance(rec, Attachment) and sink:
            sink.attachment(rec)
    return scan, got
