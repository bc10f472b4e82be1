#!/usr/bin/env python3
"""Define a 2-D keypoint model's surface points (head top, nose, heels, toes) on mesh bodies
(``isa_mocap_ros.eval.keypoint_map``) and write them:

    python tools/fit_keypoint_points.py --out config/joint_maps/halpe26_mesh_points.yaml [--random 5]

Subjects: the three named mesh subjects (``isa-mocap synth --body mesh --subject``) and ``--random N`` random
ones (``make_subject('random', rng=default_rng(k))``, k = 0..N-1), each at rest, aligned to the default 39-DOF
model. Needs the MakeHuman assets (``make venv``). Prints each point's offset and its spread over the subjects.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="YAML to write")
    p.add_argument("--random", type=int, default=5, metavar="N", help="random mesh subjects besides the named (default 5)")
    a = p.parse_args(argv)
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.body.mesh import PRESETS, make_subject
    from isa_mocap_ros.body.mesh_assets import AssetError
    from isa_mocap_ros.eval.keypoint_map import fit_keypoint_points, save_keypoint_points

    subjects = [make_subject(n) for n in PRESETS] + [make_subject("random", rng=np.random.default_rng(k))
                                                      for k in range(a.random)]
    source = {"subjects": list(PRESETS) + [f"random (default_rng({k}))" for k in range(a.random)],
              "model": "default 39-DOF shape (config/body/default.yaml) at rest",
              "note": f"tools/fit_keypoint_points.py --random {a.random}; vertex rules: eval/keypoint_map.POINT_RULES"}
    try:
        pts = fit_keypoint_points(make_model(39), subjects, source=source)
    except AssetError as exc:
        print(f"fit_keypoint_points: error: {exc}", file=sys.stderr)
        return 2
    save_keypoint_points(pts, a.out)
    print(f"fit_keypoint_points: wrote {a.out} ({len(subjects)} subjects)")
    for n, (anchor, o) in pts.points.items():
        print(f"  {n:10s} on {anchor:12s} [{o[0]:+.3f} {o[1]:+.3f} {o[2]:+.3f}] m, spread {pts.spread_mm[n]:.1f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
