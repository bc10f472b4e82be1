"""The background of a recording without empty frames when the person is found in each frame
(vision/stable_background.py with ``person``, vision/robust_mode.py's masked mode, vision/person_masks.py),
and the mask quality measured against a reference stick figure (eval/mask_quality.py).

The model-based tests read the Pose2Sim demo from ../shared (skipped when absent) and need the landmark
model (`make models`); a few frames, seconds."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from conftest import SHARED
from isa_mocap_ros.eval.mask_quality import mask_quality, mean_quality, skeleton_image
from isa_mocap_ros.vision import VisionError, default_rig
from isa_mocap_ros.vision.robust_mode import _masked_mode_numba, _masked_mode_numpy
from isa_mocap_ros.vision.stable_background import (SOURCE_INPAINTED, SOURCE_MODE, SOURCE_PLATE,
                                                    estimate_background)

DEMO = SHARED / "data" / "real" / "pose2sim_demo"


def test_masked_mode_compiled_equals_numpy():
    rng = np.random.default_rng(3)
    for _ in range(4):
        stack = rng.integers(0, 90, (11, 6, 9, 3)).astype(np.uint8)
        valid = rng.random((11, 6, 9)) < 0.6
        a, b = _masked_mode_numpy(stack, valid, 20.0), _masked_mode_numba(stack, valid, 20.0)
        np.testing.assert_allclose(a[0], b[0], atol=1e-4)
        np.testing.assert_array_equal(a[1], b[1])
        np.testing.assert_array_equal(a[2], b[2])
    # a pixel without a valid sample: count and n_valid 0
    stack = np.full((3, 1, 1, 3), 50, np.uint8)
    mu, count, n = _masked_mode_numba(stack, np.zeros((3, 1, 1), bool), 20.0)
    assert count[0, 0] == n[0, 0] == 0


def _scene(n=30, h=60, w=80, seed=0):
    """A textured room, a 'person' whose torso stands still at columns 30-41 in every frame while an arm
    swings across columns 42-69, and a scene shot with a second person (a ghost) at columns 5-16 and behind
    the torso's upper half."""
    rng = np.random.default_rng(seed)
    room = rng.integers(40, 220, (h // 4, w // 4, 3)).astype(np.uint8).repeat(4, 0).repeat(4, 1)
    frames, person = [], []
    for k in range(n):
        f = room.copy() + rng.integers(-3, 4, room.shape).astype(np.int16)
        p = np.zeros((h, w), bool)
        p[10:55, 30:42] = True                                  # the torso: never moves
        x0 = 42 + (k * 5) % 24
        p[20:26, x0:x0 + 6] = True                              # the arm
        f[p] = (200, 160, 130)
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
        person.append(p)
    plate = room.copy()
    ghost = np.zeros((h, w), bool)
    ghost[5:58, 5:17] = True
    ghost[10:30, 28:44] = True
    plate[ghost] = (30, 200, 60)
    return np.stack(frames), np.stack(person), room, plate, ghost


def test_background_with_the_person_found_keeps_scene_shot_people_out():
    F, P, room, plate, ghost = _scene()
    err = lambda img, where: np.abs(img.astype(int) - room.astype(int)).max(axis=-1)[where].mean()   # noqa: E731
    # without the person: still pixels beside the torso are taken from the plate, the ghost with them
    old = estimate_background(F, plates=[plate])
    wrong = (old.source == SOURCE_PLATE) & ghost & ~P.any(axis=0)
    # with the person and the plate's person known: the room everywhere the person leaves; under the torso
    # the plate where no ghost stands, the surroundings inpainted where one does
    new = estimate_background(F, plates=[plate], person=P, plate_people=[ghost], person_grow=0.0)
    free = ~P.any(axis=0)
    assert wrong.any() and err(old.image, wrong) > 40
    assert err(new.image, free) < 4 and err(new.image, wrong) < 4
    assert np.all(new.source[free] == SOURCE_MODE)
    torso = P.all(axis=0)
    assert np.all(new.source[torso & ~ghost] == SOURCE_PLATE) and err(new.image, torso & ~ghost) < 4
    assert np.all(new.source[torso & ghost] == SOURCE_INPAINTED)
    # the person is never "visible background"; the frames for the segmenter show the room
    assert not new.visible[P].any()
    frames = new.frames(5, F)
    assert np.abs(frames.astype(int) - room.astype(int)).max(axis=-1)[:, free].mean() < 5
    # without plates the torso is inpainted; with a plate and no plate_people the plate is taken
    assert np.all(estimate_background(F, person=P, person_grow=0.0).source[torso] == SOURCE_INPAINTED)
    assert np.all(estimate_background(F, plates=[plate], person=P, person_grow=0.0).source[torso] == SOURCE_PLATE)


def test_background_with_person_bad_shapes():
    F, P, _, plate, ghost = _scene(n=5)
    with pytest.raises(VisionError, match=r"person: expected shape \(5, 60, 80\)"):
        estimate_background(F, person=P[:, :10])
    with pytest.raises(VisionError, match="plate_people: expected one mask per plate"):
        estimate_background(F, plates=[plate], person=P, plate_people=[ghost, ghost])


def test_mask_quality_against_the_stick_figure():
    cam = default_rig(n_views=1, width=160, height=120).cameras[0]
    names = ("right_hip", "right_knee", "left_hip", "left_knee", "neck", "head")
    c = cam.center
    fwd = -c / np.linalg.norm(c)                       # towards the rig's centre
    P = np.array([[0.1, 0, 0.9], [0.1, 0, 0.5], [-0.1, 0, 0.9], [-0.1, 0, 0.5], [0, 0, 1.4], [0, 0, 1.6]])
    assert np.all(cam.depth(P) > 0), fwd
    fig, uv = skeleton_image(cam, P, names, width_px=9)
    assert fig.any() and np.all(np.isfinite(uv))
    q = mask_quality(cam, P, names, fig)
    assert q.beyond == 0.0 and q.core_missed == 0.0 and q.keypoints_on == 1.0
    blob = fig.copy()
    cv2.circle(blob, (5, 5), 4, 255, -1)               # foreground far from the person
    assert mask_quality(cam, P, names, blob).beyond > 0.0
    q0 = mask_quality(cam, P, names, np.zeros_like(fig))
    assert q0.core_missed == 1.0 and q0.keypoints_on == 0.0 and np.isnan(q0.beyond)
    m = mean_quality([q, q0])
    assert m.beyond == 0.0 and m.core_missed == 0.5
    with pytest.raises(ValueError, match="mask: expected"):
        mask_quality(cam, P, names, fig[:10])


def _demo_frames(view: int, ks, width=160):
    path = DEMO / "balancing" / f"cam0{view}.mp4"
    if not path.is_file():
        pytest.skip(f"Pose2Sim demo not found at {DEMO} (set ISA_MOCAP_SHARED to the shared/ folder)")
    cap = cv2.VideoCapture(str(path))
    out, k = [], 0
    while len(out) < len(ks):
        ok, f = cap.read()
        if not ok:
            break
        if k in ks:
            h = round(f.shape[0] * width / f.shape[1])
            out.append(cv2.cvtColor(cv2.resize(f, (width, h), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB))
        k += 1
    cap.release()
    return np.stack(out)


def test_demo_person_found_in_frames_and_in_a_scene_shot(landmark_model):
    """cam03 (1088x1920, no letterbox) at 160 px: the model finds the performer in each of 4 frames (a body-sized
    region), and finds the person standing in cam01's scene shot (rows 20-55 %, columns 10-40 % of it)."""
    from isa_mocap_ros.vision.landmarks import PoseLandmarker
    from isa_mocap_ros.vision.person_masks import PERSON_THRESHOLD, find_person, people_in_plates

    F = _demo_frames(3, {0, 30, 60, 99})
    lm = PoseLandmarker(landmark_model)
    prob = find_person(F, landmarker=lm)
    assert prob.shape == F.shape[:3] and prob.dtype == np.float32
    person = prob > PERSON_THRESHOLD
    H, W = F.shape[1:3]
    for k in range(len(F)):
        share = person[k].mean()
        assert 0.02 < share < 0.3, (k, share)
        ys, xs = np.nonzero(person[k])
        assert ys.max() - ys.min() > 0.35 * H               # head to feet, not a blob
    assert np.array_equal(prob, find_person(F, landmarker=lm))   # deterministic
    scene = cv2.imread(str(DEMO / "calibration" / "extrinsics" / "cam01_ext.png"))
    scene = cv2.cvtColor(cv2.resize(scene, (W, H), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB)
    where = np.zeros((H, W), bool)
    where[int(0.2 * H):int(0.55 * H), int(0.1 * W):int(0.4 * W)] = True   # the person in cam01's scene shot
    (found,) = people_in_plates([scene], where, landmarker=lm)
    assert found.mean() > 0.015
    ys, xs = np.nonzero(found)
    assert 0.15 * H < ys.mean() < 0.6 * H and 0.05 * W < xs.mean() < 0.45 * W
    (nobody,) = people_in_plates([scene], np.zeros((H, W), bool), landmarker=lm)
    assert not nobody.any()
