"""The launcher: YAML launch files, node processes over DDS, respawn, signals, single process."""
from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

import pytest

from isa_mocap_ros.bag import BagReader
from isa_mocap_ros.launcher import LaunchError, NodeSpec, Supervisor, load_launch_file
from bagfactory import write_test_bag

CLI = ["-m", "isa_mocap_ros.cli.main"]


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _replay_launch(tmp_path: Path, bag: Path, out: Path, *, player_extra: str = "") -> Path:
    params = _write(tmp_path / "params.yaml", f"""
/test/recorder:
  ros__parameters:
    output: {out}
    topics: ['/test/mocap/*']
/test/player:
  ros__parameters:
    bag: {bag}
    wait_for_subscribers_s: 20.0
    remap: ['/mocap/cam0/image_raw:=/test/mocap/cam0/image_raw']
    topics: ['/mocap/cam0/image_raw']
{player_extra}
""")
    return _write(tmp_path / "test.launch.yaml", f"""
launch:
- arg: {{name: params, default: "{params}"}}
- node: {{pkg: isa_mocap_ros, exec: recorder_node, name: recorder, namespace: /test,
          param: [{{from: "$(var params)"}}]}}
- node: {{pkg: isa_mocap_ros, exec: player_node, name: player, namespace: /test,
          param: [{{from: "$(var params)"}}]}}
""")


def test_parse_launch_file_args_substitutions_and_errors(tmp_path):
    params = _write(tmp_path / "p.yaml", "{}\n")
    f = _write(tmp_path / "a.launch.yaml", f"""
launch:
- arg: {{name: p, default: "{params}"}}
- arg: {{name: ns, default: /mocap}}
- node: {{pkg: isa_mocap_ros, exec: camera_node, namespace: "$(var ns)", respawn: "true",
          param: [{{from: "$(var p)"}}, {{name: fps, value: 15.0}}], remap: [{{from: a, to: b}}]}}
""")
    (spec,) = load_launch_file(f, {"ns": "/x"})
    assert spec.name == "camera" and spec.namespace == "/x" and spec.respawn
    assert spec.module == "isa_mocap_ros.nodes.camera"
    cmd = spec.command("py")
    assert cmd[:3] == ["py", "-m", "isa_mocap_ros.nodes.camera"]
    assert ["--params-file", str(params)] == cmd[cmd.index("--params-file"):cmd.index("--params-file") + 2]
    assert "fps:=15.0" in cmd and "a:=b" in cmd and "__ns:=/x" in cmd
    with pytest.raises(LaunchError, match="unknown launch arguments \\['nope'\\]"):
        load_launch_file(f, {"nope": "1"})
    bad = _write(tmp_path / "b.launch.yaml", "launch:\n- node: {pkg: other_pkg, exec: x}\n")
    with pytest.raises(LaunchError, match="only pkg 'isa_mocap_ros'"):
        load_launch_file(bad)
    with pytest.raises(LaunchError, match="var missing"):
        load_launch_file(_write(tmp_path / "c.launch.yaml",
                                "launch:\n- node: {exec: x_node, namespace: $(var missing)}\n"))
    with pytest.raises(LaunchError, match="does not exist"):
        load_launch_file(_write(tmp_path / "d.launch.yaml",
                                "launch:\n- node: {exec: x_node, param: [{from: /no/such.yaml}]}\n"))


def test_package_launch_files_parse():
    from isa_mocap_ros.resources import resource_dir
    files = sorted(resource_dir("launch").glob("*.launch.yaml"))
    assert files, "the package ships launch files"
    for f in files:
        for spec in load_launch_file(f):
            assert Path(sys.modules["isa_mocap_ros"].__file__).parent.joinpath(
                "nodes", spec.module.rsplit(".", 1)[1] + ".py").exists(), spec


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_launch_runs_nodes_as_processes_and_sigint_shuts_down_cleanly(spawn, tmp_path):
    bag = tmp_path / "bag"
    write_test_bag(bag, views=1, frames=6)
    out = tmp_path / "rec"
    lf = _replay_launch(tmp_path, bag, out)
    launch = spawn("launch", *CLI, "launch", str(lf))
    assert launch.wait_for_output("played 6 messages", 60), launch.output()
    assert launch.wait_for_output("[launch] player exited with code 0", 10), launch.output()
    time.sleep(1.0)
    assert launch.stop(signal.SIGINT, timeout=30) == 0, launch.output()
    text = launch.output()
    assert "[recorder-" in text and "closed" in text, text
    with BagReader(out) as r:
        assert r.topics["/test/mocap/cam0/image_raw"].message_count == 6


@pytest.mark.ros
@pytest.mark.timeout(60)
def test_crashed_node_is_respawned(tmp_path, rosenv):
    lines: list[str] = []
    spec = NodeSpec(exec="player_node", name="player", params=(("bag", str(tmp_path / "missing")),),
                    respawn=True, respawn_delay_s=0.2)
    sup = Supervisor([spec], env=rosenv, out=lines.append)
    import threading
    t = threading.Thread(target=sup.run)
    t.start()
    deadline = time.monotonic() + 40
    while sup.children[0].restarts < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    sup.stop()
    t.join(30)
    assert sup.children[0].restarts >= 2, lines
    assert any("respawning" in line for line in lines)
    assert any("found nothing at this path" in line for line in lines), lines
    assert all(rc != 0 for rc in sup.children[0].exit_codes)


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_single_process_mode(spawn, tmp_path):
    bag = tmp_path / "bag"
    write_test_bag(bag, views=1, frames=5)
    out = tmp_path / "rec"
    lf = _replay_launch(tmp_path, bag, out)
    launch = spawn("launch", *CLI, "launch", str(lf), "--single-process")
    assert launch.wait_for_output("played 5 messages", 60), launch.output()
    time.sleep(1.0)
    assert launch.stop(signal.SIGINT, timeout=30) == 0, launch.output()
    assert "started in-process" in launch.output()
    with BagReader(out) as r:
        assert r.topics["/test/mocap/cam0/image_raw"].message_count == 5


def test_composed_spec_carries_its_members_as_json():
    from isa_mocap_ros.cli.compose import main as compose_main

    a = NodeSpec(exec="segmentation_node", name="segmentation", namespace="/mocap", params_files=("p.yaml",),
                 params=(("views", "4"),), remaps=(("cam0/mask", "/m"),), nice=3)
    b = NodeSpec(exec="estimator_node", name="estimator", namespace="/mocap")
    both = NodeSpec(exec="compose", name="mocap_nodes", members=(a, b))
    cmd = both.command("python")
    assert cmd[:3] == ["python", "-m", "isa_mocap_ros.cli.compose"]
    import json
    assert [NodeSpec.from_json(d) for d in json.loads(cmd[3])] == [a, b]
    with pytest.raises(LaunchError, match="mocap_nodes: a composed spec"):
        both.to_json()
    assert compose_main(["not json"]) == 2 and compose_main([]) == 2
