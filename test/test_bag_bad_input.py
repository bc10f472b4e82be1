"""Bad input: missing or broken metadata, missing files, truncated and garbage MCAP files."""
from __future__ import annotations

import shutil

import pytest
import yaml

from isa_mocap_ros.bag import BagError, BagReader, bag_info
from test_bag_common import write_sample_bag


def test_missing_path(tmp_path):
    with pytest.raises(BagError, match="found nothing at this path"):
        BagReader(tmp_path / "nope")


def test_dir_without_metadata_or_mcap(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "readme.txt").write_text("x")
    with pytest.raises(BagError, match=r"metadata.yaml or .mcap files, found neither \(contents: \['readme.txt'\]\)"):
        BagReader(tmp_path / "empty")


def test_dir_without_metadata_is_derived_with_note(tmp_path):
    written = write_sample_bag(tmp_path / "bag", n=4)
    (tmp_path / "bag" / "metadata.yaml").unlink()
    with BagReader(tmp_path / "bag") as r:
        assert r.version is None
        assert any("metadata.yaml is missing" in n for n in r.notes)
        assert [m.data for m in r.messages()] == [d for _, _, d in written]
        assert r.topics["/joint_states"].latched  # QoS from the MCAP channel metadata


def test_metadata_names_missing_file(tmp_path):
    write_sample_bag(tmp_path / "bag", n=2)
    meta = tmp_path / "bag" / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    doc["rosbag2_bagfile_information"]["relative_file_paths"] = ["bag_0.mcap", "bag_1.mcap"]
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagError, match=r"relative_file_paths names 'bag_1.mcap'.*found no such file"):
        BagReader(tmp_path / "bag")


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d.pop("rosbag2_bagfile_information"), "expected a mapping with key 'rosbag2_bagfile_information'"),
    (lambda d: d["rosbag2_bagfile_information"].update(storage_identifier="sqlite3"),
     "storage_identifier expected 'mcap', received 'sqlite3'"),
    (lambda d: d["rosbag2_bagfile_information"].update(version="nine"), "version expected int, received 'nine'"),
    (lambda d: d["rosbag2_bagfile_information"].update(compression_mode="file"),
     "compression_mode expected ''"),
    (lambda d: d["rosbag2_bagfile_information"]["topics_with_message_count"][0]["topic_metadata"].pop("type"),
     r"topic_metadata: expected key 'type'"),
])
def test_broken_metadata_fields(tmp_path, mutate, match):
    write_sample_bag(tmp_path / "bag", n=2)
    meta = tmp_path / "bag" / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    mutate(doc)
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagError, match=match):
        BagReader(tmp_path / "bag")


