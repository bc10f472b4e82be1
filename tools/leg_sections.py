"""Where does a mesh body's leg volume lie around its bones? (issue 33, the knee: the calf behind the shin's line)

    .venv/bin/python tools/leg_sections.py [SUBJECT ...]      (default: the presets and random subjects 0-7)

For each subject's rest mesh (:func:`isa_mocap_ros.body.mesh.mesh_body`; legs straight, facing +x) it takes the
vertices skinned mostly (weight > 0.5) to the left thigh and the left shin, cuts them across the bone at fractions
of the bone's length, and prints each cut's centre front-back (the middle of its forward extent, relative to the
joint line, as a fraction of the bone's length; + = in front) and the shin's half depth / half width at 0.3.
A capsule on the joint line covers the cuts' centres only where these are ~0; the numbers are what a body
shape's ``axis_offsets`` would have to follow. A diagnostic, not part of the tracker.
"""
from __future__ import annotations

import sys

import numpy as np

from isa_mocap_ros.body.mesh import PRESETS, SEGMENTS, make_subject, mesh_body

CUTS = (0.15, 0.3, 0.5, 0.7, 0.85)


def sections(body, segment: str) -> np.ndarray:
    """``(len(CUTS), 3)``: centre forward / length, half depth (m), half width (m) of each cut (NaN: too few)."""
    names = list(SEGMENTS)
    a, b, _ = SEGMENTS[segment]
    pa, pb = body.joints[a], body.joints[b]
    V = body.verts[body.seg_weights[:, names.index(segment)] > 0.5]
    length = float(np.linalg.norm(pb - pa))
    u = (pb - pa) / length
    s = (V - pa) @ u / length
    out = np.full((len(CUTS), 3), np.nan)
    for i, f in enumerate(CUTS):
        d = V[np.abs(s - f) < 0.04] - (pa + f * length * u)
        if len(d) < 5:
            continue
        d -= np.outer(d @ u, u)
        out[i] = ((d[:, 0].max() + d[:, 0].min()) / 2 / length, np.ptp(d[:, 0]) / 2, np.ptp(d[:, 1]) / 2)
    return out


def main(argv: list[str]) -> int:
    subjects = argv or [*PRESETS, *(f"random:{k}" for k in range(8))]
    print(f"subject, stature | thigh cut centre / length at {CUTS} | shin the same | shin half depth / width at 0.3 (mm)")
    for name in subjects:
        kind, _, seed = name.partition(":")
        sub = make_subject(kind, rng=np.random.default_rng(int(seed)) if seed else None)
        body = mesh_body(sub)
        t, s = sections(body, "left_thigh"), sections(body, "left_shin")
        print(f"{name} {sub.stature_m:.2f} | " + " ".join(f"{v:+.3f}" for v in t[:, 0]) + " | "
              + " ".join(f"{v:+.3f}" for v in s[:, 0]) + f" | {s[1, 1] * 1000:.0f} / {s[1, 2] * 1000:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
