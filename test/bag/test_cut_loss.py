"""How much of a run repair loses when the recording is cut (file cut short, recorder killed).

A 10 s run at 200 Hz of the loop topics, written by BagWriter as the recorder writes it
(:mod:`bag.cutloss`), cut at about 20 points, several inside the first chunk and a few bytes
into a record, and snapshotted as ``kill -9`` leaves it at several times: repair must lose less
than one second of the run at every one of them (an uncompressed chunk: nothing but the
incomplete record; zstd: at most the chunk's incomplete block; a kill: at most the chunk the
writer was filling, which it closes every ``max_chunk_duration``).
"""
import struct

import pytest
from mcap.records import Channel, Message
from mcap.writer import CompressionType, Writer

from bag.cutloss import copy_bag, cut_points, loss, record_run, repair_cut, time_at_cut
from bagcheck import chunk_table, saved_in_cut
from mwip_ros.bag import BagError, BagWriter, raw_messages, repair
from mwip_ros.bag.scan import cut_chunk_records
from mwip_ros.bag.writer import DEFAULT_MAX_CHUNK_DURATION

pytestmark = pytest.mark.unit

BOUND_S = 1.0
AT_TIMES = (0.1, 0.25, 0.4, 1.0, 2.0, 3.5)  # s into the run: the first three inside the first 0.5 s chunk
OF_FILE = tuple(i / 14 for i in range(1, 14))
KILLS = (0.3, 1.0, 3.0, 6.9, 9.7)


def _last_written(run, k):
    return max(t for _topic, t in run.written if t - run.t0 <= k * 1e9)


@pytest.mark.parametrize("compression", [None, "zstd"])
def test_loss_under_a_second_at_every_cut(tmp_path, compression):
    run = record_run(tmp_path / "run", compression=compression, kills=KILLS)  # the recorder's writer, defaults
    data = run.mcap.read_bytes()
    cuts = cut_points(run, AT_TIMES, OF_FILE)
    assert len(cuts) == 19 and sum(1 for _l, cut in cuts if cut < run.chunks[0].end) >= 3
    bound = DEFAULT_MAX_CHUNK_DURATION + run.period_ns / 1e9
    losses = {}
    for label, cut in cuts:
        lost, result = repair_cut(run, data[:cut], time_at_cut(run, cut), tmp_path / "cut")
        losses[label] = lost
        assert result.total_messages == len(saved_in_cut(data, run.chunks, cut)), label  # the complete records
        if compression is None:
            assert lost == 0, label  # everything up to the last complete message
    for k, snapshot in run.kills.items():
        losses[f"kill {k}"] = loss(run, snapshot, _last_written(run, k), tmp_path / "kill")
    assert max(losses.values()) < min(bound, BOUND_S), losses


@pytest.mark.parametrize("compression", [None, "zstd"])
def test_cut_inside_a_1mib_chunk_keeps_its_complete_records(tmp_path, compression):
    """1 MiB chunks and no time bound (a bag of the old writer): a 10 s run is 3 chunks, and a cut
    in the first still keeps every complete record (zstd: every complete block) of it."""
    run = record_run(tmp_path / "run", compression=compression, max_chunk_duration=None)
    data = run.mcap.read_bytes()
    assert len(run.chunks) == 3
    for label, cut in cut_points(run, (0.1, 1.0, 2.0, 3.5), ()):
        assert cut < run.chunks[0].end, label
        lost, result = repair_cut(run, data[:cut], time_at_cut(run, cut), tmp_path / "cut")
        expected = saved_in_cut(data, run.chunks, cut)
        assert lost < BOUND_S, (label, lost)
        if compression is None:
            assert lost == 0, label
        if not expected:  # zstd, cut inside the chunk's first block
            assert not result.ok, label
            continue
        f = result.files[0]
        assert f.cut_chunk_messages == f.messages_saved == len(expected) and f.chunks_saved == 0, label
        # the messages of the cut chunk are those written, in order, up to the last complete record
        got = [(topic, t) for t, topic, _cdr in raw_messages(tmp_path / "cut")]
        assert got == run.written[:len(got)] == expected, label


def test_kill_loses_at_most_the_chunk_being_filled(tmp_path):
    """The chunk being filled is in memory: without the time bound a kill 3 s in loses all 3 s."""
    old = record_run(tmp_path / "old", max_chunk_duration=None, kills=(3.0,))
    assert loss(old, old.kills[3.0], _last_written(old, 3.0), tmp_path / "a") > 3.0
    new = record_run(tmp_path / "new", kills=(3.0, 3.49))
    for k in (3.0, 3.49):
        assert loss(new, new.kills[k], _last_written(new, k), tmp_path / "b") <= DEFAULT_MAX_CHUNK_DURATION


