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

The batch of 1500 poses in one call is the kernel's best case, not what the tracker's search asks of it:
its main search (h-isa, compiled per partition, ``optim/compiled_search.py``) calls the kernel once per
generation of 30 particles, and in every partition but the root's with the *restricted* kernel (only the
capsules the partition moves are recomputed). So the bench also runs that search — the tracker's
optimizer, parameters, partitions and search box (``Tracker.search_box``) around the scene's pose, from a
start 2 cm / 0.1 rad off it, ``--search-evals`` evaluations — and reports its **effective rate**:
evaluations per second of the whole search (kernels, launches, the optimizer's compiled steps),
wall clock and per CPU second (``search_*``), and the same with half of each partition's generations on the
energy's coarse level (two of the four views, ``search_coarse_*``; ``SearchConfig.coarse_fraction``, off in the
tracker by default).

The scanline energy (``SilhouetteEnergy(method="raster")``: Eq. 4 counted on the pixel grid, no sample) is timed the
same way on the same batch (``raster_*``; every pixel row, and every second row as ``raster2_*``), and both it and
the fast kernel are compared with the exact reference on the exact batch (``*_mean_abs_diff``: mean |f - exact|),
and the tracker's search runs on it too (``search_raster_*``: its restricted kernel and the compiled search; the
tracker's default energy since decision 017; ``isa-mocap track --energy fast`` selects the sampled kernel), also with
half of each partition's generations on its coarse level, every second pixel row (``search_raster_coarse_*``).
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


