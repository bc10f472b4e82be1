"""`isa-mocap bench ackley --quick --json` runs and reports the paper's rows."""
import argparse
import json

from isa_mocap_ros.cli import bench_ackley


def test_bench_ackley_quick_json(capsys):
    p = argparse.ArgumentParser()
    bench_ackley.add_arguments(p)
    assert bench_ackley.run(p.parse_args(["--quick", "--json"])) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    keys = {"method", "kernel", "n", "b", "c", "noise", "mean_steps", "success_rate",
            "mean_evals", "paper_mean_steps"}
    assert len(rows) == 16 and all(set(r) == keys for r in rows)
    isa = [r for r in rows if r["kernel"] is not None]
    assert {r["paper_mean_steps"] for r in isa} >= {14.34, 15.14, 14.58, 22.4, 20.3, 21.54}
    assert {r["method"] for r in rows if r["kernel"] is None} == {"pycma", "CmaEs (ours)"}
    # noiseless n = 50 rows: every quick run succeeds, in a plausible number of steps
    for r in isa[:3]:
        assert r["success_rate"] == 1.0 and 5 < r["mean_steps"] < 40
        assert r["mean_evals"] == r["n"] * (r["mean_steps"] + 1)
