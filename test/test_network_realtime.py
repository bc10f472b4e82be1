"""The node network in real time on the capsule demo: `isa-mocap run` (no --lockstep) on the bag that was
`bags/demo` until issue 32 (`synth walk_turns --empty-frames 10 --duration-s 4.5 --seed 0 --body capsules`,
rendered here: the shipped demo is now a mesh body, on which the initialized heading is right and the
check below has nothing to switch).

The automatic initialization takes several frame periods, and in real time the sets arriving meanwhile
would be dropped; the heading check that follows it decides on consecutive frames only. On
`bags/demo` with seed 0 the initialized frame's winner faces backwards (0.0690 vs 0.0711 for the right
heading), and without consecutive frames the check could not decide: the whole run was lost (310 mm,
measured twice). The estimator holds the sets that follow the initialized one (`LatestSlot.hold`)
while the check runs, so it switches as in lockstep. Since session 17 the initialization's polish
(`init_polish`) mends that first frame itself (the polished rival fits better: 8.8 mm in real time), so
this test turns it off to keep the check in real time under test.

Which set is initialized depends on the machine's load: the first sets with the person come bunched after the
segmentation's last learning set, and the estimator takes the newest. On frame 10 (an idle machine) the winner
faces backwards and the check switches; in a clean-clone run beside the other test worker (session 33) it was
frame 16, whose winner faces the right way, and no check started (its rival's energy was not close enough). So
this test starts the check on whatever frame comes first (`init_confirm_ratio` 10: every rival is close enough)
and requires it to decide right: switching where the winner faces backwards, keeping it where not. It is judged
on the sets the check held and decided on (the initialized one and the N of "energy sums over N frame(s)"; after a
switch only the decision's set, the ones before it were published facing the other way): a wrong heading puts them
200-300 mm off, a right one within 60 mm. The rest of the run is not this test's: in session 34's
second clean clone the check kept the right heading (20, 10 mm) and then, beside the other test worker, one 340 ms step
took the budget to its last level and the track drifted (135 mm over the run); how the network keeps a track under
load is `bench speed`'s (issue 35). The switch itself on held consecutive sets is tested without a clock in
test_realtime_schedule.py (a track facing backwards under load).
"""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(600)]
REPO = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "isa_mocap_ros.cli.main"]
#: `isa-mocap track bags/demo` (default settings, 135 frames) on the machine this test's bounds were
#: measured on (session 17's `make bench`: 24.4 frames/s)
REFERENCE_FPS = 24.4


