"""Track a ground-truth bag with the search started at the truth on every frame (issue 33, the flexed-leg bias).

    .venv/bin/python tools/oracle_track.py [--oracle] BAG --out DIR [isa-mocap track options...]

Runs ``isa-mocap track`` in this process (the same code and options); with ``--oracle`` every frame's external
prediction is the bag's ground-truth pose (so the search starts at the true joint angles; on a body-shape other
than ``--shape truth`` these are the true angles on the tracking model's bones). After every step it records the
tracker's own energy (``Tracker.total_energy``: the silhouette data term plus the prior, without the keypoint term)
of the truth pose and of the estimate, and at the end prints their means and the segments' angles from the
vertical (pelvis→neck, hip→knee, knee→ankle) of the estimate against the truth's joint centres.

Question it answers: is an error the search's or the prediction's (the oracle run lands near the truth at a
lower energy than the free run) or the energy's (the free run's estimate has the lower energy)? A diagnostic,
not part of the tracker (the bag needs ground truth: ``isa-mocap synth``).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.body import joint_positions
from isa_mocap_ros.cli.run_report import read_estimates
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.tracking import tracker as tracker_module

sys.path.insert(0, str(Path(__file__).parent))
from track_hooks import track_args, track_patched  # noqa: E402

SEGMENTS = (("pelvis", "neck"), ("left_hip", "left_knee"), ("right_hip", "right_knee"),
            ("left_knee", "left_ankle"), ("right_knee", "right_ankle"))


def from_vertical_deg(v: np.ndarray) -> np.ndarray:
    """Angle of vectors ``(..., 3)`` from world up (+z), degrees."""
    return np.degrees(np.arccos(np.clip(v[..., 2] / np.linalg.norm(v, axis=-1), -1.0, 1.0)))


def main(argv: list[str]) -> int:
    oracle, args, bag, out = track_args(argv, "--oracle", __doc__)
    seq = read_sequence(bag, want_images=True, want_masks=False)
    if seq.truth_model is None:
        raise SystemExit(f"{bag}: expected a bag with a ground-truth model (isa-mocap synth)")
    truth = {int(f.stamp_ns): np.asarray(f.truth, float) for f in seq.frames if f.truth is not None}
    energies: list[tuple[int, float, float]] = []
    models: list = []
    step = tracker_module.Tracker.step

    def recording_step(self, masks, frame_index, **kw):
        t = truth.get(int(frame_index))
        if oracle and t is not None and len(t) == self.model.dof:
            kw["prediction"] = t
        r = step(self, masks, frame_index, **kw)
        if t is not None and r.x is not None and len(t) == self.model.dof:
            e = self.total_energy(np.stack([t, r.x]))
            energies.append((int(frame_index), float(e[0]), float(e[1])))
        if not models:
            models.append(self.model)
        return r

    rc = track_patched(args, [(tracker_module.Tracker, "step", recording_step)])
    if rc or not energies:
        return rc or 1
    E = np.array([(a, b) for _, a, b in energies])
    model = models[0]
    est = read_estimates(Path(out) / "estimates", model)["poses"]
    names, jn = list(seq.truth_marker_names), list(model.joint_names)
    tm = {int(f.stamp_ns): np.asarray(f.truth_markers) for f in seq.frames if f.truth_markers is not None}
    ks = sorted(k for k in est if k in tm)[1:]          # not the first (initialized) frame
    J = joint_positions(model, np.stack([est[k] for k in ks]), backend="numpy")
    T = np.stack([tm[k] for k in ks])
    ang_e = np.stack([from_vertical_deg(J[:, jn.index(b)] - J[:, jn.index(a)]) for a, b in SEGMENTS], 1)
    ang_t = np.stack([from_vertical_deg(T[:, names.index(b)] - T[:, names.index(a)]) for a, b in SEGMENTS], 1)
    res = {"oracle": oracle, "frames": len(E), "energy_truth": float(E[:, 0].mean()),
           "energy_estimate": float(E[:, 1].mean()), "truth_lower_share": float(np.mean(E[:, 0] < E[:, 1])),
           "segments": [f"{a}->{b}" for a, b in SEGMENTS],
           "estimate_from_vertical_deg": np.round(ang_e.mean(0), 2).tolist(),
           "truth_from_vertical_deg": np.round(ang_t.mean(0), 2).tolist(),
           "estimate_minus_truth_deg": np.round((ang_e - ang_t).mean(0), 2).tolist()}
    print(json.dumps(res))
    with open(Path(out) / "oracle_energies.json", "w") as f:
        json.dump({**res, "per_frame": energies}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
