"""``isa-mocap bench mesh``: the mesh headline bench (automatic shape and initialization), its smoke run."""
import json

import numpy as np
import pytest

from isa_mocap_ros.bench import mesh as bm
from isa_mocap_ros.cli.main import main


def test_quick_runs_the_automatic_path_and_scores_it(tmp_path, capsys):
    js = tmp_path / "mesh.json"
    assert main(["bench", "mesh", "--quick", "--seeds", "0,1", "--jobs", "1", "--out", str(tmp_path / "w"),
                 "--json", str(js)]) == 0
    res = json.loads(js.read_text())
    d = res["design"]
    assert d["shape"] == "auto" and d["init"] == "auto" and d["body"] == "mesh"
    # one calibration for the bag, both seeds tracked with its file; a bench run again finds it in the cache
    (cal,) = res["calibrations"]
    assert np.isfinite(cal["bone_error_mm"]) and np.isfinite(cal["bone_error_default_shape_mm"])
    assert np.isfinite(cal["limb_bone_error_mm"]) and np.isfinite(cal["limb_bone_error_default_shape_mm"])
    shape_file = tmp_path / "w" / "cache" / cal["shape_file"]
    assert all(r["shape"] == str(shape_file) for r in res["runs"])
    from isa_mocap_ros.bench import robustness as br
    stamp = shape_file.stat().st_mtime_ns
    assert br.calibrate_bag(shape_file.parent / cal["bag"], bm.make_design("quick", seeds=(0, 1)))["shape_file"] \
        == cal["shape_file"] and shape_file.stat().st_mtime_ns == stamp
    run = res["runs"][0]
    assert run["frames"] == 6 and run["init"] != "ground truth"
    for k in ("mpjpe_mm", "offset_removed_mpjpe_mm", "knee_rmse_deg", "max_frame_error_mm", "backwards_share",
              "mapped_mpjpe_mm", "mapped_knee_rmse_deg", "mapped_max_frame_error_mm"):
        assert np.isfinite(run[k]), k
    assert np.isfinite(run["offset_removed_knee_rmse_deg"])
    assert run["offset_removed_mpjpe_mm"] <= run["mpjpe_mm"]
    (c,) = res["conditions"]
    assert c["per_subject"]["average_man"]["mpjpe_mm"] == pytest.approx(np.mean([r["mpjpe_mm"] for r in res["runs"]]))
    assert c["per_subject"]["average_man"]["mapped_mpjpe_mm"] == pytest.approx(
        np.mean([r["mapped_mpjpe_mm"] for r in res["runs"]]))
    assert [t["met"] for t in res["targets"]][-2:] == [None, None]      # noise and occluders not run
    out = capsys.readouterr().out
    assert "| target (issue 33) |" in out and "Smoke run" in out and "calibrated once per bag" in out


def test_design_and_targets():
    d = bm.make_design("default")
    assert [s.subject for s in d.sequences] == ["slim_woman", "average_man", "heavy_man"]
    assert d.seeds == tuple(range(8)) and d.evals == 1500 and d.optimizer == "h-isa"
    assert d.shape == "auto" and d.init == "auto" and d.conditions == ("clean", "noise70", "occluders35")
    assert round(d.sequences[0].duration_s * 30) == 60
    assert dict(bm.make_design("default", tracker=[("keypoint_weight", 1.0)]).tracker) == {"keypoint_weight": 1.0}
    with pytest.raises(ValueError, match="subjects"):
        bm.make_design("default", subjects=("giant",))
    with pytest.raises(ValueError, match="conditions"):
        bm.make_design("default", conditions=("fog",))
    # the targets judge the mapped figures (raw ones above the limits here)
    run = {"condition": "clean", "mpjpe_mm": 40.0, "offset_removed_mpjpe_mm": 12.0, "knee_rmse_deg": 9.0,
           "max_frame_error_mm": 130.0, "backwards_share": 0.0, "mapped_mpjpe_mm": 20.0, "mapped_knee_rmse_deg": 2.0,
           "mapped_max_frame_error_mm": 90.0}
    runs = [dict(run, sequence="a"), dict(run, sequence="b", mapped_max_frame_error_mm=120.0, backwards_share=0.8)]
    s = bm.summarize(runs)
    t = {x["target"]: x["met"] for x in s["targets"]}
    assert t["clean: mean joint error ≤ 30 mm (mapped)"] and t["clean: knee RMSE ≤ 3° (mapped)"]
    assert not t["clean: no frame > 100 mm (mapped, worst run)"] and not t["clean: no run tracked facing backwards"]
    assert s["conditions"][0]["backwards_runs"] == 1


