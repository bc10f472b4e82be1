"""SIGKILL during recording, then repair; and the ``isa-mocap bag info|repair`` CLI."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from isa_mocap_ros.bag import BagError, BagReader, repair_bag
from isa_mocap_ros.cli.main import main
from test_bag_common import write_sample_bag

N_FLUSHED = 30
N_UNFLUSHED = 7

_CHILD = textwrap.dedent("""
    import os, sys
    from isa_mocap_ros.bag import BagWriter, QOS_LATCHED
    path, version, compression = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    w = BagWriter(path, version=version, compression=compression, chunk_size=1 << 20)
    w.add_topic("/data", "std_msgs/msg/UInt32")
    w.add_topic("/latched", "std_msgs/msg/String", qos=[QOS_LATCHED])
    for i in range({flushed}):
        w.write("/data", b"\\x00\\x01\\x00\\x00" + i.to_bytes(4, "little"), 1000 + i)
        if i % 10 == 9:
            w.write("/latched", b"\\x00\\x01\\x00\\x00\\x02\\x00\\x00\\x00x\\x00\\x00\\x00", 1000 + i)
            w.flush()
    for i in range({flushed}, {flushed} + {unflushed}):
        w.write("/data", b"\\x00\\x01\\x00\\x00" + i.to_bytes(4, "little"), 1000 + i)
    print("killing", flush=True)
    os.kill(os.getpid(), 9)
""").format(flushed=N_FLUSHED, unflushed=N_UNFLUSHED)


def _killed_bag(tmp_path, *, version=9, compression="zstd"):
    bag = tmp_path / "rec"
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(bag), str(version), compression],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert "killing" in proc.stdout
    assert not (bag / "metadata.yaml").exists()
    return bag


def _values(reader):
    return [int.from_bytes(m.data[4:8], "little") for m in reader.messages(["/data"])]


@pytest.mark.parametrize("version, compression", [(9, "zstd"), (8, "lz4"), (9, "none")])
def test_sigkill_then_repair(tmp_path, version, compression):
    bag = _killed_bag(tmp_path, version=version, compression=compression)
    mcap = bag / "rec_0.mcap"
    with open(mcap, "rb") as f:  # the killed file has no footer: mcap's indexed reader refuses it
        with pytest.raises(McapError):
            make_reader(f).get_summary()
    with BagReader(bag) as r:  # readable before repair, with notes
        assert _values(r) == list(range(N_FLUSHED))
        assert any("metadata.yaml is missing" in n for n in r.notes)
    report = repair_bag(bag)
    assert report["messages"] >= N_FLUSHED + 3  # the 3 latched flushed too
    assert report["topics"] == {"/data": N_FLUSHED, "/latched": 3}
    assert report["dropped_bytes"] == 0 and report["rewritten"] == ["rec_0.mcap"] and report["metadata_written"]
    assert not list(bag.glob("*.tmp"))
    with BagReader(bag) as r:
        assert r.notes == [] and r.indexed and r.version == version
        assert _values(r) == list(range(N_FLUSHED))
        assert r.topics["/latched"].latched and r.topics["/latched"].message_count == 3
    with open(mcap, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary.statistics.message_count == N_FLUSHED + 3 and summary.chunk_indexes
        assert [m.log_time for _, c, m in reader.iter_messages(topics=["/data"])] == [1000 + i for i in range(N_FLUSHED)]
    again = repair_bag(bag)  # idempotent: a complete bag is left alone
    assert again["rewritten"] == [] and not again["metadata_written"] and again["messages"] == N_FLUSHED + 3


def test_repair_torn_tail_counts_dropped_bytes(tmp_path):
    bag = _killed_bag(tmp_path)
    mcap = bag / "rec_0.mcap"
    good = mcap.read_bytes()
    # a torn trailing chunk: the first 50 bytes of a valid chunk record from another bag
    write_sample_bag(tmp_path / "other", n=3)
    with open(tmp_path / "other" / "other_0.mcap", "rb") as f:
        ci = make_reader(f).get_summary().chunk_indexes[0]
        f.seek(ci.chunk_start_offset)
        torn = f.read(50)
    mcap.write_bytes(good + torn)
    report = repair_bag(bag)
    assert report["dropped_bytes"] == 50
    assert report["topics"]["/data"] == N_FLUSHED
    assert any("torn record" in n for n in report["notes"])
    assert mcap.stat().st_size > 0
    with BagReader(bag) as r:
        assert r.indexed and _values(r) == list(range(N_FLUSHED))


def test_repair_bare_mcap_and_errors(tmp_path):
    bag = _killed_bag(tmp_path)
    bare = tmp_path / "bare.mcap"
    bare.write_bytes((bag / "rec_0.mcap").read_bytes())
    report = repair_bag(bare)
    assert report["messages"] == N_FLUSHED + 3 and not report["metadata_written"]
    assert not (tmp_path / "metadata.yaml").exists()
    with BagReader(bare) as r:
        assert r.indexed and _values(r) == list(range(N_FLUSHED))
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match="repair expected .mcap files"):
        repair_bag(tmp_path / "empty")
    with pytest.raises(BagError, match="version: expected 8, 9 or None, received 7"):
        repair_bag(bag, version=7)


def test_cli_bag_info(tmp_path, capsys):
    written = write_sample_bag(tmp_path / "bag", n=5)
    assert main(["bag", "info", str(tmp_path / "bag")]) == 0
    out = capsys.readouterr().out
    assert "Messages:          10" in out and "Topic: /joint_states" in out and "latched" in out
    assert main(["bag", "info", "--json", str(tmp_path / "bag")]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["message_count"] == 10 and info["start_ns"] == written[0][1]
    assert main(["bag", "info", str(tmp_path / "missing")]) == 2
    assert "found nothing at this path" in capsys.readouterr().err


def test_cli_bag_repair(tmp_path, capsys):
    bag = _killed_bag(tmp_path)
    assert main(["bag", "repair", str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"recovered {N_FLUSHED + 3} messages on 2 topics, dropped 0 bytes" in out
    assert "rewrote rec_0.mcap; wrote metadata.yaml" in out
    assert main(["bag", "info", str(bag)]) == 0
    assert f"Messages:          {N_FLUSHED + 3}" in capsys.readouterr().out
    assert main(["bag", "repair", str(tmp_path / "nothing")]) == 2