#: The share of the search's generations on the coarse level in the ``search_coarse_*`` figures.
COARSE_FRACTION = 0.5


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--views", type=int, default=4)
    p.add_argument("--dof", type=int, default=39, choices=(18, 28, 39))
    p.add_argument("--batch", type=int, default=1500, help="poses per call of the fast energy")
    p.add_argument("--exact-batch", type=int, default=100, help="poses timed with the exact reference")
    p.add_argument("--repeats", type=int, default=9, help="timed calls of the fast energy (median)")
    p.add_argument("--search-evals", type=int, default=1500, help="evaluations of the timed h-isa search")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="small sizes (for tests)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    if args.quick:
        args.batch, args.exact_batch, args.repeats = min(args.batch, 64), min(args.exact_batch, 4), 2
        args.search_evals = min(args.search_evals, 360)
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
    raster = SilhouetteEnergy(model, rig, masks, method="raster")
    raster2 = SilhouetteEnergy(model, rig, masks, method="raster", downsample=2)
    exact(X[:1])
    times, cpu = _timed(fast, X, args.repeats)
    t_fast = float(np.median(times))
    nb = min(args.exact_batch, args.batch)
    t0 = time.perf_counter()
    f_exact = exact(X[:nb])
    t_exact = time.perf_counter() - t0
    ras = {}
    for key, en in (("raster", raster), ("raster2", raster2)):
        wall, c = _timed(en, X, args.repeats)
        ras.update({f"{key}_evals_per_s": round(args.batch / float(np.median(wall)), 1),
                    f"{key}_evals_per_cpu_s": round(args.batch / float(np.median(c)), 1) if np.median(c) > 0 else None,
                    f"{key}_ratio": round(args.batch / float(np.median(wall)) / (nb / t_exact), 1),
                    f"{key}_mean_abs_diff": round(float(np.abs(en(X[:nb]) - f_exact).mean()), 6)})
    search = search_rate(model, rig, fast, x0, args.search_evals, args.repeats, args.seed)
    search.update(search_rate(model, rig, fast, x0, args.search_evals, args.repeats, args.seed, COARSE_FRACTION,
                              "search_coarse"))
    search.update(search_rate(model, rig, raster, x0, args.search_evals, args.repeats, args.seed, key="search_raster"))
    search.update(search_rate(model, rig, raster, x0, args.search_evals, args.repeats, args.seed, COARSE_FRACTION,
                              "search_raster_coarse"))
    fast_rate = args.batch / t_fast
    exact_rate = nb / t_exact
    out = {"views": args.views, "dof": args.dof, "batch": args.batch, "fast_evals_per_s": round(fast_rate, 1),
           "exact_evals_per_s": round(exact_rate, 1),
           # per CPU second of the process (every thread): what other processes' load does not change
           "fast_evals_per_cpu_s": round(args.batch / float(np.median(cpu)), 1) if np.median(cpu) > 0 else None,
           "ratio": round(fast_rate / exact_rate, 1),
           **search, "search_ratio": round(search["search_evals_per_s"] / exact_rate, 1),
           "fast_mean_abs_diff": round(float(np.abs(fast(X[:nb]) - f_exact).mean()), 6), **ras, "exact_batch": nb, "n_model_points": tc.objective.n_model_points, "n_template": fast.n_template,
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
        print(f"  search: {search['search_evals_per_s']:12.0f} evals/s  (the tracker's h-isa, "
              f"{search['search_evals']} evaluations in generations of {search['search_generation']}, restricted "
              f"kernel in {search['search_restricted_share']:.0%} of them; {search['search_evals_per_cpu_s']:.0f} per "
              f"CPU second; median of {args.repeats}; {search['search_evals_per_s'] / exact_rate:.0f}x the exact)")
        print(f"  search, {COARSE_FRACTION:.0%} of its generations on two views: {search['search_coarse_evals_per_s']:.0f} "
              f"evals/s ({search['search_coarse_evals_per_cpu_s']:.0f} per CPU second)")
        for key, rows in (("raster", "every pixel row"), ("raster2", "every second row")):
            print(f"  {key:7s}: {out[key + '_evals_per_s']:12.0f} evals/s  (scanline count, {rows}; "
                  f"{out[key + '_evals_per_cpu_s']:.0f} per CPU second; {out[key + '_ratio']:.0f}x the exact; mean "
                  f"|f - exact| {out[key + '_mean_abs_diff']:.5f}, fast kernel {out['fast_mean_abs_diff']:.5f})")
        print(f"  search on the scanline energy: {out['search_raster_evals_per_s']:.0f} evals/s "
              f"({out['search_raster_evals_per_cpu_s']:.0f} per CPU second); {COARSE_FRACTION:.0%} of its generations "
              f"on every second row: {out['search_raster_coarse_evals_per_s']:.0f} evals/s "
              f"({out['search_raster_coarse_evals_per_cpu_s']:.0f} per CPU second)")
    return 0


def _timed(energy, X: np.ndarray, repeats: int) -> tuple[list, list]:
    """Wall and CPU seconds of ``repeats`` calls ``energy(X)`` after a warm-up call (numba cache, scratch)."""
    energy(X)
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        energy(X)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return wall, cpu


def search_rate(model, rig, energy, x_true, evals: int, repeats: int, seed: int, coarse_fraction: float = 0.0,
                key: str = "search") -> dict:
    """The effective rate of the tracker's main search on ``energy`` (module docstring): the median over
    ``repeats`` runs (the same start and draws each time) after one warm-up run; ``coarse_fraction`` of each
    partition's generations on the energy's coarse level (two views, ``SearchConfig.coarse_fraction``)."""
    from isa_mocap_ros.optim import compiled_search, make_optimizer
    from isa_mocap_ros.tracking.tracker import Tracker

    tr = Tracker(model, rig, TrackerConfig(), energy=energy)
    rng = np.random.default_rng([seed, 1])
    start = x_true.copy()
    start[:3] += rng.normal(0.0, 0.02, 3)
    start[3:] += rng.normal(0.0, 0.1, model.dof - 3)
    lo, hi, spread = tr.search_box(start)
    start = np.clip(start, lo, hi)
    params = tr.config.search.params()
    params.update(partitions=tr.partitions, whole_generations=True)

    def once():
        opt = make_optimizer(tr.config.search.optimizer, start, spread, rng=np.random.default_rng([seed, 2]),
                             bounds=(lo, hi), rotation_blocks=model.rotation_blocks, **params)
        run = compiled_search.search(opt, energy, evals, paused=True, coarse_fraction=coarse_fraction)
        if run is None:
            raise RuntimeError(f"bench energy: the tracker's optimizer {tr.config.search.optimizer!r} does not run "
                               "compiled on this energy")
        return opt, run, run.advance().result()

    opt, run, res = once()
    wall, cpu = [], []
    for _ in range(max(1, repeats)):
        t0, c0 = time.perf_counter(), time.process_time()
        once()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    n = res.n_evals
    # the partitions without a root coordinate run the restricted kernel (RestrictedSilhouetteEnergy.full)
    restricted = sum(s for q, s in zip(run.parts, run.shares) if not np.any(np.asarray(q) < 6))
    c = float(np.median(cpu))
    out = {f"{key}_evals_per_s": round(n / float(np.median(wall)), 1),
           f"{key}_evals_per_cpu_s": round(n / c, 1) if c > 0 else None}
    if key == "search":
        out.update({"search_evals": int(n), "search_generation": int(opt.params.get("n_particles", 0)),
                    "search_restricted_share": round(restricted / n, 3)})
    return out
