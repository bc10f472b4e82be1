"""``isa-mocap bench compare``: the quick design end to end, resume, and the summary on synthetic records."""
import json

import numpy as np
import pytest

from isa_mocap_ros.cli.main import main
from isa_mocap_ros.eval.compare import ALGORITHMS, PEER_ALGORITHMS, cell_key, make_design, summarize


def test_quick_json_resume_and_results(tmp_path, capsys):
    out = tmp_path / "cmp"
    res = tmp_path / "RESULTS.md"
    assert main(["bench", "compare", "--quick", "--json", "--out", str(out), "--no-progress",
                 "--write-results", str(res)]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["records"] == 2 and s["algorithms"] == ["isa", "pycma"]
    assert all(v <= 200 for v in s["max_evals_frame"].values())          # budget per frame never exceeded
    assert len(s["ranking"]) == 1 and s["ranking"][0]["budget"] == 200
    assert {r["algorithm"] for r in s["ranking"][0]["rows"]} == {"ISA(39,200)", "PYCMA(39,200)"}
    lines = (out / "cells.jsonl").read_text().splitlines()
    assert len(lines) == 2
    recs = [json.loads(x) for x in lines]
    assert all(r["frames"] == 3 and np.isfinite(r["mpjpe_mm"]) for r in recs)
    md = res.read_text()
    assert "Smoke run" in md and "Fried. Stat." in md and "command:" in md and "machine:" in md
    # the automatic shape (default): calibrated once from the sequence's silhouettes, reported against the truth
    assert s["shape"] == "auto" and all(r["shape"] == "auto" for r in recs) and len(s["calibrations"]) == 1
    cal = s["calibrations"][0]
    assert cal["sequence"] == "walk" and cal["bone_error_mm"] >= 0 and (out / "cache" / cal["shape_file"]).is_file()
    assert "body shape: calibrated once per sequence" in md
    from isa_mocap_ros.eval.compare_shape import calibrate_sequence_shape
    npz = next((out / "cache").glob("*.npz"))
    assert calibrate_sequence_shape(npz, make_design("quick").calib, 0) == cal        # cached, not run again
    # cells tracked with another shape are never resumed into this run
    assert main(["bench", "compare", "--quick", "--shape", "truth", "--resume", str(out), "--jobs", "1",
                 "--no-progress"]) == 2
    assert "shape auto; now" in capsys.readouterr().err
    # resume: drop one finished cell, only that one runs again (in process), with the same result
    (out / "cells.jsonl").write_text(lines[0] + "\n")
    assert main(["bench", "compare", "--quick", "--json", "--resume", str(out), "--jobs", "1", "--no-progress"]) == 0
    s2 = json.loads(capsys.readouterr().out)
    again = [json.loads(x) for x in (out / "cells.jsonl").read_text().splitlines()]
    assert len(again) == 2 and again[0] == recs[0]
    redo = again[1]
    orig = recs[1]
    assert redo["key"] == orig["key"] and redo["mpjpe_mm"] == orig["mpjpe_mm"]     # same seed, same numbers
    assert s2["cells"] == s["cells"]
    # cells of other sequences (another design's frames or images) are never resumed into this one
    d = json.loads((out / "design.json").read_text())
    d["sequences"][0]["duration_s"] = 1.0
    (out / "design.json").write_text(json.dumps(d))
    assert main(["bench", "compare", "--quick", "--resume", str(out), "--jobs", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "holds the cells of other sequences" in err and "walk 30@30 96x72" in err and "walk 4@30 96x72" in err


def test_resume_needs_a_run(tmp_path, capsys):
    assert main(["bench", "compare", "--quick", "--resume", str(tmp_path)]) == 2
    assert "--resume" in capsys.readouterr().err


def test_designs():
    d = make_design("default", cmu_path=None)
    assert d.algorithms == ALGORITHMS + PEER_ALGORITHMS and d.models == (28, 39) and d.budgets == (500, 1500, 3000)
    assert [s.name for s in d.sequences] == ["walk", "jog", "wave", "box"] and "CMU walk skipped" in d.notes[0]
    assert len(d.cells()) == 12 * 2 * 3 * 3 * 4
    assert len({cell_key(c) for c in d.cells()}) == len(d.cells())
    assert len(make_design("full", cmu_path=None).seeds) == 30
    with pytest.raises(ValueError):
        make_design("huge")


def test_summarize_synthetic_records():
    rng = np.random.default_rng(0)
    algs = ["cmaes", "h-cmaes", "apf", "psapf", "pycma"]
    base = {"cmaes": 30.0, "h-cmaes": 20.0, "apf": 60.0, "psapf": 50.0, "pycma": 40.0}
    recs = []
    for a in algs:
        for dof in (28, 39):
            for b in (500, 1500):
                for s in ("walk", "jog", "wave", "box"):
                    for seed in (0, 1):
                        e = base[a] - (5.0 if dof == 39 else 0.0) - b / 500 + rng.normal(0, 0.5)
                        recs.append({"algorithm": a, "model": dof, "budget": b, "sequence": s, "seed": seed,
                                     "mpjpe_mm": e, "fell_back": 0, "max_evals_frame": b})
    out = summarize(recs)
    assert len(out["ranking"]) == 4
    t = out["ranking"][0]
    assert t["control"] == "H-CMAES(28,500)" and t["friedman"]["n_problems"] == 4
    assert [r["algorithm"][:5] for r in t["rows"]][-1] == "APF(2"
    hh = {r["holistic"]: r for r in out["holistic_vs_hierarchical"]}
    assert hh["cmaes"]["b_better"] == hh["cmaes"]["n"] == 16
    dd = {r["algorithm"]: r for r in out["dof_28_vs_39"]}
    assert dd["apf"]["b_better"] == 8 and dd["apf"]["mean_b_mm"] < dd["apf"]["mean_a_mm"]
    pv = [r for r in out["ours_vs_peers"] if r["budget"] == 1500 and r["model"] == 39][0]
    assert pv["ours"] == "h-cmaes" and pv["ours_better_everywhere"]
    fam = {f["algorithm"]: f for f in out["families"]}
    assert fam["psapf"]["hierarchical"] and fam["cmaes"]["control"] == "CMAES(39,1500)"
    json.dumps(out)
