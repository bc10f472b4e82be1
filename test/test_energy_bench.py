"""``isa-mocap bench energy --quick --json`` prints the documented JSON object."""
from __future__ import annotations

import argparse
import json

from isa_mocap_ros.bench import energy as bench_energy
from isa_mocap_ros.cli import bench
from isa_mocap_ros.tracking.tracker import TrackerConfig


def test_bench_energy_quick_json(capsys):
    assert "energy" in bench.BENCHES
    p = argparse.ArgumentParser()
    bench_energy.add_arguments(p)
    assert bench_energy.run(p.parse_args(["--quick", "--json"])) == 0
    out = json.loads(capsys.readouterr().out)
    assert list(out) == ["views", "dof", "batch", "fast_evals_per_s", "exact_evals_per_s", "fast_evals_per_cpu_s",
                         "ratio", "search_evals_per_s", "search_evals_per_cpu_s", "search_evals", "search_generation",
                         "search_restricted_share", "search_coarse_evals_per_s", "search_coarse_evals_per_cpu_s",
                         "search_raster_evals_per_s", "search_raster_evals_per_cpu_s",
                         "search_raster_coarse_evals_per_s", "search_raster_coarse_evals_per_cpu_s", "search_ratio", "fast_mean_abs_diff", "raster_evals_per_s", "raster_evals_per_cpu_s",
                         "raster_ratio", "raster_mean_abs_diff", "raster2_evals_per_s", "raster2_evals_per_cpu_s",
                         "raster2_ratio", "raster2_mean_abs_diff", "exact_batch",
                         "n_model_points", "n_template", "n_mask_points", "downsample", "threads"]
    tc = TrackerConfig()                 # measured with the tracker's sample sizes
    obj = tc.objective
    assert (out["n_model_points"], out["n_mask_points"], out["downsample"]) == (obj.n_model_points, obj.n_mask_points,
                                                                                obj.downsample)
    assert out["n_template"] >= out["n_model_points"]
    assert out["views"] == 4 and out["dof"] == 39 and out["batch"] == 64 and out["exact_batch"] == 4
    assert out["fast_evals_per_s"] > 0 and out["exact_evals_per_s"] > 0 and out["fast_evals_per_cpu_s"] > 0
    assert out["ratio"] > 0
    # the tracker's search: its generations, most of it on the restricted kernel (every partition but the root's)
    assert out["search_evals"] == 360 and out["search_generation"] == 30
    assert 0.5 < out["search_restricted_share"] < 1
    assert out["search_evals_per_s"] > 0 and out["search_evals_per_cpu_s"] > 0 and out["search_ratio"] > 0
    assert out["search_coarse_evals_per_s"] > 0 and out["search_coarse_evals_per_cpu_s"] > 0
    # the scanline energy: timed as the fast one, and closer to the exact reference than the sampled kernel
    assert out["raster_evals_per_s"] > 0 and out["raster2_evals_per_s"] > 0 and out["raster_ratio"] > 0
    assert out["raster_mean_abs_diff"] < out["fast_mean_abs_diff"]
    assert out["search_raster_evals_per_s"] > 0 and out["search_raster_evals_per_cpu_s"] > 0
    assert out["search_raster_coarse_evals_per_s"] > 0 and out["search_raster_coarse_evals_per_cpu_s"] > 0
