"""A keypoint model's surface points (head top, nose, heels, toes) defined on the mesh bodies (eval/keypoint_map.py)."""
import numpy as np
import pytest

from isa_mocap_ros.body import make_model
from isa_mocap_ros.body.kinematics import joint_frames
from isa_mocap_ros.eval.joint_map import JointMap, JointMapError
from isa_mocap_ros.eval.keypoint_map import (POINT_RULES, KeypointPoints, fit_keypoint_points, keypoint_positions,
                                             load_keypoint_points, mesh_keypoint_points, save_keypoint_points)

POINTS = KeypointPoints({"Head": ["head", [0.02, 0.0, 0.15]], "LHeel": ["left_ankle", [-0.06, 0.0, -0.06]]})


def _pose(model, **angles):
    x = model.rest_pose().astype(float).copy()
    x[2] = 1.0
    for name, v in angles.items():
        x[model.dof_names.index(name)] = v
    return x


def test_points_ride_the_segment_that_carries_them():
    """The head top turns with the neck (the head has no joint of its own), the heel with the ankle's own rotation,
    and neither moves when the other segments move."""
    model = make_model(39)
    names = ["Head", "LHeel"]
    rest = _pose(model)
    nod = _pose(model, **{n: 0.5 for n in model.dof_names if n.startswith("neck_") and n.endswith("y")})
    foot = _pose(model, **{n: 0.4 for n in model.dof_names if n.startswith("left_ankle_") and n.endswith("y")})
    P = keypoint_positions(POINTS, model, np.array([rest, nod, foot]), names)
    R, J, _ = joint_frames(model, np.array([rest, nod, foot]))
    h, a = model.joint_names.index("head"), model.joint_names.index("left_ankle")
    np.testing.assert_allclose(P[0, 0] - J[0, h], [0.02, 0.0, 0.15], atol=1e-12)     # at rest: the offset itself
    # nodding moves the head top around the head joint by the neck's rotation: the same distance, another place
    assert np.linalg.norm(P[1, 0] - J[1, h]) == pytest.approx(np.linalg.norm([0.02, 0.0, 0.15]))
    assert np.linalg.norm((P[1, 0] - J[1, h]) - (P[0, 0] - J[0, h])) > 0.05
    np.testing.assert_allclose(P[1, 1], P[0, 1], atol=1e-12)                          # the heel stays
    # the ankle's flexion turns the heel about the ankle; the head top stays
    np.testing.assert_allclose(P[2, 0], P[0, 0], atol=1e-12)
    np.testing.assert_allclose(P[2, 1] - J[2, a], R[2, a] @ [-0.06, 0.0, -0.06], atol=1e-12)
    assert np.linalg.norm(P[2, 1] - P[0, 1]) > 0.02


def test_a_rig_map_moves_the_anchor_first():
    model = make_model(39)
    x = _pose(model, **{n: 0.3 for n in model.dof_names if n.startswith("neck_")})
    rig = JointMap({"head": [0.0, 0.0, 0.05]}, rig="test")
    with_rig = keypoint_positions(POINTS, model, x[None], ["Head"], rig_map=rig)
    without = keypoint_positions(POINTS, model, x[None], ["Head"])
    R, _, _ = joint_frames(model, x[None])
    np.testing.assert_allclose(with_rig - without, (R[0, model.joint_names.index("neck")] @ [0, 0, 0.05])[None, None],
                               atol=1e-12)
    with pytest.raises(JointMapError, match="no point 'Nose'"):
        keypoint_positions(POINTS, model, x[None], ["Nose"])


def test_file_round_trip_and_errors(tmp_path):
    p = tmp_path / "pts.yaml"
    save_keypoint_points(KeypointPoints(POINTS.points, {"Head": 3.0}, {"note": "test"}), p)
    back = load_keypoint_points(p)
    assert back.points == POINTS.points and back.spread_mm == {"Head": 3.0} and back.source == {"note": "test"}
    p.write_text("points:\n  Head: [head, [0.0, nan, 0.1]]\n")
    with pytest.raises(JointMapError, match=r"pts.yaml: points.Head: expected \[joint, \[x, y, z\]\]"):
        load_keypoint_points(p)
    p.write_text("offsets: {}\n")
    with pytest.raises(JointMapError, match="expected a mapping with 'points'"):
        load_keypoint_points(p)


def test_the_mesh_bodies_points_and_the_shipped_file():
    """Defined on the MakeHuman meshes (skipped without the assets): the head top above the head joint, the nose in
    front of it, the heel behind the ankle and below it, the toes in front, the big toe medial of the small one; the
    shipped file is what tools/fit_keypoint_points.py makes."""
    from isa_mocap_ros.body.mesh import PRESETS, make_subject
    from isa_mocap_ros.body.mesh_assets import AssetError, asset_dir

    try:
        asset_dir()
    except AssetError as exc:
        pytest.skip(str(exc))
    model = make_model(39)
    subjects = [make_subject(n) for n in PRESETS] + [make_subject("random", rng=np.random.default_rng(k))
                                                      for k in range(5)]
    pts = fit_keypoint_points(model, subjects)
    assert set(pts.points) == set(POINT_RULES)
    o = {n: pts.offset(n) for n in pts.points}
    assert 0.10 < o["Head"][2] < 0.25 and abs(o["Head"][1]) < 0.01
    assert o["Nose"][0] > 0.06 and o["Nose"][2] < o["Head"][2] and abs(o["Nose"][1]) < 0.01
    assert o["LHeel"][0] < -0.02 and o["LHeel"][2] < -0.03
    assert o["LBigToe"][0] > 0.10 and o["LSmallToe"][0] > 0.05
    assert o["LBigToe"][1] < o["LSmallToe"][1]                      # medial (toward the midline) of the small toe
    for n in ("Heel", "BigToe", "SmallToe"):                          # left and right mirror each other
        np.testing.assert_allclose(o["R" + n], o["L" + n] * [1, -1, 1])
    assert all(s < 25.0 for s in pts.spread_mm.values()), pts.spread_mm
    shipped = mesh_keypoint_points()
    for n in pts.points:
        np.testing.assert_allclose(shipped.offset(n), pts.offset(n), atol=1e-4, err_msg=n)
        assert shipped.anchor(n) == pts.anchor(n)
