"""BagWriter -> BagReader round trips: bytes, order, counts, topics, QoS, versions, compressions."""
from __future__ import annotations

import pytest
import yaml

from isa_mocap_ros.bag import (QOS_DEFAULT, QOS_LATCHED, BagError, BagReader, BagWriter, QosProfile,
                               bag_info, format_bag_info, msgdef_for)
from test_bag_common import BEST_EFFORT, write_sample_bag


@pytest.mark.parametrize("version", [9, 8])
@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_round_trip(tmp_path, version, compression):
    bag = tmp_path / "bag"
    written = write_sample_bag(bag, version=version, compression=compression)
    with BagReader(bag) as r:
        assert r.version == version
        assert r.notes == []
        assert r.indexed
        assert r.compression == ("" if compression == "none" else compression)
        got = list(r.messages())
        assert [(m.topic, m.log_time_ns, m.data) for m in got] == written
        assert r.message_count == len(written) == 24
        assert set(r.topics) == {"/cam/image", "/joint_states", "/unused"}
        assert r.topics["/cam/image"].type == "sensor_msgs/msg/Image"
        assert r.topics["/cam/image"].message_count == 12
        assert r.topics["/unused"].message_count == 0
        assert r.topics["/cam/image"].offered_qos == (QOS_DEFAULT, BEST_EFFORT)
        assert r.topics["/joint_states"].offered_qos == (QOS_LATCHED,)
        assert r.topics["/joint_states"].latched and not r.topics["/cam/image"].latched
        assert r.start_ns == written[0][1] and r.end_ns == written[-1][1]
        assert r.duration_ns == written[-1][1] - written[0][1]
        img = [m for m in got if m.topic == "/cam/image"]
        assert all(m.publish_time_ns == m.log_time_ns - 5 for m in img)
        assert all(m.type == "sensor_msgs/msg/Image" for m in img)


