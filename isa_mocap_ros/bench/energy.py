"""Silhouette energy speed: evaluations/s of the fast kernel and of the exact raster reference.

Scene: the 39-DOF model in a walking-like pose at the centre of the default rig (4 views,
320x240), masks rendered from it; a batch of poses spread around it (root ±5 cm, angles ±0.15 rad),
as an optimizer generation would be. The fast energy uses the tracker's sample sizes
(``TrackerConfig`` defaults: ``n_model_points``, ``n_mask_points``, ``downsample``; printed in the
output). Both energies are timed in the same run: the fast kernel on
the full batch (median of ``--repeats`` calls after a warm-up call that also loads the numba
cache), the exact reference (``render_mask`` per pose and view, pixel counting) on ``--exact-batch``
poses and scaled (it is linear in the batch size). Wall-clock time, all numba threads; the fast
kernel also per CPU second of the process (``fast_evals_per_cpu_s``, every thread counted: the figure
other processes' load leaves alone, for before/after comparisons on a shared machine).
"""
from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.energy import SilhouetteEnergy
from isa_mocap_ros.tracking.tracker import TrackerConfig
from isa_mocap_ros.vision import default_rig, render_mask


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--views", type=int, default=4)
    p.add_argument("--dof", type=int, default=39, choices=(18, 28, 39))
    p.add_argument("--batch", type=int, default=1500, help="poses per call of the fast energy")
    p.add_argument("--exact-batch", type=int, default=100, help="poses timed with the exact reference")
    p.add_argument("--repeats", type=int, default=9, help="timed calls of the fast energy (median)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="small sizes (for tests)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    if args.quick:
        args.batch, args.exact_batch, args.repeats = min(args.batch, 64), min(args.exact_batch, 4), 2
    model = make_model(args.dof)
    rig = default_rig(n_views=args.views)
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.5
    x0[model.dof_names.index("left_hip_y")] = -0.3
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in rig]
    rng = np.random.default_rng(args.seed)
    X = x0 + np.concatenate([rng.normal(0, 0.05, (args.batch, 6)),
                             rng.normal(0, 0.15, (args.batch, model.dof - 6))], axis=1)
    tc = TrackerConfig()        # the sample sizes the tracker evaluates with
    obj = tc.objective
    fast = SilhouetteEnergy(model, rig, masks, downsample=obj.downsample, n_model_points=obj.n_model_points,
                            n_mask_points=obj.n_mask_points, rng=np.random.default_rng(args.seed))
    exact = SilhouetteEnergy(model, rig, masks, method="exact")
    fast(X)
    exact(X[:1])
    times = []
    cpu = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        c0 = time.process_time()
        fast(X)
        cpu.append(time.process_time() - c0)
        times.append(time.perf_counter() - t0)
    t_fast = float(np.median(times))
    nb = min(args.exact_batch, args.batch)
    t0 = time.perf_counter()
    exact(X[:nb])
    t_exact = time.perf_counter() - t0
    fast_rate = args.batch / t_fast
    exact_rate = nb / t_exact
    out = {"views": args.views, "dof": args.dof, "batch": args.batch, "fast_evals_per_s": round(fast_rate, 1),
           "exact_evals_per_s": round(exact_rate, 1),
           # per CPU second of the process (every thread): what other processes' load does not change
           "fast_evals_per_cpu_s": round(args.batch / float(np.median(cpu)), 1) if np.median(cpu) > 0 else None,
           "ratio": round(fast_rate / exact_rate, 1),
           "exact_batch": nb, "n_model_points": tc.objective.n_model_points, "n_template": fast.n_template,
           "n_mask_points": fast.n_mask_points, "downsample": fast.downsample, "threads": numba.get_num_threads()}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"silhouette energy, {args.views} views 320x240, {args.dof} DOF, batch {args.batch}, "
              f"{numba.get_num_threads()} threads")
        print(f"  fast  : {fast_rate:12.0f} evals/s  (median of {args.repeats}; tracker sample sizes: "
              f"n_model_points {tc.objective.n_model_points} -> template {fast.n_template} points, "
              f"{fast.n_mask_points} foreground points per view, downsample {fast.downsample}; "
              f"fastest call {args.batch / min(times):.0f} evals/s)")
        print(f"  exact : {exact_rate:12.0f} evals/s  (measured on {nb} poses)")
        print(f"  ratio : {fast_rate / exact_rate:12.0f}x")
    return 0
