"""Replay planning (pure): topic selection, remaps, header detection, lockstep frames."""
from __future__ import annotations

import pytest

from isa_mocap_ros.bag import BagError, BagMessage, BagReader, TopicInfo
from isa_mocap_ros.bag.playback import (PlaybackOptions, first_field_is_header, frames, parse_remaps,
                                        select_topics)
from bagfactory import write_test_bag


def _topics(*names: str) -> dict[str, TopicInfo]:
    return {n: TopicInfo(name=n, type="std_msgs/msg/String", serialization_format="cdr", offered_qos=(),
                         message_count=1) for n in names}


def test_select_topics_globs_and_excludes():
    t = _topics("/mocap/cam0/image_raw", "/mocap/cam1/image_raw", "/mocap/cam0/camera_info", "/other")
    assert select_topics(t, PlaybackOptions()) == sorted(t)
    assert select_topics(t, PlaybackOptions(topics=("/mocap/cam*/image_raw",))) == [
        "/mocap/cam0/image_raw", "/mocap/cam1/image_raw"]
    assert select_topics(t, PlaybackOptions(exclude_topics=("/mocap/*",))) == ["/other"]
    with pytest.raises(BagError, match="topics not in the bag: \\['/nope'\\]"):
        select_topics(t, PlaybackOptions(topics=("/nope",)))


def test_parse_remaps():
    assert parse_remaps(["/a:=/b", " /c := /d "]) == {"/a": "/b", "/c": "/d"}
    with pytest.raises(BagError, match="old:=new"):
        parse_remaps(["/a=/b"])


@pytest.mark.parametrize("bad", [{"rate": 0.0}, {"rate": -1.0}, {"start_offset_s": -0.5}])
def test_options_are_validated(bad):
    with pytest.raises(BagError):
        PlaybackOptions(**bad)


def test_first_field_is_header_reads_real_schemas(tmp_path):
    write_test_bag(tmp_path / "b", views=1, frames=1)
    with BagReader(tmp_path / "b") as r:
        assert first_field_is_header(r.msgdef("sensor_msgs/msg/Image"))
        assert first_field_is_header(r.msgdef("geometry_msgs/msg/TransformStamped"))
    assert not first_field_is_header("# comment\nint32 X=3\nfloat64 data\n")
    assert not first_field_is_header("string data\n")


def _m(topic: str, t: int, stamp: int | None) -> BagMessage:
    return BagMessage(topic=topic, type="x", log_time_ns=t, publish_time_ns=t,
                      data=b"" if stamp is None else stamp.to_bytes(8, "little"))


def test_frames_group_by_stamp_latched_go_alone():
    msgs = [_m("/ext", 0, None), _m("/img0", 1, 100), _m("/img1", 1, 100), _m("/tf", 1, None),
            _m("/img0", 2, 200), _m("/ext", 2, None), _m("/img1", 3, 200), _m("/img0", 4, 300)]
    out = list(frames(msgs, stamped_topics=["/img0", "/img1"], latched_topics=["/ext"],
                      stamp_of=lambda m: int.from_bytes(m.data, "little")))
    assert [(f.stamp_ns, [m.topic for m in f.messages]) for f in out] == [
        (None, ["/ext"]), (100, ["/img0", "/img1", "/tf"]), (200, ["/img0"]), (None, ["/ext"]),
        (200, ["/img1"]), (300, ["/img0"])]


def test_frames_of_a_real_bag_have_one_stamp_per_frame_set(tmp_path):
    import msg_adapters as ma
    write_test_bag(tmp_path / "b", views=3, frames=4)
    with BagReader(tmp_path / "b") as r:
        stamped = [t for t in r.topics if not t.endswith("extrinsics")]
        fs = list(frames(r.messages(), stamped_topics=stamped,
                         latched_topics=[t for t in r.topics if t.endswith("extrinsics")],
                         stamp_of=lambda m: ma.header_stamp_ns_from_cdr(m.data)))
    stamped_frames = [f for f in fs if f.stamp_ns is not None]
    assert len(stamped_frames) == 4
    assert all(len(f.messages) == 3 * 2 + 1 for f in stamped_frames)  # image+info per view, joint states
