"""tools/real_floor.py: the bound of a rigid model against a peer's points (docs/real_cameras.md section 5)."""
import importlib.util
from pathlib import Path

import numpy as np

from isa_mocap_ros.body import make_model
from isa_mocap_ros.eval.metrics import marker_positions

_SPEC = importlib.util.spec_from_file_location("real_floor", Path(__file__).resolve().parents[1] / "tools" / "real_floor.py")
real_floor = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(real_floor)


def _poses(model, n, rng):
    lo, hi = np.asarray(model.lower), np.asarray(model.upper)
    X = np.zeros((n, model.dof))
    X[:, 2] = 1.0
    X[:, 6:] = np.clip(rng.normal(0.0, 0.25, (n, model.dof - 6)), lo[6:], hi[6:])
    return X


def test_ik_reaches_points_the_model_can_reach_and_stays_in_its_limits():
    rng = np.random.default_rng(0)
    model = make_model(39)
    names = [model.joint_names[j] for j in model.markers]
    truth = _poses(model, 3, rng)
    Pt = marker_positions(model, truth, joints=names)
    start = truth + np.concatenate([rng.normal(0, 0.03, (3, 6)), rng.normal(0, 0.15, (3, model.dof - 6))], axis=1)
    start[:, 6:] = np.clip(start[:, 6:], model.lower[6:], model.upper[6:])
    before = np.linalg.norm(marker_positions(model, start, joints=names) - Pt, axis=-1).mean()
    X = real_floor.ik_to_peer(model, start, Pt, names)
    after = np.linalg.norm(marker_positions(model, X, joints=names) - Pt, axis=-1).mean()
    assert before > 0.05 and after < 0.2 * before       # a local least-squares fit: a bound, not the global optimum
    assert np.all(X >= np.asarray(model.lower) - 1e-12) and np.all(X <= np.asarray(model.upper) + 1e-12)


def test_peer_distances_per_third():
    names = ["left_shoulder", "right_shoulder", "left_hip", "right_hip", "neck"]
    T = np.zeros((6, 5, 3))
    T[:, 0, 1], T[:, 1, 1] = 0.15, -0.15          # shoulders 0.30 m apart, then 0.34 in the last third
    T[4:, 0, 1] = 0.19
    T[:, 2, 1], T[:, 3, 1] = 0.1, -0.1
    T[:, 4, 2] = 0.5
    d = real_floor.peer_distances(names, T)
    assert [round(m) for m, _ in d["shoulder width"]] == [300, 300, 340]
    assert [round(m) for m, _ in d["hip width"]] == [200] * 3 and [round(m) for m, _ in d["mid-hip to neck"]] == [500] * 3
