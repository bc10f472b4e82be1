"""Where does a mesh body's pelvis volume lie around its hip joints? (issue 33, the knee: the hips tracked forward)

    .venv/bin/python tools/pelvis_sections.py [SUBJECT ...]      (default: the presets and random subjects 0-7)

For each subject's rest mesh (:func:`isa_mocap_ros.body.mesh.mesh_body`; facing +x) it cuts the body horizontally at
heights relative to the hip joints' (the mesh skeleton's femoral heads) and prints each cut's front-back centre
(the middle of its forward extent) relative to the hip joints, and its half depth, in mm, for the vertices between
the hip joints laterally (the pelvis, not the thighs' outer sides). The tracking model's pelvis and abdomen capsules
are centred on the hip joints' line (``config/body/default.yaml``): where the cuts' centres lie in front of the
hips, a capsule pelvis covers the mesh's best with the hip joints moved forward, which tilts the thighs
(``docs/history/issue33_mesh_accuracy_s27.md``: the tracked hips 2-6 cm in front of the mesh's). A diagnostic, not
part of the tracker.
"""
from __future__ import annotations

import sys

import numpy as np

from isa_mocap_ros.body.mesh import PRESETS, make_subject, mesh_body

#: cut heights above the hip joints, metres
HEIGHTS = (-0.05, 0.0, 0.05, 0.10, 0.15)


def sections(body) -> np.ndarray:
    """``(len(HEIGHTS), 2)``: centre forward of the hips (m) and half depth (m) of each cut (NaN: too few)."""
    lh, rh = body.joints["left_hip"], body.joints["right_hip"]
    c = (lh + rh) / 2
    half_w = abs(lh[1] - rh[1]) / 2
    V = body.verts
    out = np.full((len(HEIGHTS), 2), np.nan)
    for i, h in enumerate(HEIGHTS):
        sel = V[(np.abs(V[:, 2] - (c[2] + h)) < 0.01) & (np.abs(V[:, 1] - c[1]) < half_w)]
        if len(sel) < 5:
            continue
        out[i] = ((sel[:, 0].max() + sel[:, 0].min()) / 2 - c[0], np.ptp(sel[:, 0]) / 2)
    return out


def main(argv: list[str]) -> int:
    subjects = argv or [*PRESETS, *(f"random:{k}" for k in range(8))]
    print(f"subject, stature | cut centre forward of the hip joints, mm, at {HEIGHTS} m above them | half depth, mm"
          " | pelvis joint forward / up of the hips, mm")
    for name in subjects:
        kind, _, seed = name.partition(":")
        sub = make_subject(kind, rng=np.random.default_rng(int(seed)) if seed else None)
        body = mesh_body(sub)
        s = sections(body)
        c = (body.joints["left_hip"] + body.joints["right_hip"]) / 2
        p = body.joints["pelvis"] - c
        print(f"{name} {sub.stature_m:.2f} | " + " ".join(f"{1e3 * v:+4.0f}" for v in s[:, 0]) + " | "
              + " ".join(f"{1e3 * v:3.0f}" for v in s[:, 1]) + f" | {1e3 * p[0]:+.0f} / {1e3 * p[2]:+.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
