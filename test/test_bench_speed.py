"""``isa-mocap bench speed --quick``: energy, tracker frames/s per budget in one run."""
import json

import numpy as np

from isa_mocap_ros.bench import speed as bench_speed
from isa_mocap_ros.cli.main import main


def test_quick_json(capsys):
    assert main(["bench", "speed", "--quick", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    e = res["energy"]
    assert e["fast_evals_per_s"] > 0 and e["exact_evals_per_s"] > 0
    rows = res["tracker"]["rows"]
    assert [r["evals_per_frame"] for r in rows] == [500, 1500, 3000]
    for r in rows:
        assert r["frames"] == 3 and np.isfinite(r["frames_per_s"]) and r["frames_per_s"] > 0
    assert res["network"]["rows"] == [] and res["network"]["skipped"] == "--quick"
    md = bench_speed.render_markdown(res)
    assert "#### Offline tracker" in md and "Skipped (--quick)" in md


def test_bad_frames(capsys):
    assert main(["bench", "speed", "--quick", "--frames", "0"]) == 2
    assert "--frames" in capsys.readouterr().err
