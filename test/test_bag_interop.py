"""Interop: our bags read by mcap + mcap_ros2 and by rosbags; we read bags written by both."""
from __future__ import annotations

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as McapRos2Writer
from rclpy.serialization import deserialize_message
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import Image, JointState

from isa_mocap_ros.bag import QOS_LATCHED, BagReader, BagWriter, msgdef_for
from test_bag_common import image_msg, joint_msg, write_sample_bag

TS = get_typestore(Stores.ROS2_JAZZY)


@pytest.mark.parametrize("version", [9, 8])
def test_our_bag_decodes_with_mcap_ros2(tmp_path, version):
    written = write_sample_bag(tmp_path / "bag", n=6, version=version)
    mcap_file = tmp_path / "bag" / "bag_0.mcap"
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 12 and summary.chunk_indexes
        assert all(ci.message_index_offsets for ci in summary.chunk_indexes)  # message indexes written
        got = list(reader.iter_decoded_messages())
    assert [(c.topic, m.log_time, m.data) for _, c, m, _ in got] == written
    for schema, channel, message, decoded in got:
        assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
        assert "offered_qos_profiles" in channel.metadata and "topic_type_hash" in channel.metadata
        if channel.topic == "/cam/image":
            ref = deserialize_message(message.data, Image)
            assert (decoded.height, decoded.width, decoded.encoding) == (ref.height, ref.width, ref.encoding)
            assert bytes(decoded.data) == bytes(ref.data)
            assert decoded.header.frame_id == ref.header.frame_id
            assert decoded.header.stamp.sec == ref.header.stamp.sec
        else:
            ref = deserialize_message(message.data, JointState)
            assert list(decoded.name) == list(ref.name)
            assert list(decoded.position) == pytest.approx(list(ref.position))


@pytest.mark.parametrize("version", [9, 8])
def test_our_bag_reads_with_rosbags(tmp_path, version):
    bag = tmp_path / "bag"
    images = [TS.serialize_cdr(_rosbags_image(i), "sensor_msgs/msg/Image") for i in range(5)]
    joints = [TS.serialize_cdr(_rosbags_joint(i), "sensor_msgs/msg/JointState") for i in range(5)]
    with BagWriter(bag, version=version) as w:
        w.add_topic("/img", "sensor_msgs/msg/Image")
        w.add_topic("/js", "sensor_msgs/msg/JointState", qos=[QOS_LATCHED])
        for i in range(5):
            w.write("/img", bytes(images[i]), 1000 + 10 * i)
            w.write("/js", bytes(joints[i]), 1001 + 10 * i)
    with RosbagsReader(bag) as r:
        assert r.message_count == 10
        conns = {c.topic: c for c in r.connections}
        assert conns["/js"].ext.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL
        assert conns["/js"].ext.offered_qos_profiles[0].depth == 1
        assert conns["/img"].ext.offered_qos_profiles[0].durability == QosDurability.VOLATILE
        seen = []
        for conn, t, raw in r.messages():
            msg = TS.deserialize_cdr(raw, conn.msgtype)
            i = (t - 1000) // 10
            if conn.topic == "/img":
                assert bytes(msg.data) == bytes(_rosbags_image(i).data) and msg.header.frame_id == f"f{i}"
            else:
                assert list(msg.position) == [float(i), -float(i)]
            seen.append(t)
    assert seen == sorted(seen) and len(seen) == 10


