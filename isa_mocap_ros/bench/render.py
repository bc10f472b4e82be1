"""Renderer speed: ms per view of render / render_mask (320x240, 16 capsules) and project_batch.

Scene: a hand-made 16-capsule stick figure (a standing person, 1.7 m) at the centre of the default
4-camera rig (``config/rigs/default_4cam.yaml``), textured background. Each figure is the median
(and the minimum) over ``--repeats`` runs of all views, divided by the number of views; the first call per camera
(per-camera ray set-up, cached afterwards) is reported apart. ``project_batch`` projects
``--particles`` x 16 x 2 capsule end points into all views (what the energy does per generation).
"""
from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np

from isa_mocap_ros.vision import default_rig, make_background, project_batch, render, render_mask
from isa_mocap_ros.vision.render import clear_ray_cache

_J = dict(pelvis=(0, 0, 0.95), neck=(0, 0, 1.45), head=(0, 0, 1.62), lsh=(0, 0.19, 1.42), rsh=(0, -0.19, 1.42),
          lel=(0.05, 0.25, 1.15), rel=(-0.05, -0.25, 1.15), lwr=(0.2, 0.28, 1.0), rwr=(0.1, -0.3, 0.92),
          lhip=(0, 0.1, 0.92), rhip=(0, -0.1, 0.92), lkn=(0.15, 0.11, 0.52), rkn=(-0.05, -0.1, 0.5),
          lan=(0.05, 0.12, 0.1), ran=(-0.2, -0.1, 0.1), ltoe=(0.2, 0.12, 0.04), rtoe=(-0.06, -0.1, 0.03))
_SEG = [("pelvis", "neck", 0.14, 0.15), ("neck", "head", 0.05, 0.1), ("lsh", "lel", 0.055, 0.045),
        ("rsh", "rel", 0.055, 0.045), ("lel", "lwr", 0.045, 0.035), ("rel", "rwr", 0.045, 0.035),
        ("lhip", "lkn", 0.08, 0.055), ("rhip", "rkn", 0.08, 0.055), ("lkn", "lan", 0.055, 0.04),
        ("rkn", "ran", 0.055, 0.04), ("lan", "ltoe", 0.04, 0.035), ("ran", "rtoe", 0.04, 0.035),
        ("lsh", "rsh", 0.06, 0.06), ("lhip", "rhip", 0.09, 0.09), ("head", "head", 0.1, 0.1),
        ("lwr", "lwr", 0.04, 0.04)]


def stick_figure() -> tuple[np.ndarray, np.ndarray]:
    """``(16, 2, 3)`` end points and ``(16, 2)`` radii of the benchmark figure."""
    E = np.array([[_J[a], _J[b]] for a, b, _, _ in _SEG], float)
    R = np.array([[ra, rb] for _, _, ra, rb in _SEG], float)
    return E, R


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--repeats", type=int, default=50, help="timed runs per view (median)")
    p.add_argument("--particles", type=int, default=1000, help="point sets for project_batch")
    p.add_argument("--threads", type=int, default=0, help="numba threads (0: numba's default, all cores)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def _times_ms(fn, repeats: int) -> tuple[float, float]:
    """(median, min) wall time of ``fn()`` in ms over ``repeats`` runs."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3), float(np.min(times) * 1e3)


def run(args: argparse.Namespace) -> int:
    if args.threads:
        numba.set_num_threads(args.threads)
    rig = default_rig(width=args.width, height=args.height)
    E, R = stick_figure()
    rng = np.random.default_rng(0)
    bgs = [make_background(args.width, args.height, rng=rng) for _ in rig]
    # warm-up: numba compilation (cached on disk) on a throw-away camera size
    warm = rig.cameras[0].resized(33, 25)
    render(warm, E, R)
    render_mask(warm, E, R)
    clear_ray_cache()
    t0 = time.perf_counter()
    for cam, bg in zip(rig, bgs):
        render(cam, E, R, background=bg)
    first_ms = (time.perf_counter() - t0) * 1e3 / len(rig)
    n = len(rig)
    ms_render, min_render = (x / n for x in _times_ms(
        lambda: [render(c, E, R, background=b) for c, b in zip(rig, bgs)], args.repeats))
    ms_mask, min_mask = (x / n for x in _times_ms(lambda: [render_mask(c, E, R) for c in rig], args.repeats))
    fg = float(np.mean([render_mask(c, E, R).mean() / 255 for c in rig]))
    P = E[None].reshape(1, -1, 3) + rng.normal(0, 0.05, (args.particles, E.size // 3, 3))
    project_batch(rig, P[:2])
    ms_proj, min_proj = _times_ms(lambda: project_batch(rig, P), max(5, args.repeats // 5))
    res = {"width": args.width, "height": args.height, "views": n, "capsules": len(E),
           "foreground_fraction": round(fg, 4), "threads": numba.get_num_threads(),
           "render_ms_per_view": round(ms_render, 3), "render_mask_ms_per_view": round(ms_mask, 3),
           "render_ms_per_view_min": round(min_render, 3), "render_mask_ms_per_view_min": round(min_mask, 3),
           "first_render_ms_per_view": round(first_ms, 2),
           "project_batch_ms": round(ms_proj, 3), "project_batch_ms_min": round(min_proj, 3),
           "project_batch_points": int(P.shape[0] * P.shape[1] * n)}
    if args.json:
        print(json.dumps(res))
    else:
        print(f"render {args.width}x{args.height}, {len(E)} capsules, {n} views, {res['threads']} threads, "
              f"foreground {100 * fg:.1f}%")
        print(f"  render        {ms_render:7.3f} ms/view (min {min_render:.3f}; first call per camera "
              f"{first_ms:.1f} ms: ray set-up)")
        print(f"  render_mask   {ms_mask:7.3f} ms/view (min {min_mask:.3f})")
        print(f"  project_batch {ms_proj:7.3f} ms (min {min_proj:.3f}) for {P.shape[0]} sets x {P.shape[1]} points "
              f"x {n} views")
    return 0
