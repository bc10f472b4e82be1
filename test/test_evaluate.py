"""``isa-mocap evaluate`` on a ``bags/fixture`` track result."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from isa_mocap_ros.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "bags" / "fixture"


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    out = tmp_path_factory.mktemp("evaluate") / "track"
    assert main(["track", str(FIXTURE), "--out", str(out), "--evals", "200", "--use-masks", "--no-progress", "--shape", "truth"]) == 0
    return out


def test_evaluate_track_directory(tracked, capsys):
    capsys.readouterr()
    assert main(["evaluate", str(tracked)]) == 0
    text = capsys.readouterr().out
    for head in ("per sequence:", "per joint: mean error (mm)", "per DOF: joint-angle RMSE (deg), knees first",
                 "per frame: Eq. 20 error"):
        assert head in text
    ev = json.loads((tracked / "evaluation.json").read_text())
    s = json.loads((tracked / "summary.json").read_text())
    # the same numbers as the tracker's own summary
    assert ev["sequence"]["frames"] == s["frames"]
    assert ev["sequence"]["mpjpe_mm"] == pytest.approx(s["mpjpe_mm"], rel=1e-9)
    assert ev["sequence"]["knee_rmse_deg"] == pytest.approx(s["knee_rmse_deg"], rel=1e-9)
    # Eq. 20 is the mean over markers of the per-marker mean errors
    assert np.mean(list(ev["per_marker_mm"].values())) == pytest.approx(s["mpjpe_mm"], rel=1e-9)
    assert list(ev["per_dof_rmse_deg"])[:2] == ["left_knee_y", "right_knee_y"]
    assert [f["error_mm"] for f in ev["per_frame"]] == s["frame_errors_mm"]
    assert (tracked / "knees_and_error.png").stat().st_size > 1000
    # the track summary's per-frame energies (ISA Fig. 13.14: energy and error over time)
    assert len(s["frame_energies"]) == len(s["frame_stamps_ns"]) == s["frames_estimated"]
    assert ev["energy"]["source"].startswith("per frame") and len(ev["energy"]["energy"]) == s["frames"]
    assert ev["energy"]["energy"] == pytest.approx([e for e in s["frame_energies"]])
    assert (tracked / "energy_and_error.png").stat().st_size > 1000


def test_evaluate_estimates_bag_with_truth_and_energies(tracked, tmp_path, capsys):
    res = tmp_path / "copy"
    shutil.copytree(tracked, res)
    s = json.loads((res / "summary.json").read_text())
    s["frame_energies"] = [0.1 * (i + 1) for i in range(s["frames"])]
    (res / "summary.json").write_text(json.dumps(s))
    out = tmp_path / "ev"
    assert main(["evaluate", str(res), "--out", str(out), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["energy"]["energy"] == s["frame_energies"]
    assert (out / "energy_and_error.png").is_file() and (out / "evaluation.json").is_file()
    # estimates bag alone plus --truth
    out2 = tmp_path / "ev2"
    assert main(["evaluate", str(res / "estimates"), "--truth", str(FIXTURE), "--out", str(out2), "--model", "39",
                 "--shape", "truth", "--no-plots"]) == 0
    ev2 = json.loads((out2 / "evaluation.json").read_text())
    assert ev2["sequence"]["mpjpe_mm"] == pytest.approx(ev["sequence"]["mpjpe_mm"])
    assert ev2["plots"] == []


def test_evaluate_bad_input(tracked, tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "nope")]) == 2
    assert main(["evaluate", str(tracked / "estimates")]) == 2          # no --truth, no summary
    err = capsys.readouterr().err
    assert "no such path" in err and "--truth" in err
