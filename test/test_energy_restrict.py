"""Restricted evaluation of the silhouette energy (SilhouetteEnergy.restrict) and its use by Hierarchical
and the tracker: the same values as the full kernel (bit for bit), the contract, the same optimizer runs."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.energy import EnergyError, SilhouetteEnergy
from isa_mocap_ros.energy.restricted import RestrictedSilhouetteEnergy
from isa_mocap_ros.optim import Hierarchical, minimize
from isa_mocap_ros.vision import default_rig, look_at, render_mask

PARTS = ("root", "torso", "left_arm", "right_arm", "left_leg", "right_leg")


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.6
    x0[model.dof_names.index("left_shoulder_y")] = -0.5
    x0[model.dof_names.index("right_shoulder_x")] = -0.4
    x0[5] = 0.3
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in rig]
    return model, rig.cameras, x0, masks


def _distorted(model, x0):
    cams = [look_at((3.0, -1.5, 2.0), (0, 0, 1.0), fov_deg=70, dist=(-0.2, 0.05, 0.001, -0.001, 0.0), name="d0"),
            look_at((-3.0, 1.0, 1.5), (0, 0, 1.0), fov_deg=70, dist=(0.1, -0.02, 0.0, 0.0, 0.0), name="d1")]
    E = capsule_endpoints(model, x0)[0]
    return cams, [render_mask(c, E, model.capsule_radii) for c in cams]


SETTINGS = {
    "library defaults": {},
    "tracker sizes": dict(n_model_points=640, n_mask_points=384),
    "downsample 2": dict(downsample=2),
    "area term 2 (n_mask_points=0)": dict(n_mask_points=0),
    "a view skipped": dict(skip=1),
    "lens distortion": dict(distorted=True),
    "view weights": dict(weights=(1.0, 0.25, 0.0, 0.6)),
}


@pytest.mark.parametrize("name", list(SETTINGS))
def test_restricted_equals_full_bit_for_bit_in_every_partition(scene, name):
    """A few hundred poses per partition (3 bases x 100 poses; joint moves of 0.4 rad and bases off
    the rendered pose, so moving capsules overlap fixed ones, earlier and later in the processing
    order): max |difference| <= 1e-9 required; measured 0 (the same bits)."""
    model, cams, x0, masks = scene
    kw = dict(SETTINGS[name])
    if kw.pop("distorted", False):
        cams, masks = _distorted(model, x0)
    skip = kw.pop("skip", None)
    if skip is not None:
        masks = list(masks)
        masks[skip] = None
    weights = kw.pop("weights", None)
    en = SilhouetteEnergy(model, cams, masks, rng=np.random.default_rng(0), **kw)
    if weights is not None:
        en.set_masks(masks, weights)
    rng = np.random.default_rng(1)
    for part in PARTS:
        cols = model.partitions[part]
        for _ in range(3):
            base = np.clip(x0 + rng.normal(0, 0.2, model.dof), model.lower, model.upper)
            X = np.repeat(base[None], 100, axis=0)
            X[:, cols] += rng.normal(0, 0.4, (100, len(cols))) * np.where(cols < 3, 0.25, 1.0)
            f = en.restrict(base, cols)
            assert isinstance(f, RestrictedSilhouetteEnergy) and f.full == (part == "root")
            full, restricted = en(X), f(X)
            assert np.abs(full - restricted).max() <= 1e-9, (part, np.abs(full - restricted).max())
            np.testing.assert_array_equal(restricted, full, err_msg=part)


def test_moving_capsules_follow_the_kinematic_tree(scene):
    model, cams, x0, masks = scene
    en = SilhouetteEnergy(model, cams, masks)
    names = {n: i for i, n in enumerate(model.joint_names)}
    caps = [tuple(c) for c in np.asarray(model.capsules).tolist()]
    f = en.restrict(x0, model.partitions["left_arm"])
    got = {caps[c] for c in f.moving_capsules}
    want = {(names["left_shoulder"], names["left_elbow"]), (names["left_elbow"], names["left_wrist"]),
            (names["left_wrist"], names["left_hand"])}
    assert got == want and not f.full          # the shoulder girdle capsule does not move
    knee = en.restrict(x0, [model.knee_dofs[0]])
    assert len(knee.moving_capsules) == 2      # shank and foot
    assert en.restrict(x0, [0]).full and en.restrict(x0, model.partitions["root"]).full
    nothing = en.restrict(x0, [])              # no coordinate: every capsule fixed, a constant
    X = np.repeat(x0[None], 3, axis=0)
    np.testing.assert_array_equal(nothing(X), en(X))
    exact = SilhouetteEnergy(model, cams, masks, method="exact").restrict(x0, model.partitions["left_leg"])
    assert exact.full


def test_contract_and_bad_input(scene):
    model, cams, x0, masks = scene
    en = SilhouetteEnergy(model, cams, masks, rng=np.random.default_rng(0))
    cols = model.partitions["right_leg"]
    f = en.restrict(x0, cols)
    X = np.repeat(x0[None], 5, axis=0)
    X[:, cols] += 0.1
    X[3, 7] += 1e-12                            # outside the coordinates: never a silent value
    with pytest.raises(EnergyError, match=r"row 3 with coordinate 7"):
        f(X)
    X[3, 7] = x0[7]
    X[1, cols[0]] = np.nan                      # non-finite rows give +inf, as the full energy
    X[2, 12] = np.inf
    out = f(X)
    assert np.isinf(out[1]) and np.isinf(out[2])
    np.testing.assert_array_equal(out, en(X))
    n = en.n_evals
    f(X[0])                                     # one row as (D,)
    assert en.n_evals == n + 1                  # counted in the parent
    for bad, msg in [(x0[:5], "x_base"), (np.full(model.dof, np.nan), "x_base")]:
        with pytest.raises(EnergyError, match=msg):
            en.restrict(bad, cols)
    for bad in ([model.dof], [-1], [3, 3], [0.5], [[1, 2]]):
        with pytest.raises(EnergyError, match="coords"):
            en.restrict(x0, bad)
    with pytest.raises(EnergyError, match="X: expected shape"):
        f(np.zeros((2, 5)))
    en.set_masks(masks)                         # a new frame: the restriction is stale
    with pytest.raises(EnergyError, match="restrict again"):
        f(X[:1])
    with pytest.raises(EnergyError, match="masks"):
        SilhouetteEnergy(model, cams).restrict(x0, cols)
    with pytest.raises(EnergyError, match="energy: expected a SilhouetteEnergy, received object"):
        RestrictedSilhouetteEnergy(object(), x0, cols)


def test_batched_and_one_by_one_agree(scene):
    model, cams, x0, masks = scene
    en = SilhouetteEnergy(model, cams, masks, n_model_points=640, n_mask_points=384)
    cols = model.partitions["torso"]
    X = np.repeat(x0[None], 7, axis=0)
    X[:, cols] += np.random.default_rng(2).normal(0, 0.3, (7, len(cols)))
    f = en.restrict(x0, cols)
    np.testing.assert_array_equal(f(X), np.concatenate([f(x) for x in X]))


# ---------------------------------------------------------------------- Hierarchical
class _Recorded:
    """A batch energy with ``restrict`` returning an energy that computes the same bits another way."""

    def __init__(self, fn, give=True):
        self.fn = fn
        self.calls = []
        self.give = give

    def __call__(self, X):
        return self.fn(X)

    def restrict(self, x_base, coords):
        self.calls.append((x_base.copy(), np.array(coords)))
        if not self.give:
            return None
        fixed = np.setdiff1d(np.arange(x_base.size), coords)

        def restricted(X):
            assert np.all(X[:, fixed] == x_base[fixed])     # every row equals the base outside coords
            return self.fn(X)
        return restricted


def _sphere(X):
    return np.sum((X - 1.0) ** 2, axis=1)


def _same_runs(a, b):
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.best_x, b.best_x)
    assert (a.n_evals, a.n_iter, a.energy) == (b.n_evals, b.n_iter, b.energy)
    assert [h.n_evals for h in a.history] == [h.n_evals for h in b.history]


@pytest.mark.parametrize("inner", ["isa", "cmaes", "de"])
def test_hierarchical_restricts_each_partition_and_runs_the_same(inner):
    parts = [np.array([0, 1, 2]), np.array([3, 4]), np.array([6])]
    def run(energy):
        opt = Hierarchical(np.zeros(7), 0.5, partitions=parts, optimizer=inner, rng=np.random.default_rng(4))
        res = minimize(opt, energy, max_evals=900)
        return res, [n for _, n in opt.partition_log] + [opt._inner_used]

    plain, spent = run(_sphere)
    rec = _Recorded(_sphere)
    got, spent_rec = run(rec)
    _same_runs(plain, got)
    assert spent_rec == spent and sum(spent) == plain.n_evals        # budgets and counts as before
    assert [c.tolist() for _, c in rec.calls] == [p.tolist() for p in parts]     # once per partition
    # the base is the estimate when the partition starts: earlier partitions optimised, later ones at x0
    assert np.all(rec.calls[0][0] == 0.0)
    assert np.all(rec.calls[2][0][[3, 4]] != 0.0) and np.all(rec.calls[2][0][[5, 6]] == 0.0)
    none = _Recorded(_sphere, give=False)                   # restrict may decline: the energy itself
    _same_runs(plain, run(none)[0])
    assert len(none.calls) == 3


def test_hierarchical_with_the_silhouette_energy_same_result_and_counts(scene):
    model, cams, x0, masks = scene
    parts = [np.asarray(model.partitions[k]) for k in PARTS]
    start = np.clip(x0 + np.random.default_rng(3).normal(0, 0.05, model.dof), model.lower, model.upper)

    def run(energy):
        opt = Hierarchical(start, 0.05, partitions=parts, optimizer="isa", n_particles=30,
                           rng=np.random.default_rng(5), bounds=(model.lower, model.upper),
                           rotation_blocks=model.rotation_blocks)
        return minimize(opt, energy, max_evals=900)

    en = SilhouetteEnergy(model, cams, masks, n_model_points=640, n_mask_points=384)
    plain = run(lambda X: en(X))                # no restrict: the full kernel throughout
    n_plain = en.n_evals
    got = run(en)                               # restricted per partition
    _same_runs(plain, got)
    assert en.n_evals == 2 * n_plain == 2 * plain.n_evals


# ---------------------------------------------------------------------- tracker
def test_tracker_restricted_total_energy_adds_the_prior(scene):
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.energy.prior import ParzenPrior
    from isa_mocap_ros.tracking import Tracker, TrackerConfig, frame_masks

    model, cams, x0, masks = scene
    prior = ParzenPrior(generate_motion("walk", model, duration_s=1.0, fps=30, rng=np.random.default_rng(5)))
    tr = Tracker(model, cams, TrackerConfig.from_flat(optimizer="h-isa", evals=600, prior_eta=0.01), prior=prior)
    tr.initialize(pose=x0)
    ctx = tr.frame_context(0)
    ctx.masks = list(masks)
    frame_masks.set_masks(tr, ctx)
    cols = model.partitions["left_arm"]
    X = np.repeat(x0[None], 6, axis=0)
    X[:, cols] += np.random.default_rng(6).normal(0, 0.2, (6, len(cols)))
    np.testing.assert_array_equal(tr.restricted_energy(x0, cols)(X), tr.total_energy(X))
    tr.energy = lambda X: np.zeros(len(X))      # a data term without restrict: none
    assert tr.restricted_energy(x0, cols) is None


def test_tracker_steps_are_the_same_with_and_without_restriction(scene, monkeypatch):
    from isa_mocap_ros.tracking import Tracker, TrackerConfig
    from isa_mocap_ros.tracking.objective import TotalEnergy

    model, cams, x0, masks = scene
    walk = [x0.copy() for _ in range(3)]
    for k, x in enumerate(walk):
        x[0] += 0.02 * k
        x[model.knee_dofs[0]] += 0.1 * k
    frames = [[render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in cams] for x in walk]

    def track():
        tr = Tracker(model, cams, TrackerConfig.from_flat(optimizer="h-isa", evals=850, seed=2))
        tr.initialize(pose=walk[0])
        return tr, [tr.step(frames[k], k) for k in (1, 2)]

    calls = []
    orig = SilhouetteEnergy.restrict
    monkeypatch.setattr(SilhouetteEnergy, "restrict", lambda self, x, c: calls.append(1) or orig(self, x, c))
    tr, with_ = track()
    # once per partition and frame, the torso stage's (from 830 with the contour stage) and the limb stage's (one per
    # limb: its proposals scored on the energy restricted to that limb), and the untwist stage's (one per leg)
    assert len(calls) == 2 * (len(PARTS) + 1 + 4 + 2)
    monkeypatch.setattr(TotalEnergy, "restrict", lambda self, x, c: None)
    n = tr.energy.n_evals
    tr2, without = track()
    for a, b in zip(with_, without):
        np.testing.assert_array_equal(a.x, b.x)
        assert a.energy == b.energy and a.n_evals == b.n_evals and 850 - 4 < a.n_evals <= 850   # whole generations
    assert tr2.energy.n_evals == n