def test_writer_closes_a_chunk_every_max_chunk_duration(tmp_path):
    run = record_run(tmp_path / "r", seconds=3.0, max_chunk_duration=0.2)
    spans = [(c.messages[-1][1] - c.messages[0][1]) / 1e9 for c in chunk_table(run.mcap)]
    assert len(spans) == 15 and max(spans) <= 0.2
    for bad in (0, -1.0, "0.5", True):
        with pytest.raises(BagError, match="max_chunk_duration must be a positive number"):
            BagWriter(tmp_path / f"bad{bad}", max_chunk_duration=bad)


# --- the structural checks that stand in for the CRC of a cut chunk --------------------------

def _chunk_body(records: bytes, start=0, end=100, compression=b"") -> bytes:
    return struct.pack("<QQQII", start, end, len(records), 0, len(compression)) + compression + \
        struct.pack("<Q", len(records) + 1000) + records  # records length past the cut: cut short


def _record(rec) -> bytes:
    from mcap.records import RecordBuilder
    builder = RecordBuilder()
    rec.write(builder)
    return bytes(builder.end())


def _message(channel_id=1, log_time=10, data=b"abc"):
    return _record(Message(channel_id=channel_id, log_time=log_time, data=data, publish_time=log_time, sequence=0))


def test_cut_chunk_records_stop_at_the_first_record_that_fails():
    good = _record(Channel(id=1, topic="/a", message_encoding="cdr", schema_id=0, metadata={})) + _message()
    cases = {
        "unknown opcode": (good + b"\x0d" + _message()[1:] + _message(), 2),
        "unknown channel": (good + _message(channel_id=7) + _message(), 2),
        "outside the time range": (good + _message(log_time=101) + _message(), 2),
        "too short for a message": (good + b"\x05" + struct.pack("<Q", 10) + bytes(10) + _message(), 2),
        "field past its record": (good + b"\x04" + struct.pack("<Q", 8) + struct.pack("<HHI", 2, 0, 999) +
                                  _message(), 2),
        "incomplete last record": (good + _message() + _message()[:-1], 3),
        "zeros after the cut": (good + _message(data=b"ab\x00")[:-1] + bytes(64), 2),
        "all fine": (good + _message(log_time=100) + _message(log_time=0), 4),
    }
    for name, (records, n) in cases.items():
        cut = cut_chunk_records(_chunk_body(records), set())
        assert len(cut.records) == n, (name, cut.stop)
        assert isinstance(cut.records[0], Channel) and all(isinstance(r, Message) for r in cut.records[1:]), name
    cut = cut_chunk_records(_chunk_body(_message()), {1})  # the channel defined before the chunk
    assert len(cut.records) == 1 and cut.used == len(_chunk_body(_message()))
    assert not cut_chunk_records(_chunk_body(good)[:30], set()).records  # the chunk header itself cut
    assert "cannot decode" in cut_chunk_records(_chunk_body(good, compression=b"brotli"), set()).stop


def test_repair_decodes_a_cut_lz4_chunk(tmp_path):
    """An lz4 chunk (another writer's; BagWriter writes none or zstd): its complete blocks are kept."""
    lz4_frame = pytest.importorskip("lz4.frame")
    from mcap.records import Schema
    path = tmp_path / "lz4.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=1 << 22, compression=CompressionType.LZ4)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("std_msgs/msg/Float64", "ros2msg", b"float64 data")
        cid = w.register_channel("/x", "cdr", sid)
        for i in range(20000):
            w.add_message(cid, 1000 + i, struct.pack("<4xd", i * 0.5) + bytes(40), 1000 + i, i)
        w.finish()
    data = path.read_bytes()
    head = len(_record(Schema(id=sid, name="std_msgs/msg/Float64", encoding="ros2msg", data=b"float64 data"))) + \
        len(_record(Channel(id=cid, topic="/x", message_encoding="cdr", schema_id=sid, metadata={})))
    first = data.index(b"lz4") + 3 + 8  # the chunk's compressed records
    cut = len(data) // 2
    plain = lz4_frame.LZ4FrameDecompressor().decompress(data[first:cut])  # the complete blocks
    expected = (len(plain) - head) // len(_message(data=bytes(52)))
    assert 0 < expected < 20000 and len(plain) % (64 * 1024) == 0
    result = repair(copy_bag(data[:cut], tmp_path / "b"))
    assert result.total_messages == result.files[0].cut_chunk_messages == expected
    assert [t for t, _topic, _cdr in raw_messages(tmp_path / "b")] == list(range(1000, 1000 + expected))
