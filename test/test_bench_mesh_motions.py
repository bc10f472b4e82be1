"""``isa-mocap bench mesh_motions``: CMU clips of other kinds on mesh subjects, its smoke run and design."""
import json

import numpy as np
import pytest

from isa_mocap_ros.bench import mesh_motions as mm
from isa_mocap_ros.cli.main import main

HAVE_CLIPS = all((mm.cmu_dir() / f).is_file() for f, *_ in mm.CLIPS.values())


@pytest.mark.skipif(not (mm.cmu_dir() / mm.CLIPS["jog"][0]).is_file(), reason=f"{mm.cmu_dir()} absent (shared data)")
def test_quick_tracks_a_cmu_clip_on_a_mesh_and_scores_it(tmp_path, capsys):
    js = tmp_path / "motions.json"
    assert main(["bench", "mesh_motions", "--quick", "--jobs", "1", "--out", str(tmp_path / "w"),
                 "--json", str(js)]) == 0
    res = json.loads(js.read_text())
    d = res["design"]
    assert d["shape"] == "auto" and d["init"] == "auto" and d["sequences"][0]["motion"].endswith("16_36_run_jog.bvh")
    (run,) = res["runs"]
    assert run["frames"] == 6 and run["init"] != "ground truth"
    for k in ("mapped_mpjpe_mm", "mapped_knee_rmse_deg", "mpjpe_mm", "offset_removed_mpjpe_mm"):
        assert np.isfinite(run[k]), k
    (cal,) = res["calibrations"]
    assert np.isfinite(cal["bone_error_mm"])
    v = res["per_sequence"]["jog-average_man"]
    assert v["mapped_mpjpe_mm"] == pytest.approx(run["mapped_mpjpe_mm"]) and v["bone_error_mm"] == cal["bone_error_mm"]
    assert res["mean"]["mapped_mpjpe_mm"] == pytest.approx(run["mapped_mpjpe_mm"])
    out = capsys.readouterr().out
    assert "Smoke run" in out and "| jog | average_man |" in out


def test_design(tmp_path):
    if HAVE_CLIPS:
        d = mm.make_design("default")
        assert len(d.sequences) == len(mm.MOTIONS) * len(mm.SUBJECTS) and d.seeds == mm.SEEDS
        assert d.evals == 1500 and d.conditions == ("clean",) and d.shape == "auto"
        rnd = [s for s in d.sequences if s.subject == "random"]
        assert len({s.seed for s in rnd}) == len(rnd)           # a different random body per clip
        assert all(s.duration_s * s.fps == pytest.approx(mm.FRAMES) for s in d.sequences)
    with pytest.raises(ValueError, match="motions: expected some of"):
        mm.make_design(motions=("moonwalk",))
    with pytest.raises(ValueError, match="no clip found under"):
        mm.make_design(root=tmp_path)
    (tmp_path / mm.CLIPS["kick"][0]).write_text("")
    d = mm.make_design(motions=("kick", "jog"), root=tmp_path)
    assert [s.name for s in d.sequences] == ["kick-average_man", "kick-random"]
    assert any("jog skipped" in n for n in d.notes)


def test_bench_all_skips_it_clearly_without_the_shared_clips(tmp_path, monkeypatch):
    # a checkout without ../shared (CI): bench all's runner says why and the page says "Not run"
    monkeypatch.setenv("ISA_MOCAP_SHARED", str(tmp_path / "nowhere"))
    res = mm.for_all(True, {"out": tmp_path / "w", "jobs": 1, "progress": False})
    assert "skipped" in res and str(tmp_path / "nowhere") in res["skipped"]
    assert mm.section(res).startswith("Not run: the shared CMU clips are not under")
    assert not (tmp_path / "w").exists()
