"""``isa-mocap bench robustness --quick``: the ISA §13.4.2 conditions end to end, and the target checks."""
import json

import numpy as np
import pytest

from isa_mocap_ros.bench import robustness as br
from isa_mocap_ros.cli.main import main
from isa_mocap_ros.tracking import TrackerConfig


def test_quick_json(tmp_path, capsys):
    cache = tmp_path / "cache"
    assert main(["bench", "robustness", "--quick", "--json", "--cache", str(cache), "--out", str(tmp_path / "o")]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [c["condition"] for c in res["conditions"]] == ["clean", "noise50", "noise70", "occluders35"]
    assert [c["paper_knee_rmse_deg"] for c in res["conditions"]] == [2.74, 2.97, 4.51, 5.21]
    assert res["design"]["seeds"] == [0] and res["design"]["gate_margin_px"] is None
    for r in res["runs"]:
        assert r["sequence"] == "walk" and r["frames"] == 5          # 6 frames, the ground-truth first one not scored
        assert r["seed"] == 0 and r["gate_margin_px"] == TrackerConfig().masks.gate_margin_px   # the tracker's default
        assert np.isfinite(r["knee_rmse_deg"]) and np.isfinite(r["mpjpe_mm"])
        assert len(r["knee_est_deg"]) == len(r["t_s"]) == r["frames"]
    # one cached bag per condition, tracked with `isa-mocap track`'s code (its summary.json is there)
    assert len([p for p in cache.iterdir() if (p / "metadata.yaml").is_file()]) == 4
    assert all((tmp_path / "o" / p.name / "summary.json").is_file() for p in cache.iterdir() if p.is_dir())
    # the shape calibrated once per bag, every run tracked with it
    assert len(res["calibrations"]) == 4 and all(r["shape"].endswith(".yaml") for r in res["runs"])
    assert "calibrated once per bag" in br.render_markdown(res)
    assert {t["condition"] for t in res["targets"]} == {"clean", "noise70", "occluders35"}
    md = br.render_markdown(res)
    assert "70 % pixel noise" in md and "4.51°" in md


def test_targets_from_numbers():
    runs = [{"sequence": "walk", "condition": "clean", "mpjpe_mm": 20.0, "knee_rmse_deg": 1.5},
            {"sequence": "cmu_walk", "condition": "clean", "mpjpe_mm": 30.0, "knee_rmse_deg": 1.9},
            {"sequence": "jog", "condition": "clean", "mpjpe_mm": 90.0, "knee_rmse_deg": 9.0},
            {"sequence": "walk", "condition": "noise70", "mpjpe_mm": 25.0, "knee_rmse_deg": 3.4},
            {"sequence": "cmu_walk", "condition": "noise70", "mpjpe_mm": 25.0, "knee_rmse_deg": 3.0}]
    t = {(x["condition"], x["measure"]): x for x in br.check_targets(runs)}
    assert not t[("clean", "mpjpe_mm")]["met"]                # the CMU walk misses 25 mm
    assert t[("clean", "knee_rmse_deg")]["met"]                 # the jog is not a walk: not part of the target
    assert t[("noise70", "knee_rmse_deg")]["met"]
    assert ("occluders35", "knee_rmse_deg") not in t            # not run: not claimed
    d = br.make_design("default", cmu_path=None)
    assert [s.name for s in d.sequences] == ["walk", "jog"] and "CMU walk skipped" in d.notes[0]


def test_seeds_are_summarized_with_their_spread():
    runs = [{"sequence": "walk", "condition": "clean", "seed": s, "mpjpe_mm": e, "knee_rmse_deg": k}
            for s, e, k in ((0, 20.0, 4.0), (1, 26.0, 6.0), (2, 23.0, 5.0))]
    runs += [{"sequence": "jog", "condition": "clean", "seed": 0, "mpjpe_mm": 60.0, "knee_rmse_deg": 12.0}]
    (c,) = br.summarize_conditions(runs)
    w = c["per_sequence"]["walk"]
    assert w["mpjpe_mm"] == 23.0 and w["knee_rmse_deg"] == 5.0 and w["seeds"] == [0, 1, 2]
    assert (w["mpjpe_mm_min"], w["mpjpe_mm_max"]) == (20.0, 26.0) and abs(w["mpjpe_mm_se"] - np.sqrt(3)) < 1e-12
    assert c["per_sequence"]["jog"]["knee_rmse_deg_se"] == 0.0
    assert c["mpjpe_mm"] == (23.0 + 60.0) / 2                  # mean over sequences of the per-sequence means
    (t,) = [t for t in br.check_targets(runs) if t["measure"] == "mpjpe_mm"]
    assert t["values"] == {"walk": 23.0} and t["met"]          # targets on the mean over the seeds
    d = br.make_design("default", cmu_path=None)
    assert d.seeds == br.DEFAULT_SEEDS == tuple(range(8)) and d.seed == 0 and d.gate_margin_px is None
    assert d.shape == "auto" and br.make_design("quick", shape="truth").calib == ()
    q = br.make_design("quick", seeds=(4, 5), gate_margin_px=0)
    assert q.seeds == (4, 5) and q.seed == 4 and q.gate_margin_px == 0 and br.make_design("quick").seeds == (0,)
    for bad in ({"shape": "default"}, {"seeds": ()}, {"seeds": (1, 1)}, {"seeds": (-1,)}, {"gate_margin_px": -2}, {"gate_margin_px": 1.5}):
        with pytest.raises(ValueError):
            br.make_design("quick", **bad)
    md = br.render_markdown({"design": d.to_dict(), "runs": [dict(r, frames=10, max_frame_error_mm=1.0, fps=5.0,
                                                                  frames_fell_back=0) for r in runs],
                             "conditions": [c], "seconds": 1.0})
    assert "seeds 0, 1, 2, 3, 4, 5, 6, 7 (mean, min-max)" in md and "5.00° (4.0-6.0) / 23.0 (20-26)" in md


def test_seeds_and_gate_from_the_command_line(tmp_path, capsys):
    args = ["bench", "robustness", "--quick", "--json", "--cache", str(tmp_path / "c"), "--out", str(tmp_path / "o")]
    assert main(args + ["--seeds", "1,x"]) == 2 and "error" in capsys.readouterr().err
    assert main(args + ["--jobs", "0"]) == 2
    assert main(args + ["--gate-margin-px", "-1"]) == 2
