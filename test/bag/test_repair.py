"""Repairing bags cut short or damaged (mwip_ros.bag.repair, .scan) and ``mwip_bag_repair``."""
import os
import subprocess
import sys

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from bagcheck import ENDPOINT_QOS_YAML, chunk_table, damage_cases, saved_in_cut, typestore, write_bag, write_graph_bag
from mwip_ros.bag import REPAIRED_KEY, RepairResult, raw_messages, repair, topic_counts, type_hash
from mwip_ros.cli.bag_repair import main

pytestmark = pytest.mark.unit

TS = typestore()
TOPICS = {"/joint_states": "sensor_msgs/msg/JointState", "/wheel_torque_cmd": "std_msgs/msg/Float64",
          "/disturbance_estimate": "geometry_msgs/msg/WrenchStamped"}


def _expected_saved(mcap_path, cut, written):
    """Messages whose record is complete in the first ``cut`` bytes: the chunks wholly there, then
    the complete records of the chunk the cut falls in (from the intact file's indexes)."""
    saved = saved_in_cut(mcap_path.read_bytes(), chunk_table(mcap_path), cut)
    assert saved == [(w[0], w[2]) for w in written[:len(saved)]]  # a prefix of what was written
    return len(saved)


@pytest.mark.parametrize("compression", [None, "zstd"])
def test_repair_truncated_copies(tmp_path, compression):
    src_dir = tmp_path / "orig"
    written = write_graph_bag(src_dir, n=12, compression=compression, chunk_size=400)
    src = src_dir / "orig_0.mcap"
    data = src.read_bytes()
    with open(src, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    boundary = chunks[2].chunk_start_offset + chunks[2].chunk_length  # exactly after a chunk
    cuts = sorted({len(data) // 3, len(data) // 2, boundary, boundary - 1, (2 * len(data)) // 3, len(data) - 40})
    for cut in cuts:
        bag = tmp_path / f"cut{cut}"
        bag.mkdir()
        (bag / f"cut{cut}_0.mcap").write_bytes(data[:cut])  # no metadata.yaml: the recorder died first
        expected = _expected_saved(src, cut, written)
        assert expected > 0, cut

        dry = repair(bag, dry_run=True)
        assert dry.total_messages == expected and sorted(os.listdir(bag)) == [f"cut{cut}_0.mcap"]

        result = repair(bag)
        assert result.total_messages == expected, cut
        assert 0 <= result.bytes_discarded < cut
        if cut == boundary:  # the file ends right after a chunk: nothing lost
            assert result.bytes_discarded == 0
        if cut == boundary - 1 and compression is None:  # one byte less: that chunk's last record is lost
            assert expected == _expected_saved(src, boundary, written) - 1
            table = chunk_table(src)[2]
            assert result.bytes_discarded == table.messages[-1][2] - table.messages[-2][2] - 1
        if cut == boundary - 1 and compression:  # ... its last zstd block: here the whole (small) chunk
            assert result.bytes_discarded == chunks[2].chunk_length - 1
        broken = bag / f"cut{cut}_0.mcap.broken"
        assert broken.read_bytes() == data[:cut]
        assert result.files[0].backup == broken and result.metadata_written

        with AnyReader([bag], default_typestore=TS) as reader:
            got = [(c.topic, t, bytes(raw), reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
            counts = {c.topic: c.msgcount for c in reader.connections}
        assert [(g[0], g[1], g[2]) for g in got] == [(w[0], w[2], w[4]) for w in written[:expected]]
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["message_count"] == expected
        assert {e["topic_metadata"]["name"]: e["message_count"] for e in meta["topics_with_message_count"]} \
            == result.topic_counts
        assert sum(counts.values()) == expected
        for e in meta["topics_with_message_count"]:
            tm = e["topic_metadata"]
            assert tm["offered_qos_profiles"] == yaml.safe_load(ENDPOINT_QOS_YAML)
            assert tm["type_description_hash"] == type_hash(tm["type"])

        again = repair(bag)  # a second run finds a complete bag
        assert not again.needed_repair and again.total_messages == expected and not again.metadata_written


@pytest.mark.parametrize("compression", [None, "zstd"])
def test_repair_saves_exactly_the_intact_chunks(tmp_path, compression):
    """Cut at several points and a damaged chunk in the middle: repair saves exactly the
    messages of the chunks still whole (from the intact file's chunk and message indexes)."""
    src = tmp_path / "src"
    written = write_bag(src, TOPICS, 1000, compression=compression, chunk_size=4096)
    for i, (case, data, expected) in enumerate(damage_cases(src / "src_0.mcap")):
        bag = tmp_path / f"case{i}"
        bag.mkdir()
        mcap = bag / f"case{i}_0.mcap"
        mcap.write_bytes(data)
        result = repair(bag)
        assert isinstance(result, RepairResult)
        assert result.topic_counts == expected, case
        assert result.needed_repair, case
        if not expected:  # 9 bytes in: nothing to save, file left as it was
            assert not result.ok and "nothing could be recovered" in result.report(), case
            assert mcap.read_bytes() == data and os.listdir(bag) == [mcap.name]
            continue
        assert result.ok and (bag / f"{mcap.name}.broken").read_bytes() == data, case
        # the repaired file is complete and every saved message reads back, CRCs checked
        with open(mcap, "rb") as fh:
            reader = make_reader(fh, validate_crcs=True)
            saved = [(m.log_time, c.topic, bytes(m.data)) for _s, c, m in reader.iter_messages()]
        assert saved == list(raw_messages(bag)), case
        assert topic_counts(bag) == {t: expected.get(t, 0) for t in TOPICS}, case
        assert set(saved) <= {(t, topic, cdr) for topic, _type, t, _msg, cdr in written}, case
        assert len(saved) == sum(expected.values())
        if "damaged" in case:
            assert result.files[0].chunks_discarded == 1, case
            assert "damaged chunk(s)" in result.report()
        if case == "damaged chunk in the middle":
            assert not result.files[0].cut_short and "damaged (" in result.report()
        assert not repair(bag).needed_repair, case


def test_repair_keeps_existing_metadata_fields(tmp_path):
    bag = tmp_path / "b"
    written = write_graph_bag(bag, n=10, chunk_size=400)
    meta_path = bag / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text())
    doc["rosbag2_bagfile_information"]["custom_data"] = {"run": "42"}
    meta_path.write_text(yaml.safe_dump(doc))
    mcap = bag / "b_0.mcap"
    mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    assert main([str(mcap)]) == 0  # an .mcap inside a bag directory repairs the bag
    meta = yaml.safe_load(meta_path.read_text())["rosbag2_bagfile_information"]
    assert set(meta["custom_data"]) == {"run", REPAIRED_KEY} and meta["custom_data"]["run"] == "42"
    assert 0 < meta["message_count"] < len(written)


def test_repair_writes_the_repaired_note(tmp_path):
    """metadata.yaml of a repaired bag says, under custom_data[REPAIRED_KEY], in one line: repaired,
    how many messages kept up to which log time, what was lost; other entries are kept."""
    bag = tmp_path / "b"
    written = write_bag(bag, TOPICS, 200, chunk_size=4096)  # log times 1 ms apart
    meta_path = bag / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text())
    doc["rosbag2_bagfile_information"]["custom_data"] = {"mwip_ros.lockstep_gaps": "none", "run": "7"}
    meta_path.write_text(yaml.safe_dump(doc))
    mcap = bag / "b_0.mcap"
    chunk = chunk_table(mcap)[3]
    cut = chunk.data_start + chunk.messages[4][2] + 5  # 5 bytes into the 6th record of the 4th chunk
    mcap.write_bytes(mcap.read_bytes()[:cut])
    result = repair(bag)
    kept = result.total_messages  # the chunks before, and the first 5 records of the cut one
    assert kept == sum(1 for w in written if w[2] <= chunk.messages[4][1])
    custom = yaml.safe_load(meta_path.read_text())["rosbag2_bagfile_information"]["custom_data"]
    assert custom["mwip_ros.lockstep_gaps"] == "none" and custom["run"] == "7"
    note = custom[REPAIRED_KEY]
    assert "\n" not in note
    last = (written[kept - 1][2] - written[0][2]) / 1e9
    lost_until = (chunk.messages[-1][1] - written[0][2]) / 1e9
    assert note == (f"repaired after a cut: {kept} messages kept up to log time {last:.3f} s (from the bag's "
                    f"start); the {result.bytes_discarded} bytes after that were incomplete (messages up to log "
                    f"time {lost_until:.3f} s lost)"), note
    assert result.files[0].cut_chunk_messages == 5
    assert not repair(bag).needed_repair  # a second run keeps the note
    custom = yaml.safe_load(meta_path.read_text())["rosbag2_bagfile_information"]["custom_data"]
    assert custom[REPAIRED_KEY] == note


def test_repair_note_for_a_damaged_chunk_without_a_cut(tmp_path):
    src = tmp_path / "src"
    write_bag(src, TOPICS, 300, chunk_size=4096)
    case = dict((name, data) for name, data, _ in damage_cases(src / "src_0.mcap"))["damaged chunk in the middle"]
    bag = tmp_path / "b"
    bag.mkdir()
    (bag / "b_0.mcap").write_bytes(case)
    result = repair(bag)  # no metadata.yaml: written from scratch, with the note
    custom = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]["custom_data"]
    assert custom[REPAIRED_KEY].startswith(f"repaired after damage: {result.total_messages} messages kept up to "
                                           f"log time ")
    assert custom[REPAIRED_KEY].endswith("; 1 damaged chunk(s) skipped")


def test_repair_complete_bag_without_metadata(tmp_path):
    bag = tmp_path / "b"
    written = write_graph_bag(bag, n=3)
    (bag / "metadata.yaml").unlink()
    result = repair(bag)
    assert not result.needed_repair and result.metadata_written and result.total_messages == len(written)
    assert sorted(os.listdir(bag)) == ["b_0.mcap", "metadata.yaml"]
    with AnyReader([bag], default_typestore=TS) as reader:
        assert sum(1 for _ in reader.messages()) == len(written)


def test_repair_cli_exit_codes(tmp_path, capsys):
    bag = tmp_path / "b"
    write_graph_bag(bag, n=6, chunk_size=400)
    mcap = bag / "b_0.mcap"
    full = mcap.read_bytes()
    mcap.write_bytes(full[:100])  # not even the first chunk
    assert main([str(bag)]) == 1
    assert "nothing could be recovered" in capsys.readouterr().out
    assert mcap.read_bytes() == full[:100]  # left unchanged
    assert main([str(tmp_path / "missing")]) == 2
    assert "no such bag" in capsys.readouterr().err
    (tmp_path / "notes.txt").write_text("x")
    assert main([str(tmp_path / "notes.txt")]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    with pytest.raises(SystemExit) as exc:
        main([])
    assert exc.value.code == 2
    mcap.write_bytes(full[: len(full) * 2 // 3])
    assert main([str(bag), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "would save" in out and mcap.stat().st_size == len(full) * 2 // 3
    assert main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert "saved" in out and "b_0.mcap.broken" in out and "total:" in out


@pytest.mark.cli
def test_repair_cli_as_module(tmp_path):
    bag = tmp_path / "b"
    write_graph_bag(bag, n=6, chunk_size=400)
    mcap = bag / "b_0.mcap"
    mcap.write_bytes(mcap.read_bytes()[:-100])
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.bag_repair", str(bag)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert "cut short (ends after its data section without a valid footer)" in r.stdout
    from mwip_ros.msgs.topics import GRAPH_TOPICS
    assert f"total: {6 * len(GRAPH_TOPICS)} messages saved" in r.stdout   # nothing lost: the cut was the footer
    r = subprocess.run([sys.executable, "-m", "mwip_ros.cli.bag_repair", str(bag)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and "nothing to repair" in r.stdout


def test_damaged_fields_inside_records_skip_only_that_record(tmp_path):
    """A length inside a record that points past the record's end: that record is skipped
    (a chunk counted as damaged), the walk goes on with the next record."""
    import struct

    from bagcheck import chunk_table, summed

    src = tmp_path / "src"
    write_bag(src, TOPICS, 300, chunk_size=4096)
    data = bytearray((src / "src_0.mcap").read_bytes())
    chunks = chunk_table(src / "src_0.mcap")
    m = len(chunks) // 2
    # the chunk's compression string length (after start, end, size, CRC)
    struct.pack_into("<I", data, chunks[m].start + 9 + 28, 0xFFFFFFF0)
    # the name length of the rosbag2 Metadata record right after the Header
    header_end = 8 + 9 + struct.unpack_from("<Q", data, 9)[0]
    assert data[header_end] == 0x0C
    struct.pack_into("<I", data, header_end + 9, 0x7FFFFFFF)
    bag = tmp_path / "b"
    bag.mkdir()
    (bag / "b_0.mcap").write_bytes(bytes(data))
    result = repair(bag)
    assert result.topic_counts == summed(c for i, c in enumerate(chunks) if i != m)
    f = result.files[0]
    assert f.chunks_discarded == 1 and not f.cut_short and f.was_complete is False
    metadata_record = 9 + struct.unpack_from("<Q", data, header_end + 1)[0]
    assert f.bytes_discarded == (chunks[m].end - chunks[m].start) + metadata_record
    with open(bag / "b_0.mcap", "rb") as fh:
        assert sum(1 for _ in make_reader(fh, validate_crcs=True).iter_messages()) == result.total_messages


def test_a_split_bag_cut_in_its_last_file_is_repaired_whole_in_file_order(tmp_path):
    """A recorder killed while writing the 12th file of a split bag: no metadata.yaml, the finished files whole, the
    last one cut.  Repair keeps every finished file, saves what it can of the last, lists the files in recording
    order (_10 after _9, not after _1) and rosbags reads the result as one run."""
    bag = tmp_path / "run"
    topics = {"/joint_states": "sensor_msgs/msg/JointState", "/wheel_torque_cmd": "std_msgs/msg/Float64"}
    written = write_bag(bag, topics, 130, chunk_size=400, max_bagfile_duration=0.02)
    (bag / "metadata.yaml").unlink()
    files = sorted(bag.glob("*.mcap"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
    assert len(files) >= 12
    last = files[-1]
    with open(last, "rb") as fh:
        in_last = sum(1 for _ in make_reader(fh).iter_messages())
    last.write_bytes(last.read_bytes()[:len(last.read_bytes()) // 2])
    result = repair(bag)
    assert result.metadata_written
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == [p.name for p in files]
    kept = len(written) - in_last
    assert kept <= meta["message_count"] < len(written)
    with AnyReader([bag], default_typestore=TS) as reader:
        got = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    assert got == [(w[0], w[2], w[4]) for w in written[:len(got)]] and len(got) == meta["message_count"]
