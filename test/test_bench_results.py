"""``isa-mocap bench all --quick --results PATH``: the results page from every bench's --quick variant."""
import json
import math
import re

from isa_mocap_ros.bench import results as bench_results
from isa_mocap_ros.cli.main import main


def test_all_quick_writes_the_page(tmp_path):
    page = tmp_path / "docs" / "RESULTS.md"
    page.parent.mkdir()
    # --jobs 1: the comparison's two cells in process (no spawned workers to start)
    assert main(["bench", "all", "--quick", "--jobs", "1", "--results", str(page), "--out", str(tmp_path / "work"),
                 "--no-progress"]) == 0
    md = page.read_text()
    for head in ("# Results", "Smoke run", "- command: `isa-mocap bench all --quick --jobs 1", "- git commit:", "- machine:",
                 "GB RAM", "## Headline figures", "robustness, knee RMSE (ours vs the ISA paper)", "## Targets (issue #7), from the measured numbers",
                 "## The comparison paper's findings, checked on our data",
                 "## Ackley function", "## Optimizer comparison", "## Robustness", "## Speed", "## Silhouette energy speed",
                 "## Renderer speed", "## Message adapter speed", "Fried. Stat.", "70 % pixel noise", "#### Offline tracker",
                 "## Mesh bodies vs capsules", "## Headline: mesh subjects", "mesh subjects, everything automatic",
                 "| target (issue 33) |", "## Learned keypoints: cost and tracking with the term",
                 "## The real recording", "## Unseen motions on mesh subjects"):
        assert head in md, head
    # every target has a status computed from the numbers
    targets = md.split("## Targets", 1)[1].split("\n## ", 1)[0]
    statuses = re.findall(r"\| \*\*(.+?)\*\* \|$", targets, flags=re.M)
    assert statuses
    for status in statuses:
        assert status in ("met", "not met", "not tested")
    figs = tmp_path / "docs" / "results"
    for png in ("ackley_steps.png", "compare_error_vs_budget.png", "robustness_knees.png", "robustness_knee_rmse.png", "speed_tracker_fps.png"):
        assert (figs / png).stat().st_size > 1000
        assert f"](results/{png})" in md
    # numbers on the page are finite
    assert "nan" not in md.lower().replace("nanmean", "") and "inf " not in md
    for name in bench_results.ORDER:
        d = json.loads((figs / f"{name}.json").read_text())
        assert d["_seconds"] >= 0
    rob = json.loads((figs / "robustness.json").read_text())
    assert all(math.isfinite(c["knee_rmse_deg"]) for c in rob["conditions"])
    # --only re-runs a subset; the page keeps (and names) the others' saved results
    assert main(["bench", "all", "--quick", "--only", "energy", "--results", str(page), "--out", str(tmp_path / "work"),
                 "--no-progress"]) == 0
    md2 = page.read_text()
    assert ("not re-run this time (last saved results shown): ackley, adapters, compare, keypoints, mesh, "
            "mesh_baseline, mesh_motions, real, render, robustness, speed") in md2
    assert "## Robustness" in md2 and "## Silhouette energy speed" in md2
    assert main(["bench", "all", "--quick", "--only", "nope", "--results", str(page)]) == 2
    # --render runs nothing: every section from the saved results
    assert main(["bench", "all", "--render", "--results", str(page), "--out", str(tmp_path / "work")]) == 0
    md3 = page.read_text()
    assert "--render" in md3 and ("not re-run this time (last saved results shown): ackley, adapters, compare, energy, "
                                  "keypoints, mesh, mesh_baseline, mesh_motions, real, render, robustness, speed") in md3


def test_findings_and_targets_from_data():
    from isa_mocap_ros.eval.compare import findings, peer_targets, summarize

    recs = []
    base = {"cmaes": 30.0, "h-cmaes": 20.0, "apf": 60.0, "psapf": 50.0, "isa": 40.0, "h-isa": 45.0, "pycma": 35.0}
    for a, e0 in base.items():
        for dof in (28, 39):
            for s, ds in (("walk", 0.0), ("jog", 3.0), ("wave", 1.0)):
                e = e0 + ds + (2.0 if dof == 39 else 0.0)        # 39 DOF worse: the paper's (ii) must not hold
                recs.append({"algorithm": a, "model": dof, "budget": 1500, "sequence": s, "seed": 0, "mpjpe_mm": e,
                             "fell_back": 0, "max_evals_frame": 1500})
    f = {r["finding"]: r for r in findings(summarize(recs))}
    assert f["EA vs PF"]["better"] == f["EA vs PF"]["n"] == 12 and f["EA vs PF"]["verdict"] == "holds"
    assert f["39 vs 28 DOF (EAs)"]["verdict"] == "does not hold"
    hh = f["hierarchical vs holistic"]
    assert hh["n"] == 18 and hh["better"] == 12 and hh["verdict"] in ("holds", "not significant")
    pt = peer_targets(summarize(recs))
    assert {t["model"] for t in pt} == {28, 39} and all(t["met"] and t["ours"] == "h-cmaes" for t in pt)
    rows = bench_results.targets({"compare": summarize(recs)})
    assert rows[0][2] == "met" and rows[-1][2] == "not tested"
