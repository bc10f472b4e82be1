"""BVH import: channel orders, naming styles, unit detection, resampling, bad input, retargeting."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from isa_mocap_ros.body import BodyError, joint_positions, make_model
from isa_mocap_ros.body.bvh import BVH_TO_WORLD, load_bvh, parse_bvh
from isa_mocap_ros.body.retarget import map_skeleton, model_from_bvh, retarget
from isa_mocap_ros.geometry import exp_so3, log_so3

TWO_JOINTS = """HIERARCHY
ROOT Hips
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {order}
  JOINT Child
  {{
    OFFSET 0 {length} 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {{
      OFFSET 0 {length} 0
    }}
  }}
}}
MOTION
Frames: 2
Frame Time: 0.5
{f0}
{f1}
"""


@pytest.mark.parametrize("order", ["Zrotation Yrotation Xrotation", "Xrotation Yrotation Zrotation",
                                   "Yrotation Xrotation Zrotation", "Yrotation Zrotation Xrotation"])
def test_channel_orders_world_positions(order):
    rng = np.random.default_rng(0)
    vals = rng.uniform(-90, 90, size=(2, 6))
    pos = np.array([[10.0, 90.0, -20.0], [15.0, 92.0, -18.0]])
    frames = [" ".join(f"{v:.6f}" for v in np.r_[pos[k], vals[k]]) for k in range(2)]
    text = TWO_JOINTS.format(order=order, length=40, f0=frames[0], f1=frames[1])
    m = parse_bvh(text, scale=0.01)
    assert m.joint_names == ("Hips", "Child", "Child_end")
    assert m.frame_time == 0.5 and m.frames.shape == (2, 9)
    seq = "".join(c[0] for c in order.split())
    P = m.world_positions()
    for k in range(2):
        R0 = Rotation.from_euler(seq, vals[k, :3], degrees=True).as_matrix()
        R1 = R0 @ Rotation.from_euler("ZXY", vals[k, 3:], degrees=True).as_matrix()
        root = pos[k] * 0.01
        child = root + R0 @ [0, 0.4, 0]
        end = child + R1 @ [0, 0.4, 0]
        expected = np.stack([root, child, end]) @ BVH_TO_WORLD.T
        np.testing.assert_allclose(P[k], expected, atol=1e-6)


def test_y_up_becomes_z_up():
    text = TWO_JOINTS.format(order="Zrotation Yrotation Xrotation", length=0.8, f0="0 1 0 0 0 0 0 0 0",
                             f1="0 1 2 0 0 0 0 0 0")
    m = parse_bvh(text)
    P = m.world_positions()
    np.testing.assert_allclose(P[0, 0], [0, 0, 1])      # BVH y (up) -> our z
    np.testing.assert_allclose(P[1, 0], [2, 0, 1])      # BVH z (facing) -> our x
    assert P[0, 2, 2] > P[0, 1, 2] > P[0, 0, 2]


# --- a BVH written from our own model (known ground truth) ---------------------------------------
MB_NAMES = {"pelvis": "Hips", "spine_lower": "Spine", "spine_upper": "Spine1", "neck": "Neck", "head": "Head",
            "left_shoulder": "LeftArm", "left_elbow": "LeftForeArm", "left_wrist": "LeftHand",
            "right_shoulder": "RightArm", "right_elbow": "RightForeArm", "right_wrist": "RightHand",
            "left_hip": "LeftUpLeg", "left_knee": "LeftLeg", "left_ankle": "LeftFoot", "left_toe": "LeftToeBase",
            "right_hip": "RightUpLeg", "right_knee": "RightLeg", "right_ankle": "RightFoot",
            "right_toe": "RightToeBase"}
POSER_NAMES = {"pelvis": "hip", "spine_lower": "abdomen", "spine_upper": "chest", "neck": "neck", "head": "head",
               "left_shoulder": "lShldr", "left_elbow": "lForeArm", "left_wrist": "lHand",
               "right_shoulder": "rShldr", "right_elbow": "rForeArm", "right_wrist": "rHand",
               "left_hip": "lThigh", "left_knee": "lShin", "left_ankle": "lFoot", "left_toe": "lToe",
               "right_hip": "rThigh", "right_knee": "rShin", "right_ankle": "rFoot", "right_toe": "rToe"}


def write_bvh_from_model(model, X, names, *, unit=1.0, order="ZXY", collars=True):
    """BVH text (y up, facing +z) whose joints follow `model` posed by X; lengths / unit."""
    M = BVH_TO_WORLD
    T = model.joint_names
    kids = {j: [k for k in range(len(T)) if model.parents[k] == j] for j in range(len(T))}
    Rloc = {}
    for j in range(len(T)):
        R = np.broadcast_to(np.eye(3), (len(X), 3, 3))
        for d in model.joint_dofs[j] if j else ():
            R = R @ Rotation.from_euler("XYZ"[model.dof_axis[d]], X[:, d][:, None]).as_matrix()
        Rloc[j] = R
    Rloc[0] = Rotation.from_rotvec(X[:, 3:6]).as_matrix()
    cols = []  # per frame channel values
    lines = ["HIERARCHY"]
    chan = " ".join(f"{c}rotation" for c in order)

    def emit(j, depth, offset):
        ind = "  " * depth
        name = names.get(T[j])
        is_end = name is None or not kids[j] and T[j].endswith(("toe", "hand", "top"))
        if is_end:
            lines.extend([f"{ind}End Site", f"{ind}{{", f"{ind}  OFFSET {' '.join(f'{v:.6f}' for v in offset)}",
                          f"{ind}}}"])
            return
        lines.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {name}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {' '.join(f'{v:.6f}' for v in offset)}")
        lines.append(f"{ind}  CHANNELS {6 if j == 0 else 3} {'Xposition Yposition Zposition ' if j == 0 else ''}{chan}")
        Rb = M.T @ Rloc[j] @ M
        if j == 0:
            cols.append((X[:, :3] @ M) / unit)
        cols.append(Rotation.from_matrix(Rb).as_euler(order, degrees=True))
        for k in kids[j]:
            off = M.T @ model.offsets[k] / unit
            if collars and T[k].endswith("shoulder"):
                side = "Left" if T[k].startswith("left") else "Right"
                lines.extend([f"{ind}  JOINT {side}Shoulder" if names is MB_NAMES else f"{ind}  JOINT {side[0].lower()}Collar",
                              f"{ind}  {{", f"{ind}    OFFSET {' '.join(f'{v:.6f}' for v in off * 0.4)}",
                              f"{ind}    CHANNELS 3 {chan}"])
                cols.append(np.zeros((len(X), 3)))
                emit(k, depth + 2, off * 0.6)
                lines.append(f"{ind}  }}")
            else:
                emit(k, depth + 1, off)
        lines.append(f"{ind}}}")

    emit(0, 0, np.zeros(3))
    data = np.hstack(cols)
    lines += ["MOTION", f"Frames: {len(X)}", "Frame Time: 0.0333333"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return "\n".join(lines) + "\n"


def model_poses(model, n, rng):
    X = np.tile(model.rest_pose(), (n, 1))
    X[:, 6:] = rng.uniform(model.lower[6:], model.upper[6:], size=(n, model.dof - 6)) * 0.5
    X[:, :3] += rng.normal(scale=0.3, size=(n, 3))
    X[:, 3:6] = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi, (n, 1))).as_rotvec()
    return X


@pytest.mark.parametrize("names,unit,expected_scale", [(MB_NAMES, 0.01, 0.01), (POSER_NAMES, 0.0254, 0.0254),
                                                       (MB_NAMES, 1.0, 1.0)])
def test_naming_styles_and_unit_detection(names, unit, expected_scale):
    model = make_model(39)
    X = model_poses(model, 6, np.random.default_rng(1))
    m = parse_bvh(write_bvh_from_model(model, X, names, unit=unit))
    assert m.scale == expected_scale
    mapping = map_skeleton(m)
    for ours, theirs in names.items():
        if ours.endswith("toe"):
            assert mapping[ours] in (theirs, theirs + "_end", f"{names[ours.replace('toe', 'ankle')]}_end")
        else:
            assert mapping[ours] == theirs, ours
    # world positions of the BVH equal our FK of the same poses
    P = m.world_positions()
    Q = joint_positions(model, X)
    for ours, theirs in names.items():
        np.testing.assert_allclose(P[:, m.joint_index(mapping[ours])], Q[:, model.joint_index(ours)], atol=2e-5)


@pytest.mark.parametrize("dof", [39, 28, 18])
def test_retarget_own_motion_is_exact(dof):
    source = make_model(39)
    X = model_poses(source, 8, np.random.default_rng(2))
    if dof != 39:  # poses the smaller model can represent: zero the dropped axes
        small = make_model(dof)
        X[:, [source.dof_names.index(n) for n in source.dof_names if n not in small.dof_names]] = 0.0
    m = parse_bvh(write_bvh_from_model(source, X, MB_NAMES, unit=0.01, order="YXZ"))
    model = model_from_bvh(m, dof)
    for j, name in enumerate(model.joint_names[1:], start=1):  # segment lengths from the skeleton
        if name in MB_NAMES and model.joint_names[model.parents[j]] in MB_NAMES:
            assert np.linalg.norm(model.offsets[j]) == pytest.approx(
                np.linalg.norm(source.offsets[source.joint_index(name)]), abs=2e-4)
    Y, report = retarget(m, model, reg=0.0)  # no regulariser: the exact poses are the optimum
    assert Y.shape == (8, dof)
    assert np.median(report.per_frame_mm) < 0.01 and report.mean_mm < 1.0
    np.testing.assert_allclose(Y[:, :3], X[:, :3], atol=0.02)
    _, report_reg = retarget(m, model)  # default: small pull of unobservable twists towards zero
    assert report_reg.mean_mm < 1.5
    model.validate_pose(Y)
    assert np.all(Y[:, 6:] >= model.lower[6:] - 1e-12) and np.all(Y[:, 6:] <= model.upper[6:] + 1e-12)


def test_resample():
    model = make_model(18)
    X = model_poses(model, 7, np.random.default_rng(3))
    X[:, 6:] *= 0.2
    m = parse_bvh(write_bvh_from_model(model, X, MB_NAMES, unit=0.01), scale=0.01)  # ~1 m: ambiguous unit
    r = m.resample(60.0)  # 30 fps -> 60 fps: originals on even frames, slerp in between
    assert r.n_frames == 2 * m.n_frames - 1 and r.frame_time == pytest.approx(1 / 60)
    P, Q = m.world_positions(), r.world_positions()
    np.testing.assert_allclose(Q[::2], P, atol=1e-4)  # the file's frame time is rounded (0.0333333 s)
    # in between: root position linear, every joint rotation the geodesic midpoint (slerp)
    np.testing.assert_allclose(Q[1::2, 0], 0.5 * (P[:-1, 0] + P[1:, 0]), atol=1e-4)
    R, _ = m.local_transforms()
    Rr, _ = r.local_transforms()
    half = R[:-1] @ exp_so3(0.5 * log_so3(np.swapaxes(R[:-1], -1, -2) @ R[1:]))
    np.testing.assert_allclose(Rr[1::2], half, atol=1e-4)
    down = m.resample(15.0)
    np.testing.assert_allclose(down.world_positions(), P[::2], atol=1e-4)
    with pytest.raises(BodyError, match="fps: expected a positive number, got -1"):
        m.resample(-1)


# --- bad input -------------------------------------------------------------------------------
def good_text(**kw):
    args = dict(order="Zrotation Yrotation Xrotation", length=40, f0="0 90 0 0 0 0 0 0 0", f1="0 90 0 0 0 0 0 0 0")
    args.update(kw)
    return TWO_JOINTS.format(**args)


def test_frame_line_wrong_length():
    text = good_text(f1="0 90 0 0 0 0 0 0")
    with pytest.raises(BodyError, match=r"line 20 \(frame 1\): expected 9 channel values, got 8"):
        parse_bvh(text)


def test_missing_channels():
    text = good_text().replace("    CHANNELS 3 Zrotation Xrotation Yrotation\n", "")
    with pytest.raises(BodyError, match="joint 'Child' has no CHANNELS line"):
        parse_bvh(text)
    text = good_text().replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Zrotation Xrotation")
    with pytest.raises(BodyError, match="CHANNELS of 'Child': expected 3 channel names .* got 'End'"):
        parse_bvh(text)


def test_wrong_frame_count_and_header():
    with pytest.raises(BodyError, match=r"expected 2 frame lines \('Frames: 2'\), got 1"):
        parse_bvh(good_text(f1=""))
    with pytest.raises(BodyError, match="Frame Time"):
        parse_bvh(good_text().replace("Frame Time: 0.5", "Frametime 0.5"))
    with pytest.raises(BodyError, match="no MOTION section"):
        parse_bvh(good_text().split("MOTION")[0])


def test_undetectable_unit_and_bad_scale():
    with pytest.raises(BodyError, match="cannot detect the length unit from the skeleton height 10"):
        parse_bvh(good_text(length=5))
    with pytest.raises(BodyError, match="scale: expected a positive number"):
        parse_bvh(good_text(), scale=0.0)
    assert parse_bvh(good_text(length=5), scale=0.1).offsets[1, 1] == pytest.approx(0.5)


def test_unknown_joint_layout(tmp_path):
    text = good_text().replace("Hips", "bone1").replace("Child", "bone2")
    path = tmp_path / "odd.bvh"
    path.write_text(text)
    m = load_bvh(path)
    with pytest.raises(BodyError, match=r"unknown joint layout in .*odd.bvh: could not find .*left_ankle.*"
                                        r"among the BVH joints \(bone1, bone2, bone2_end\)"):
        map_skeleton(m)
    with pytest.raises(BodyError, match="BVH file not found"):
        load_bvh(tmp_path / "missing.bvh")


def test_lower_body_bvh_maps_for_18_dof_only():
    model = make_model(18)
    X = model_poses(model, 3, np.random.default_rng(4))
    m = parse_bvh(write_bvh_from_model(model, X, MB_NAMES, unit=0.01), scale=0.01)
    assert set(map_skeleton(m, lower_body_only=True)) >= {"pelvis", "left_knee", "right_toe"}
    with pytest.raises(BodyError, match="could not find .*head"):
        map_skeleton(m)
    Y, rep = retarget(m, model_from_bvh(m, 18), reg=0.0)
    assert rep.mean_mm < 0.01 and rep.joints == ("pelvis", "left_hip", "left_knee", "left_ankle", "left_toe",
                                                 "right_hip", "right_knee", "right_ankle", "right_toe")


def test_retarget_onto_default_model_and_progress(tmp_path):
    """Any model with our joint names works (here the default shape); progress reports stages."""
    source = make_model(39)
    X = model_poses(source, 5, np.random.default_rng(5))
    m = parse_bvh(write_bvh_from_model(source, X, POSER_NAMES, unit=0.0254))
    calls = []
    Y, rep = retarget(m, make_model(28), progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (4, 4) and [c[0] for c in calls] == [1, 2, 3, 4]
    assert Y.shape == (5, 28) and rep.n_frames == 5 and "mean" in str(rep)
    # sized model saved as a shape file and rebuilt gives the same offsets
    from isa_mocap_ros.body import save_shape
    sized = model_from_bvh(m, 39)
    save_shape(sized.shape, tmp_path / "sized.yaml")
    again = make_model(39, shape=tmp_path / "sized.yaml")
    np.testing.assert_allclose(again.offsets, sized.offsets, atol=1e-6)