def _rosbags_image(i):
    import numpy as np

    Image_ = TS.types["sensor_msgs/msg/Image"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    return Image_(header=Header(stamp=Time(sec=i, nanosec=7), frame_id=f"f{i}"), height=1, width=4,
                  encoding="mono8", is_bigendian=0, step=4, data=np.arange(i, i + 4, dtype=np.uint8))


def _rosbags_joint(i):
    import numpy as np

    JS = TS.types["sensor_msgs/msg/JointState"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    return JS(header=Header(stamp=Time(sec=i, nanosec=0), frame_id=""), name=["a", "b"],
              position=np.array([float(i), -float(i)]), velocity=np.array([], dtype=np.float64),
              effort=np.array([], dtype=np.float64))


def test_we_read_mcap_ros2_writer_bag(tmp_path):
    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        w = McapRos2Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/JointState", msgdef_for("sensor_msgs/msg/JointState")[0])
        for i in range(7):
            w.write_message("/js", schema, {"header": {"stamp": {"sec": i, "nanosec": 0}, "frame_id": "w"},
                                            "name": ["a"], "position": [float(i)], "velocity": [], "effort": []},
                            log_time=500 + i, publish_time=400 + i)
        w.finish()
    with BagReader(path) as r:
        assert r.version is None and r.notes == []
        assert r.topics["/js"].type == "sensor_msgs/msg/JointState" and r.topics["/js"].message_count == 7
        assert r.topics["/js"].offered_qos == ()  # mcap_ros2 records no QoS
        msgs = list(r.messages())
    assert [m.log_time_ns for m in msgs] == list(range(500, 507))
    assert [m.publish_time_ns for m in msgs] == list(range(400, 407))
    assert [deserialize_message(m.data, JointState).position[0] for m in msgs] == [float(i) for i in range(7)]


@pytest.mark.parametrize("version", [9, 8])
def test_we_read_rosbags_writer_bag(tmp_path, version):
    bag = tmp_path / "rb"
    latched = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                  QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)
    best = Qos(QosHistory.KEEP_LAST, 3, QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
               QosTime(1, 2), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)
    with RosbagsWriter(bag, version=version, storage_plugin=StoragePlugin.MCAP) as w:
        c1 = w.add_connection("/js", "sensor_msgs/msg/JointState", typestore=TS, offered_qos_profiles=[latched])
        c2 = w.add_connection("/img", "sensor_msgs/msg/Image", typestore=TS, offered_qos_profiles=[best])
        for i in range(4):
            w.write(c2, 2000 + 10 * i, TS.serialize_cdr(_rosbags_image(i), "sensor_msgs/msg/Image"))
            w.write(c1, 2005 + 10 * i, TS.serialize_cdr(_rosbags_joint(i), "sensor_msgs/msg/JointState"))
    with BagReader(bag) as r:
        assert r.version == version and r.notes == []
        assert r.message_count == 8 and r.start_ns == 2000 and r.end_ns == 2035
        js, img = r.topics["/js"], r.topics["/img"]
        assert js.latched and js.offered_qos[0].depth == 1 and js.offered_qos[0].liveliness == "automatic"
        assert img.offered_qos[0].reliability == "best_effort" and img.offered_qos[0].deadline == (1, 2)
        assert img.message_count == 4
        msgs = list(r.messages())
        assert "MSG: std_msgs/Header" in r.msgdef("sensor_msgs/msg/Image")
    assert [m.log_time_ns for m in msgs] == [2000, 2005, 2010, 2015, 2020, 2025, 2030, 2035]
    decoded = [deserialize_message(m.data, Image) for m in msgs if m.topic == "/img"]
    assert [bytes(d.data) for d in decoded] == [bytes(range(i, i + 4)) for i in range(4)]


def test_rclpy_image_bytes_survive_unchanged(tmp_path):
    from rclpy.serialization import serialize_message

    data = [serialize_message(image_msg(i)) for i in range(3)] + [serialize_message(joint_msg(0))]
    with BagWriter(tmp_path / "bag", compression="lz4") as w:
        w.add_topic("/a", "sensor_msgs/msg/Image")
        w.add_topic("/b", "sensor_msgs/msg/JointState")
        for i, d in enumerate(data):
            w.write("/a" if i < 3 else "/b", d, i)
    with BagReader(tmp_path / "bag") as r:
        assert [m.data for m in r.messages()] == data