@pytest.fixture(scope="module")
def capsule_demo(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("demo") / "capsule_demo"
    res = subprocess.run(CLI + ["synth", "walk_turns", str(out), "--empty-frames", "10", "--duration-s", "4.5",
                                "--seed", "0", "--body", "capsules", "--no-progress"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return out


def replay_rate(tmp_path: Path, env: dict, bag: Path) -> float:
    """The replay rate that loads this machine as real time (rate 1) loaded the reference machine.

    The test is about the estimator's hold in real time, not about the machine's speed: session 18's
    machine tracked 2.5x slower (9.6 frames/s offline), dropped ~90 of 145 sets at rate 1 and lost
    the track in 2 runs of 6 (56-130 mm; at the commit before, 88 mm in 3 of 3). So the bag is replayed
    at ``min(1, fps / REFERENCE_FPS)``, with ``fps`` measured here with `isa-mocap track`."""
    out = tmp_path / "speed"
    res = subprocess.run(CLI + ["track", str(bag), "--out", str(out), "--seed", "0", "--no-progress", "--shape", "truth"],
                         env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    fps = json.loads((out / "summary.json").read_text())["fps"]
    return min(1.0, fps / REFERENCE_FPS)


def test_real_time_run_checks_the_first_heading_on_held_sets(tmp_path, rosenv, capsule_demo):
    out = tmp_path / "rt"
    # the default parameters but init_polish; the contour stage on: it makes a set ~18 ms dearer, and without
    # the estimator's catch_up_ms (sets that waited tracked without it) the drops lost the track beside the other
    # test worker (122 mm in session 16's clean-clone run)
    params = tmp_path / "pipeline.yaml"
    text = (REPO / "config" / "pipeline.yaml").read_text()
    assert "init_polish: true" in text and "energy: raster" in text and "startup_catch_up: 0 " in text
    assert "    init_confirm_frames: 3 " in text
    # and the sampled energy: with the scanline count (the default since decision 017) this bag's seed-0
    # initialization faces the right way (heading check: kept, 0.0502 vs 0.0600), leaving nothing to mend.
    # And the start-up's sets caught up (startup_catch_up 12, off by default): without it the sets that come
    # during the initialization and the check are dropped, and after the switch the tracker crosses a gap of
    # 11-20 frames; beside a busy core (rate 0.7, a busy loop: CI's one failure, 131 mm) a gap of 15 or more lost
    # the legs' side for the rest of the run in 3 of 8 runs (94-108 mm; root and heading right), an open issue-35
    # defect of the gap, not of the check (docs/history/issue35_speed.md, session 33 (lead)); with it 8 of 8 held.
    # Session 34's side check after a long gap (frame_prediction.side_check) kept the legs' side in 20 of 21 emulated
    # gaps (tools/gap_legs.py), but the default 0 here is not proven in real time yet: beside a busy loop on that
    # session's loaded machine the network dropped 101-121 of 145 sets whatever the gap did (history, session 34)
    params.write_text(text.replace("init_polish: true", "init_polish: false").replace("energy: raster", "energy: fast")
                      .replace("startup_catch_up: 0 ", "startup_catch_up: 12 ")
                      .replace("    init_confirm_frames: 3 ", "    init_confirm_ratio: 10.0\n    init_confirm_frames: 3 "))
    rate = replay_rate(tmp_path, rosenv, capsule_demo)
    res = subprocess.run(CLI + ["run", str(capsule_demo), "--out", str(out), "--seed", "0", "--shape", "default",
                                "--params", str(params), "--rate", f"{rate:.3f}"],
                         env=rosenv, capture_output=True, text=True, timeout=500)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    # the heading check's start and decision are expected events: INFO, in the nodes' log (run echoes WARN/ERROR)
    log = (out / "nodes.log").read_text()
    assert "heading check started" in log and "heading check decided: " in log, log[-3000:]
    s = json.loads((out / "summary.json").read_text())
    # measured over the whole run: 24.5 / 25.4 mm (4-11 sets dropped) on an idle machine; lost for good without the
    # hold: 310 mm
    # (on failure, the whole summary and the lines that say why a track goes: where each view's background was
    # learnt, the initialization, the heading check, the budget's changes)
    why = [line for line in log.splitlines() if re.search(r"background learnt|budget|lost|heading check|initiali", line)]
    # the initialized set (0) and the sets the check held (1..N), published as they came: the decision's set (N) faces
    # the heading decided; after a switch the sets before it were published facing the other way (said in the log)
    decided = re.search(r"heading check decided: (kept|switched) .*energy sums over (\d+) frame", log)
    held = int(decided.group(2))
    errs = s["frame_errors_mm"][:1 + held]
    judged = errs if decided.group(1) == "kept" else errs[-1:]
    assert len(errs) == 1 + held and max(judged) < 60.0, json.dumps(s, indent=0) + "\n" + "\n".join(why[-40:])
    # the start-up's drops (initialization + heading check) are counted within all the drops; whether there
    # are any depends on the machine (a replay slowed to this machine's speed, rate 0.21 on a loaded one,
    # dropped none), so their count is checked by test_run_report's _first_gap test, not here
    assert 0 <= s["dropped_while_initializing"] <= s["dropped_frames"], s
    # sets that waited for the tracker went without the contour stage (27-88 of 145 on an idle machine, session 17)
    assert 0 <= s["frames_without_contour_stage"] <= s["frames_processed"], s
