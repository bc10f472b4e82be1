"""Where two tracked runs of one bag part: the free run against the oracle's (issue 33, the clean knee).

    .venv/bin/python tools/free_vs_oracle.py FREE_RUN ORACLE_RUN

Both are ``isa-mocap track`` outputs of the same bag (e.g. ``tools/oracle_track.py`` without and with ``--oracle``).
Prints, rms over the frames both estimated (not the first), the difference of the two runs' knee and hip angles,
root rotation (rotation-vector components), lower spine angles (degrees) and pelvis marker (mm, body axes: lateral,
forward, up), and per leg the correlation of the difference of their mapped knee errors (|free| − |oracle|) with the
knee's, the hip flexion's, and the pelvis's height and forward differences. A diagnostic, not part of the tracker.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.body import make_model
from isa_mocap_ros.cli.run_report import read_estimates
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.eval.joint_map import mapped_markers, mesh_rig_map
from isa_mocap_ros.eval.metrics import body_frames

sys.path.insert(0, str(Path(__file__).parent))
from knee_split import MARKS, knees_deg  # noqa: E402  (a sibling tool)


def load(run: Path, seq) -> tuple:
    s = json.loads((run / "summary.json").read_text())
    sh = s.get("shape")
    model = make_model(39, shape=dict(seq.truth_model.shape)) if sh == "truth" else make_model(39, shape=Path(sh))
    est = read_estimates(run / "estimates", model)["poses"]
    return model, est


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        raise SystemExit(__doc__)
    runs = [Path(a) for a in argv]
    seq = read_sequence(json.loads((runs[0] / "summary.json").read_text())["bag"], want_images=True, want_masks=False)
    (m, ef), (m2, eo) = load(runs[0], seq), load(runs[1], seq)
    names = list(seq.truth_marker_names)
    tm = {int(f.stamp_ns): np.asarray(f.truth_markers) for f in seq.frames if f.truth_markers is not None}
    ks = sorted(k for k in ef if k in eo and k in tm)[1:]
    Xf, Xo = np.stack([ef[k] for k in ks]), np.stack([eo[k] for k in ks])
    T = np.stack([tm[k] for k in ks])[:, [names.index(n) for n in MARKS]]
    B = body_frames(T, MARKS.index("left_hip"), MARKS.index("right_hip"))
    Pf, Po = mapped_markers(mesh_rig_map(), m, Xf, MARKS), mapped_markers(mesh_rig_map(), m2, Xo, MARKS)
    kt = knees_deg(T)
    de = np.abs(knees_deg(Pf) - kt) - np.abs(knees_deg(Po) - kt)
    dpel = 1e3 * np.einsum("fji,fj->fi", B, Pf[:, 0] - Po[:, 0])
    dof = list(m.dof_names)
    rms = (lambda v: float(np.sqrt(np.mean(np.square(v)))))
    d = {n: np.degrees(Xf[:, dof.index(n)] - Xo[:, dof.index(n)]) for n in dof if not n.startswith("root_t")}
    for c, side in enumerate(("left", "right")):
        print(f"{side}: rms difference knee {rms(d[f'{side}_knee_y']):.1f}, hip flexion {rms(d[f'{side}_hip_y']):.1f}, "
              f"abduction {rms(d[f'{side}_hip_x']):.1f}, ankle {rms(d[f'{side}_ankle_y']):.1f} deg; correlation of the "
              f"knee error difference with |d knee| {np.corrcoef(de[:, c], np.abs(d[f'{side}_knee_y']))[0, 1]:+.2f}, "
              f"|d hip flexion| {np.corrcoef(de[:, c], np.abs(d[f'{side}_hip_y']))[0, 1]:+.2f}, |d pelvis up| "
              f"{np.corrcoef(de[:, c], np.abs(dpel[:, 2]))[0, 1]:+.2f}, |d pelvis forward| "
              f"{np.corrcoef(de[:, c], np.abs(dpel[:, 1]))[0, 1]:+.2f}")
    print("root rotation rms difference (rotation vector x, y, z), deg:",
          [round(rms(d[n]), 1) for n in ("root_rx", "root_ry", "root_rz")])
    print("lower spine rms difference (flexion, bend, twist), deg:",
          [round(rms(d[n]), 1) for n in ("spine_lower_y", "spine_lower_x", "spine_lower_z")])
    print("pelvis marker difference, mm (lateral, forward, up): mean", np.round(dpel.mean(0), 1).tolist(),
          "rms", np.round(np.sqrt((dpel ** 2).mean(0)), 1).tolist())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
