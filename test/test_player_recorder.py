"""Player and recorder as separate processes talking over DDS (real components, real MCAP bags)."""
from __future__ import annotations

import signal
import time
from collections import defaultdict
from pathlib import Path

import pytest

from isa_mocap_ros.bag import BagReader, repair_bag
from bagfactory import write_test_bag

pytestmark = [pytest.mark.ros, pytest.mark.timeout(180)]
HERE = Path(__file__).parent
CLI = ["-m", "isa_mocap_ros.cli.main"]


def _by_topic(path: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = defaultdict(list)
    with BagReader(path) as r:
        for m in r.messages():
            out[m.topic].append(m.data)
    return dict(out)


def _same_payload(sent: bytes, received: bytes) -> bool:
    """Equal bytes, up to the zero padding DDS appends to reach a multiple of 4 bytes (RTPS payloads)."""
    pad = received[len(sent):]
    return received[:len(sent)] == sent and len(received) % 4 == 0 and len(pad) < 4 and not any(pad) \
        if len(received) != len(sent) else received == sent


def _start_recorder(spawn, out: Path, *topics: str):
    args = [*CLI, "record", str(out)] + (["--topics", *topics] if topics else ["--all"])
    rec = spawn("recorder", *args)
    assert rec.wait_for_output("recording to", 30), rec.output()
    return rec


def test_play_then_record_keeps_every_message_byte_for_byte(spawn, tmp_path):
    src = tmp_path / "src"
    counts = write_test_bag(src, views=2, frames=15)
    out = tmp_path / "rec"
    rec = _start_recorder(spawn, out, "/mocap/*")
    player = spawn("player", *CLI, "play", str(src), "--rate", "2", "--wait-for-subscribers", "20")
    assert player.popen.wait(90) == 0, player.output()
    time.sleep(1.0)
    assert rec.stop(signal.SIGINT) == 0, rec.output()
    got, want = _by_topic(out), _by_topic(src)
    assert {t: len(v) for t, v in got.items()} == counts
    for topic, msgs in want.items():
        assert len(got[topic]) == len(msgs)
        for sent, recorded in zip(msgs, got[topic]):
            assert _same_payload(sent, recorded), f"bytes differ on {topic}"
    with BagReader(out) as r:
        latched = r.topics["/mocap/cam0/extrinsics"].offered_qos
        assert latched and latched[0].durability == "transient_local"
        assert r.topics["/mocap/cam0/image_raw"].offered_qos[0].durability == "volatile"
    assert "closed" in rec.output()


def test_lockstep_waits_for_the_echo_of_each_frame(spawn, tmp_path):
    src = tmp_path / "src"
    write_test_bag(src, views=1, frames=8)
    # the echo node also subscribes to the bag's other topics: the player waits for a subscriber on each
    echo = spawn("echo", str(HERE / "echo_node.py"), "/mocap/cam0/image_raw", "/echo", "0.15",
                 "/mocap/cam0/camera_info:CameraInfo", "/mocap/cam0/extrinsics:TransformStamped",
                 "/mocap/ground_truth/joint_states:JointState")
    assert echo.wait_for_output("echo ready", 30)
    # Played at 1000x real time: only the lockstep wait can keep frames apart.
    player = spawn("player", *CLI, "play", str(src), "--rate", "1000", "--lockstep", "/echo",
                   "--lockstep-timeout", "20", "--wait-for-subscribers", "20", "--json")
    assert player.popen.wait(90) == 0, player.output()
    assert '"lockstep_acks": 8' in player.output(), player.output()
    assert '"lockstep_timeouts": 0' in player.output()
    assert "no subscriber after" not in player.output(), player.output()     # it started once it saw the echo node
    time.sleep(0.5)
    events = [line.split() for line in echo.output().splitlines()
              if line.startswith(("image ", "echo ")) and len(line.split()) == 3]
    images = [(int(s), float(t)) for kind, s, t in events if kind == "image"]
    echoes = {int(s): float(t) for kind, s, t in events if kind == "echo"}
    assert len(images) == 8 and len(echoes) == 8, events
    # Causality: image k+1 reached the echo node only after the echo of frame k was published
    # (without lockstep all 8 images would arrive within milliseconds, well inside the 150 ms delay).
    for (stamp_k, _), (_, arrival_next) in zip(images, images[1:]):
        assert arrival_next >= echoes[stamp_k], (stamp_k, arrival_next, echoes[stamp_k])
    assert [s for s, _ in images] == sorted(s for s, _ in images)


def test_lockstep_timeout_is_logged_and_replay_goes_on(spawn, tmp_path):
    src = tmp_path / "src"
    write_test_bag(src, views=1, frames=3)
    player = spawn("player", *CLI, "play", str(src), "--lockstep", "/nobody", "--lockstep-timeout", "0.3",
                   "--json")
    assert player.popen.wait(60) == 0, player.output()
    out = player.output()
    assert '"lockstep_timeouts": 3' in out and '"messages": 10' in out, out
    assert "lockstep: no /nobody with stamp" in out


def test_recorder_sigkill_then_repair_recovers_flushed_messages(spawn, tmp_path):
    src = tmp_path / "src"
    counts = write_test_bag(src, views=2, frames=30)
    out = tmp_path / "rec"
    rec = _start_recorder(spawn, out, "/mocap/*")
    player = spawn("player", *CLI, "play", str(src), "--wait-for-subscribers", "20")
    assert player.popen.wait(90) == 0, player.output()
    time.sleep(2.5)  # > flush period: everything is on disk
    rec.stop(signal.SIGKILL)
    report = repair_bag(out)
    assert report["messages"] == sum(counts.values())
    got = _by_topic(out)
    assert {t: len(v) for t, v in got.items()} == counts
    from mcap.reader import make_reader
    mcap_file = next(out.glob("*.mcap"))
    with open(mcap_file, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == sum(counts.values())


def test_recorder_sigterm_closes_the_bag_cleanly(spawn, tmp_path):
    src = tmp_path / "src"
    write_test_bag(src, views=1, frames=5)
    out = tmp_path / "rec"
    rec = _start_recorder(spawn, out)  # --all
    player = spawn("player", *CLI, "play", str(src), "--wait-for-subscribers", "20")
    assert player.popen.wait(60) == 0
    time.sleep(1.0)
    assert rec.stop(signal.SIGTERM) == 0, rec.output()
    assert (out / "metadata.yaml").exists()
    with BagReader(out) as r:
        assert r.topics["/mocap/cam0/image_raw"].message_count == 5


def test_start_offset_clock_and_loop(spawn, tmp_path):
    src = tmp_path / "src"
    write_test_bag(src, views=1, frames=12, fps=30.0)
    out = tmp_path / "rec"
    rec = _start_recorder(spawn, out, "/clock", "/mocap/cam0/image_raw")
    # 0.2 s offset at 30 fps skips frames 0..5 (stamps up to 0.1667 s); --clock publishes the bag time.
    player = spawn("player", *CLI, "play", str(src), "--start-offset", "0.2", "--clock", "--topics",
                   "/mocap/cam0/image_raw", "--wait-for-subscribers", "20", "--json")
    assert player.popen.wait(60) == 0, player.output()
    time.sleep(1.0)
    rec.stop(signal.SIGINT)
    import msg_adapters as ma
    with BagReader(out) as r:
        stamps = [ma.header_stamp_ns_from_cdr(m.data) for m in r.messages(["/mocap/cam0/image_raw"])]
        clocks = [ma.stamp_to_ns(ma.from_cdr(m.data, m.type).clock) for m in r.messages(["/clock"])]
    from bagfactory import frame_stamps
    assert stamps == frame_stamps(12)[6:]
    assert clocks and set(clocks) <= set(frame_stamps(12)[6:]) and clocks == sorted(clocks)
    # --loop replays again from the start until stopped
    loop = spawn("loop", *CLI, "play", str(src), "--loop", "--rate", "10", "--topics", "/mocap/cam0/image_raw")
    # the bag lasts 0.04 s at rate 10: once played, the player says it loops, and keeps running
    assert loop.wait_for_output("replaying it from the start", 60), loop.output()
    time.sleep(1.0)
    assert loop.popen.poll() is None, loop.output()       # still running: it loops
    assert loop.stop(signal.SIGINT, timeout=20) in (0, 1), loop.output()   # Ctrl-C ends it cleanly
    assert "Traceback" not in loop.output()