def test_metadata_yaml_layout_per_version(tmp_path):
    write_sample_bag(tmp_path / "v9", version=9)
    write_sample_bag(tmp_path / "v8", version=8)
    v9 = yaml.safe_load((tmp_path / "v9" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    v8 = yaml.safe_load((tmp_path / "v8" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert v9["version"] == 9 and v8["version"] == 8
    assert v9["relative_file_paths"] == ["v9_0.mcap"] and (tmp_path / "v9" / "v9_0.mcap").is_file()
    assert v9["storage_identifier"] == "mcap" and v9["message_count"] == 24
    assert v9["files"][0]["message_count"] == 24 and v9["files"][0]["path"] == "v9_0.mcap"
    assert v9["duration"]["nanoseconds"] == 110_000_004
    assert v9["ros_distro"] and v8["ros_distro"]
    q9 = v9["topics_with_message_count"][1]["topic_metadata"]["offered_qos_profiles"]
    q8 = v8["topics_with_message_count"][1]["topic_metadata"]["offered_qos_profiles"]
    assert isinstance(q9, list) and q9[0]["durability"] == "transient_local"  # v9: list with names
    assert isinstance(q8, str) and yaml.safe_load(q8)[0]["durability"] == 1  # v8: string with rmw ints
    assert v9["topics_with_message_count"][0]["topic_metadata"]["type_description_hash"].startswith("RIHS01_")


def test_topic_and_time_filters(tmp_path):
    written = write_sample_bag(tmp_path / "bag")
    with BagReader(tmp_path / "bag") as r:
        js = list(r.messages(["/joint_states"]))
        assert [m.data for m in js] == [d for t, _, d in written if t == "/joint_states"]
        lo, hi = written[5][1], written[14][1]
        window = list(r.messages(start_ns=lo, end_ns=hi))
        assert [m.log_time_ns for m in window] == [t for _, t, _ in written if lo <= t <= hi]
        assert len(window) == 10
        assert list(r.messages("/unused")) == []
        with pytest.raises(BagError, match=r"unknown \['/nope'\]"):
            r.messages(["/nope"])


def test_msgdef_is_stored_schema(tmp_path):
    write_sample_bag(tmp_path / "bag")
    with BagReader(tmp_path / "bag") as r:
        text = r.msgdef("sensor_msgs/msg/Image")
        assert text == msgdef_for("sensor_msgs/msg/Image")[0]
        assert "MSG: std_msgs/Header" in text
        with pytest.raises(BagError, match="msgdef type_name"):
            r.msgdef("foo_msgs/msg/Bar")


def test_custom_msgdef_and_flush_then_more(tmp_path):
    bag = tmp_path / "bag"
    with BagWriter(bag, compression="none") as w:
        w.add_topic("/x", "my_pkg/msg/Thing", msgdef="int32 a\n", qos=[])
        w.write("/x", b"\x00\x01\x00\x00\x07\x00\x00\x00", 5)
        w.flush()
        w.write("/x", b"\x00\x01\x00\x00\x08\x00\x00\x00", 3)
        assert w.message_count == 2 and w.topics["/x"].message_count == 2
    with BagReader(bag) as r:
        assert [m.log_time_ns for m in r.messages()] == [3, 5]
        assert r.msgdef("my_pkg/msg/Thing") == "int32 a\n"
        assert r.topics["/x"].offered_qos == ()


def test_many_chunks_stay_in_log_time_order(tmp_path):
    bag = tmp_path / "bag"
    times = [(k * 7919) % 1000 for k in range(400)]  # a permutation of 0..999 subset, unordered
    with BagWriter(bag, chunk_size=256) as w:
        w.add_topic("/a", "std_msgs/msg/UInt32")
        w.add_topic("/b", "std_msgs/msg/UInt32")
        for k, t in enumerate(times):
            w.write("/a" if k % 2 else "/b", b"\x00\x01\x00\x00" + k.to_bytes(4, "little"), t)
    with BagReader(bag) as r:
        got = [(m.log_time_ns, int.from_bytes(m.data[4:], "little")) for m in r.messages()]
    assert got == sorted(((t, k) for k, t in enumerate(times)), key=lambda x: x[0])


def test_qos_profile_validation_and_dicts():
    assert QOS_LATCHED.latched and not QOS_DEFAULT.latched
    for v in (8, 9):
        assert QosProfile.from_dict(BEST_EFFORT.to_dict(version=v)) == BEST_EFFORT
    assert BEST_EFFORT.to_dict(version=8)["reliability"] == 2
    with pytest.raises(BagError, match="reliability: expected one of"):
        QosProfile(reliability="sometimes")
    with pytest.raises(BagError, match="depth: expected an int >= 0"):
        QosProfile(depth=-1)
    with pytest.raises(BagError, match=r"deadline: expected a \(sec, nsec\) pair"):
        QosProfile(deadline=1.5)
    with pytest.raises(BagError, match="history expected an rmw enum value"):
        QosProfile.from_dict({"history": 9})


def test_writer_argument_errors(tmp_path):
    with pytest.raises(BagError, match="version: expected 8 or 9, received 7"):
        BagWriter(tmp_path / "a", version=7)
    with pytest.raises(BagError, match="compression: expected one of"):
        BagWriter(tmp_path / "a", compression="gzip")
    write_sample_bag(tmp_path / "b", n=1)
    with pytest.raises(BagError, match="exists"):
        BagWriter(tmp_path / "b")
    with BagWriter(tmp_path / "b", overwrite=True) as w:  # replaces the old bag
        w.add_topic("/t", "std_msgs/msg/Empty")
    with BagReader(tmp_path / "b") as r:
        assert list(r.topics) == ["/t"] and r.message_count == 0
    (tmp_path / "b" / "notes.txt").write_text("mine")
    with pytest.raises(BagError, match="refusing to delete"):
        BagWriter(tmp_path / "b", overwrite=True)


def test_writer_input_errors(tmp_path):
    with BagWriter(tmp_path / "bag") as w:
        with pytest.raises(BagError, match=r"type_name 'foo_msgs/msg/Nope'.*unknown type"):
            w.add_topic("/f", "foo_msgs/msg/Nope")
        with pytest.raises(BagError, match="expected 'pkg/msg/Type', received 'Image'"):
            w.add_topic("/i", "Image")
        with pytest.raises(BagError, match="expected QosProfile items"):
            w.add_topic("/q", "std_msgs/msg/Empty", qos=["reliable"])
        w.add_topic("/e", "std_msgs/msg/Empty")
        w.add_topic("/e", "std_msgs/msg/Empty")  # identical: no-op
        with pytest.raises(BagError, match="already added as std_msgs/msg/Empty"):
            w.add_topic("/e", "std_msgs/msg/String")
        with pytest.raises(BagError, match=r"write topic: expected one added with add_topic \['/e'\], received '/x'"):
            w.write("/x", b"\x00\x01\x00\x00", 1)
        with pytest.raises(BagError, match="write data: expected CDR bytes, received str"):
            w.write("/e", "abc", 1)
        with pytest.raises(BagError, match="log_time_ns: expected an int"):
            w.write("/e", b"\x00\x01\x00\x00", -3)
        w.write("/e", b"\x00\x01\x00\x00\x00", 1)
    with pytest.raises(BagError, match="after close"):
        w.write("/e", b"\x00\x01\x00\x00", 2)
    w.close()  # idempotent
    with BagReader(tmp_path / "bag") as r:
        assert r.message_count == 1 and r.topics["/e"].message_count == 1


def test_writer_closes_bag_when_body_raises(tmp_path):
    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / "bag") as w:
            w.add_topic("/e", "std_msgs/msg/Empty")
            w.write("/e", b"\x00\x01\x00\x00", 10)
            raise RuntimeError("boom")
    with BagReader(tmp_path / "bag") as r:
        assert r.indexed and r.message_count == 1


def test_bag_info_dict_and_text(tmp_path):
    written = write_sample_bag(tmp_path / "bag")
    info = bag_info(tmp_path / "bag")
    assert info["message_count"] == 24 and info["version"] == 9
    assert info["start_ns"] == written[0][1] and info["duration_ns"] == written[-1][1] - written[0][1]
    topics = {t["name"]: t for t in info["topics"]}
    assert topics["/joint_states"]["latched"] and topics["/joint_states"]["message_count"] == 12
    assert topics["/cam/image"]["offered_qos"][1]["reliability"] == "best_effort"
    text = format_bag_info(info)
    assert "Messages:          24" in text
    assert "Topic: /cam/image" in text and "Type: sensor_msgs/msg/Image" in text and "Count: 12" in text
    assert "Duration:          0.110000004s" in text
    assert "Nov 14 2023 22:13:20" in text  # 1_700_000_000 s, UTC