def test_metadata_not_yaml(tmp_path):
    write_sample_bag(tmp_path / "bag", n=2)
    (tmp_path / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with pytest.raises(BagError, match="metadata.yaml: expected YAML"):
        BagReader(tmp_path / "bag")


def test_garbage_file(tmp_path):
    bad = tmp_path / "garbage.mcap"
    bad.write_bytes(b"this is not an mcap file at all" * 10)
    with pytest.raises(BagError, match=r"garbage.mcap: expected an MCAP file starting with magic"):
        BagReader(bad)
    with pytest.raises(BagError, match="expected an MCAP file starting with magic"):
        bag_info(bad)


def test_magic_then_garbage_reads_empty_with_note(tmp_path):
    bad = tmp_path / "g.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    with BagReader(bad) as r:
        assert r.message_count == 0 and list(r.messages()) == []
        assert any("no summary" in n and "bytes dropped" in n for n in r.notes)


@pytest.mark.parametrize("fraction", [0.3, 0.5, 0.8, 0.97])
def test_truncated_mcap_recovers_complete_chunks(tmp_path, fraction):
    written = write_sample_bag(tmp_path / "bag", n=40, chunk_size=400)
    mcap = tmp_path / "bag" / "bag_0.mcap"
    cut = tmp_path / "cut.mcap"
    data = mcap.read_bytes()
    cut.write_bytes(data[: int(len(data) * fraction)])
    with BagReader(cut) as r:
        assert not r.indexed
        assert any("no summary" in n for n in r.notes)
        got = [(m.topic, m.log_time_ns, m.data) for m in r.messages()]
    assert 0 < len(got) <= len(written)
    assert r.message_count == len(got)
    assert set(got) <= set(written)  # every recovered message is one that was written, unchanged
    assert [t for _, t, _ in got] == sorted(t for _, t, _ in got)
    if fraction >= 0.8:
        assert len(got) >= len(written) // 2


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_corrupt_chunk_in_middle_stops_cleanly(tmp_path, compression):
    from mcap.reader import make_reader

    write_sample_bag(tmp_path / "bag", n=40, chunk_size=400, compression=compression)
    mcap = tmp_path / "bag" / "bag_0.mcap"
    with open(mcap, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) >= 4
    third = chunks[2]
    data = bytearray(mcap.read_bytes()[: chunks[-1].chunk_start_offset])  # no summary: forces a scan
    mid = third.chunk_start_offset + third.chunk_length - 20  # inside the third chunk's payload
    data[mid:mid + 8] = bytes(8 * [0x5A])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with BagReader(bad) as r:  # no raw mcap/zstd exception; the first two chunks are kept
        got = list(r.messages())
    ref = tmp_path / "first_two_chunks.mcap"
    ref.write_bytes(mcap.read_bytes()[: third.chunk_start_offset])
    with BagReader(ref) as r2:
        first_two = list(r2.messages())
    assert 0 < len(first_two) < 80
    assert len(got) == r.message_count
    assert {(m.topic, m.log_time_ns, m.data) for m in got} == {(m.topic, m.log_time_ns, m.data) for m in first_two}
    assert any(f"undecodable record at byte {third.chunk_start_offset}" in n for n in r.notes)


def test_file_truncated_after_indexing(tmp_path):
    write_sample_bag(tmp_path / "bag", n=20, chunk_size=300)
    with BagReader(tmp_path / "bag") as r:
        mcap = r.files[0]
        data = mcap.read_bytes()
        mcap.write_bytes(data[:200])
        with pytest.raises(BagError, match="expected .* bytes, received"):
            list(r.messages())


def test_bag_path_as_metadata_file_and_parent_relative_paths(tmp_path):
    write_sample_bag(tmp_path / "bag", n=3)
    with BagReader(tmp_path / "bag" / "metadata.yaml") as r:
        assert r.message_count == 6
    # old rosbag2 versions wrote paths relative to the bag's parent directory
    meta = tmp_path / "bag" / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    doc["rosbag2_bagfile_information"]["relative_file_paths"] = ["bag/bag_0.mcap"]
    meta.write_text(yaml.safe_dump(doc))
    with BagReader(tmp_path / "bag") as r:
        assert r.message_count == 6


def test_several_files_merge_in_time_order(tmp_path):
    a = write_sample_bag(tmp_path / "a", n=5)
    b_msgs = []
    from isa_mocap_ros.bag import BagWriter
    with BagWriter(tmp_path / "b") as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState")
        for _, t, d in a[::3]:
            w.write("/joint_states", d, t + 2)
            b_msgs.append(("/joint_states", t + 2, d))
    shutil.copy(tmp_path / "b" / "b_0.mcap", tmp_path / "a" / "a_1.mcap")
    meta = tmp_path / "a" / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    doc["rosbag2_bagfile_information"]["relative_file_paths"].append("a_1.mcap")
    meta.write_text(yaml.safe_dump(doc))
    with BagReader(tmp_path / "a") as r:
        got = [(m.topic, m.log_time_ns, m.data) for m in r.messages()]
        assert r.topics["/joint_states"].message_count == 5 + len(b_msgs)
        assert any("message_count" in n for n in r.notes)  # metadata.yaml disagrees with storage
    assert got == sorted(a + b_msgs, key=lambda x: x[1])
