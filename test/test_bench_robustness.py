"""``isa-mocap bench robustness --quick``: the ISA §13.4.2 conditions end to end, and the target checks."""
import json

import numpy as np

from isa_mocap_ros.cli import bench_robustness as br
from isa_mocap_ros.cli.main import main


def test_quick_json(tmp_path, capsys):
    cache = tmp_path / "cache"
    assert main(["bench", "robustness", "--quick", "--json", "--cache", str(cache), "--out", str(tmp_path / "o")]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [c["condition"] for c in res["conditions"]] == ["clean", "noise50", "noise70", "occluders35"]
    assert [c["paper_knee_rmse_deg"] for c in res["conditions"]] == [2.74, 2.97, 4.51, 5.21]
    for r in res["runs"]:
        assert r["sequence"] == "walk" and r["frames"] == 5          # 6 frames, the ground-truth first one not scored
        assert np.isfinite(r["knee_rmse_deg"]) and np.isfinite(r["mpjpe_mm"])
        assert len(r["knee_est_deg"]) == len(r["t_s"]) == r["frames"]
    # one cached bag per condition, tracked with `isa-mocap track`'s code (its summary.json is there)
    assert len([p for p in cache.iterdir() if (p / "metadata.yaml").is_file()]) == 4
    assert all((tmp_path / "o" / p.name / "summary.json").is_file() for p in cache.iterdir())
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