def test_quick_with_two_calibration_seeds_tracks_each_seed_with_its_calibration(tmp_path):
    js = tmp_path / "mesh.json"
    assert main(["bench", "mesh", "--quick", "--seeds", "0,1", "--calib-seeds", "0,1", "--jobs", "1",
                 "--out", str(tmp_path / "w"), "--json", str(js)]) == 0
    res = json.loads(js.read_text())
    assert res["design"]["calib_seeds"] == [0, 1]
    cals = {c["calib_seed"]: c for c in res["calibrations"]}
    assert sorted(cals) == [0, 1] and cals[0]["shape_file"] != cals[1]["shape_file"]
    cache = tmp_path / "w" / "cache"
    # tracker seed i tracks with calibration seed i mod 2; the seed-0 file is the one-calibration bench's file
    assert {r["seed"]: r["shape"] for r in res["runs"]} == {0: str(cache / cals[0]["shape_file"]),
                                                          1: str(cache / cals[1]["shape_file"])}
    assert cals[0]["shape_file"] == bm.br.calibration_path(cache / cals[0]["bag"], bm.make_design("quick")).name
    v = res["conditions"][0]["per_subject"]["average_man"]
    assert sorted(v["per_calibration"]) == ["0", "1"]
    assert v["calibration_range_mm"] == [min(r["mapped_mpjpe_mm"] for r in res["runs"]),
                                         max(r["mapped_mpjpe_mm"] for r in res["runs"])]


def test_calibration_seeds_of_the_design():
    assert bm.make_design("default").calib_seeds == bm.CALIB_SEEDS == (0, 1, 2)
    assert bm.make_design("quick", seeds=(3, 4)).calib_seeds == (3,)
    assert bm.make_design("default", calib_seeds=(5,)).calib_seeds == (5,)
    with pytest.raises(ValueError, match="calibration seeds"):
        bm.make_design("default", calib_seeds=(1, 1))
    # a calibration option: its own cache name, the seed-0 name of the defaults unchanged
    from pathlib import Path
    rp = bm.make_design("default", calib=[("calib_radius_prior", 0.05)])
    assert dict(rp.calib) == {"calib_radius_prior": 0.05} and bm.make_design("default").calib == ()
    bag = Path("/x/bag")
    assert bm.br.calibration_path(bag, rp, 0) != bm.br.calibration_path(bag, bm.make_design("default"), 0)
    # runs of one calibration have no per-calibration figures
    run = {"condition": "clean", "sequence": "a", "mpjpe_mm": 40.0, "offset_removed_mpjpe_mm": 12.0, "knee_rmse_deg": 9.0,
           "max_frame_error_mm": 130.0, "backwards_share": 0.0, "mapped_mpjpe_mm": 20.0, "mapped_knee_rmse_deg": 2.0,
           "mapped_max_frame_error_mm": 90.0, "calib_seed": 0}
    assert "per_calibration" not in bm.summarize([run, dict(run)])["conditions"][0]["per_subject"]["a"]
    two = bm.summarize([run, dict(run, calib_seed=1, mapped_mpjpe_mm=30.0)])["conditions"][0]["per_subject"]["a"]
    assert two["calibration_range_mm"] == [20.0, 30.0] and two["per_calibration"]["1"]["mapped_mpjpe_mm"] == 30.0
