"""``isa-mocap bench speed --quick``: energy, tracker frames/s per budget in one run."""
import json

import numpy as np
import pytest

from isa_mocap_ros.bench import speed as bench_speed
from isa_mocap_ros.cli.main import main


def test_quick_json(capsys):
    assert main(["bench", "speed", "--quick", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    e = res["energy"]
    assert e["fast_evals_per_s"] > 0 and e["exact_evals_per_s"] > 0 and e["search_evals_per_s"] > 0
    rows = res["tracker"]["rows"]
    assert [r["evals_per_frame"] for r in rows] == [500, 1500, 3000]
    for r in rows:
        assert r["frames"] == 3 and np.isfinite(r["frames_per_s"]) and r["frames_per_s"] > 0
        assert np.isfinite(r["cpu_ms_per_frame"]) and r["cpu_ms_per_frame"] > 0
    assert res["network"]["rows"] == [] and res["network"]["skipped"] == "--quick"
    sg = res["segmentation"]
    assert [r["work_scale"] for r in sg["rows"]] == list(bench_speed.SEGMENTATION_SCALES) and sg["sets"] > 0
    for r in sg["rows"]:
        assert r["cpu_ms_per_set"] > 0 and abs(r["cpu_ms_per_view"] * sg["views"] - r["cpu_ms_per_set"]) < 1e-9
    assert sg["rows"][0]["iou_vs_default"] == 1.0 and 0.5 < sg["rows"][1]["iou_vs_default"] < 1.0
    pr = res["profile"]
    assert pr["frames"] == 3 and pr["evals_per_frame"] == 1500 and pr["cpu_ms_per_frame"] > 0
    stages = {r["stage"]: r for r in pr["by_stage"]}
    assert list(stages) == [s[0] for s in bench_speed.PROFILE_STAGES] + ["bookkeeping (the rest of the step)"]
    # every default stage ran once a frame, and the rows add up to the profiled step
    for name in ("prediction", "main search", "pelvis stage", "torso stage", "limb stage", "contour stage"):
        assert stages[name]["calls_per_frame"] >= 1 and stages[name]["cpu_ms_per_frame"] > 0, name
    total = sum(r["cpu_ms_per_frame"] for r in pr["by_stage"])
    assert abs(total - pr["profiled_cpu_ms_per_frame"]) < 1e-6 * total + 1e-9
    assert stages["bookkeeping (the rest of the step)"]["share"] < 0.5
    # the energy's kernels are among the top calls (the compiled search runs them inside its own frame)
    energy_calls = ("silhouette", "raster_kernel", "compiled_search")
    assert len(pr["by_call"]) == 15 and any(k in r["function"] for r in pr["by_call"] for k in energy_calls)
    md = bench_speed.render_markdown(res)
    assert "| the tracker's h-isa search (360 evaluations in generations of 30" in md
    assert "| scanline count (`method='raster'`" in md and "| the tracker's search on the scanline energy" in md
    assert "#### Offline tracker" in md and "Skipped (--quick)" in md and "#### Segmentation" in md
    assert "#### Where a tracked frame's CPU time goes" in md and "| contour stage |" in md


def test_bad_frames(capsys):
    assert main(["bench", "speed", "--quick", "--frames", "0"]) == 2
    assert "--frames" in capsys.readouterr().err


def test_network_rows_change_estimator_parameters_in_a_copy_of_the_parameter_file(tmp_path):
    """The network part's A/B rows (NETWORK_MODES' last field) run with config/pipeline.yaml's estimator
    parameters changed in a copy: only that parameter, only the estimator's."""
    import yaml

    from isa_mocap_ros.bench.speed import NETWORK_MODES, _params_with
    from isa_mocap_ros.resources import resource_dir

    assert any(m[4] == {"startup_catch_up": 3} and not m[1] and not m[2] for m in NETWORK_MODES)
    assert any(m[4] == {"startup_catch_up": 3} and m[2] for m in NETWORK_MODES)     # one core busy, A/B
    orig = yaml.safe_load((resource_dir("config") / "pipeline.yaml").read_text())
    got = yaml.safe_load(_params_with({"startup_catch_up": 12, "degrade": False}, tmp_path / "p.yaml").read_text())
    est, ref = got["/mocap/estimator"]["ros__parameters"], orig["/mocap/estimator"]["ros__parameters"]
    assert est["startup_catch_up"] == 12 and est["degrade"] is False and ref["startup_catch_up"] == 0
    assert {k: v for k, v in est.items() if k not in ("startup_catch_up", "degrade")} == \
        {k: v for k, v in ref.items() if k not in ("startup_catch_up", "degrade")}
    assert {k: v for k, v in got.items() if k != "/mocap/estimator"} == \
        {k: v for k, v in orig.items() if k != "/mocap/estimator"}
    with pytest.raises(ValueError, match="no_such_parameter"):
        _params_with({"no_such_parameter": 1}, tmp_path / "q.yaml")


def test_the_network_table_says_where_the_drops_came_from():
    """A network row's drops are split: the estimator's queue (of them at bunched arrivals) and the rest lost before
    it; the governor's lowerings beside them (the figures the one-core-busy question needs)."""
    row = {"mode": "real time, one core busy", "frame_sets_played": 145, "frames_processed": 129, "fps": 26.4,
           "real_time_factor": 0.88, "latency_ms_p50": 50.0, "latency_ms_p95": 120.0, "dropped_frames": 16,
           "dropped_share": 16 / 145, "dropped_while_initializing": 6, "dropped_by_estimator": 14,
           "dropped_at_bunched_arrivals": 5, "startup_sets_caught_up": 0, "frames_without_contour_stage": 14,
           "budget_lowered": 3, "budget_levels": [3, 0, 10, 20, 90], "init_ms": 168.0, "init_cpu_ms": 101.4, "tracker_ms_p50": 21.0, "tracker_ms_p95": 44.0, "mpjpe_mm": 38.2,
           "mpjpe_vs_lockstep_mm": 2.9}
    lines = bench_speed.network_table([row, {"mode": "lockstep", "error": "x"}])
    head = next(ln for ln in lines if ln.startswith("| mode |"))
    cells = next(ln for ln in lines if ln.startswith("| real time, one core busy |")).split(" | ")
    names = head.split(" | ")
    assert len(cells) == len(names)
    at = dict(zip(names, cells))
    assert at["of them by the estimator (its queue) / at bunched arrivals"] == "14 / 5"
    assert at["budget lowered (times)"] == "3" and at["dropped"] == "16 (11 %)"
    assert at["sets per budget level 0/1/2/…"] == "3/0/10/20/90"
    assert at["initialization wall / CPU (ms)"] == "168 / 101"      # the estimator's init_ms and init_cpu_ms
    failed = next(ln for ln in lines if ln.startswith("| lockstep |"))
    assert failed.count("|") == head.count("|")


def test_budget_levels_are_counted_from_the_estimators_trace(tmp_path):
    """The real-time rows' level histogram: the governor's level of each accounted set in the trace (the start-up's
    sets carry none and are not counted); no trace, no histogram."""
    lines = [{"stamp": 1, "init": True}, {"stamp": 2, "level": 0}, {"stamp": 3, "level": 2}, {"stamp": 4, "level": 2},
             {"stamp": 5, "level": 4}]
    trace = tmp_path / "trace.jsonl"
    trace.write_text("".join(json.dumps(ln) + "\n" for ln in lines))
    assert bench_speed.budget_levels(trace) == [1, 0, 2, 0, 1]
    assert bench_speed.budget_levels(tmp_path / "none.jsonl") is None
