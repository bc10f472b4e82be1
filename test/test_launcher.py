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


def _camera_network(tmp_path: Path, *, camera_fps: str | None, launch_period: str | None = None) -> Path:
    fps_line = f"    fps: {camera_fps}\n" if camera_fps is not None else ""
    params = _write(tmp_path / "params.yaml", f"""
/mocap/camera:
  ros__parameters:
    source: synthetic
    views: 1
    width: 80
    height: 60
{fps_line}/mocap/prediction:
  ros__parameters:
    frame_period_s: 0.03333333333333333
/mocap/estimator:
  ros__parameters:
    frame_period_s: 0.03333333333333333
""")
    extra = f", param: [{{from: \"{params}\"}}, {{name: frame_period_s, value: {launch_period}}}]" if launch_period \
        else f", param: [{{from: \"{params}\"}}]"
    return _write(tmp_path / "cam.launch.yaml", f"""
launch:
- node: {{pkg: isa_mocap_ros, exec: camera_node, name: camera, namespace: /mocap, param: [{{from: "{params}"}}]}}
- node: {{pkg: isa_mocap_ros, exec: prediction_node, name: prediction, namespace: /mocap{extra}}}
- node: {{pkg: isa_mocap_ros, exec: estimator_node, name: estimator, namespace: /mocap, param: [{{from: "{params}"}}]}}
""")


def test_launch_gives_the_camera_frame_period_to_prediction_and_estimator(tmp_path):
    from isa_mocap_ros.cli.launch import with_camera_frame_period

    specs, line = with_camera_frame_period(load_launch_file(_camera_network(tmp_path, camera_fps="60.0")))
    period = {s.name: dict(s.params).get("frame_period_s") for s in specs}
    assert period == {"camera": None, "prediction": repr(1 / 60), "estimator": repr(1 / 60)}, period
    assert "camera at 60 fps" in line and "prediction (was 0.033333)" in line
    # the camera's default rate (30) matches the files: nothing changes
    specs, line = with_camera_frame_period(load_launch_file(_camera_network(tmp_path, camera_fps=None)))
    assert line is None and all("frame_period_s" not in dict(s.params) for s in specs)
    # a period set on the node in the launch file is kept
    specs, _ = with_camera_frame_period(load_launch_file(_camera_network(tmp_path, camera_fps="60.0",
                                                                        launch_period="0.05")))
    assert dict(specs[1].params)["frame_period_s"] == "0.05" and dict(specs[2].params)["frame_period_s"] == repr(1 / 60)


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_launched_prediction_node_uses_the_camera_frame_period(spawn, tmp_path):
    """Real processes: the prediction node started by `isa-mocap launch` next to a 60 fps camera stamps its
    predictions 1/60 s ahead (its start-up line), not the parameter file's 1/30."""
    lf = _camera_network(tmp_path, camera_fps="60.0")
    text = lf.read_text().replace("- node: {pkg: isa_mocap_ros, exec: estimator_node", "# estimator left out: ")
    lf.write_text(text)
    launch = spawn("launch", *CLI, "launch", str(lf))
    assert launch.wait_for_output("stamps + 0.016667 s", 90), launch.output()
    assert launch.stop(signal.SIGINT, timeout=30) == 0, launch.output()


@pytest.mark.ros
@pytest.mark.timeout(90)
def test_a_launcher_killed_outright_takes_its_nodes_with_it(rosenv):
    """SIGKILL of the launching process (``subprocess.run(timeout=)`` of ``isa-mocap run`` in a test) left its nodes
    running on the test's ROS domain, where they answered the next test's network: they now get SIGTERM."""
    import os
    import re
    import subprocess

    script = ("import sys; from isa_mocap_ros.launcher import NodeSpec, Supervisor; "
              "Supervisor([NodeSpec(exec='prediction_node', name='prediction', namespace='/mocap')]).run()")
    parent = subprocess.Popen([sys.executable, "-c", script], env=rosenv, stdout=subprocess.PIPE, text=True)
    try:
        line = parent.stdout.readline()
        pid = int(re.search(r"\(pid (\d+)\)", line).group(1))
        deadline = time.monotonic() + 60            # the node up: its first line after the launch line
        while "prediction:" not in parent.stdout.readline() and time.monotonic() < deadline:
            pass
        parent.kill()
        parent.wait(10)

        def alive() -> bool:
            try:
                with open(f"/proc/{pid}/status") as f:
                    return "\nState:\tZ" not in f.read()
            except FileNotFoundError:
                return False
        deadline = time.monotonic() + 20
        while alive() and time.monotonic() < deadline:
            time.sleep(0.1)
        gone = not alive()
        if not gone:
            os.kill(pid, signal.SIGKILL)
        assert gone, "the node outlived its killed launcher"
    finally:
        if parent.poll() is None:
            parent.kill()
