"""Track with the search started at the truth for some coordinates only (issue 33, the clean knee).

    H33K_ORACLE_DOFS=root_r,spine_ .venv/bin/python tools/partial_oracle.py BAG --out DIR [isa-mocap track options...]
    .venv/bin/python tools/partial_oracle.py --dofs root_r,spine_ BAG --out DIR [...]

``tools/oracle_track.py`` (free, its energies and segment angles recorded the same way) with the tracker's own
damped prediction (:func:`isa_mocap_ros.tracking.frame_prediction.predict`) changed on every tracked frame: the
coordinates whose DOF names start with one of the prefixes take the bag's true pose's values (the true angles on the
tracking model's bones), the rest stay the tracker's. Question it answers: which part of the pose (trunk, legs, root)
the free run's error comes from, between the free run and the full oracle (``oracle_track.py --oracle``).
A diagnostic, not part of the tracker (the bag needs ground truth: ``isa-mocap synth``).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.tracking import frame_prediction

sys.path.insert(0, str(Path(__file__).parent))
import oracle_track  # noqa: E402  (a sibling tool)


def main(argv: list[str]) -> int:
    dofs = os.environ.get("H33K_ORACLE_DOFS", "")
    if "--dofs" in argv:
        i = argv.index("--dofs")
        dofs, argv = argv[i + 1], argv[:i] + argv[i + 2:]
    prefixes = tuple(p for p in dofs.split(",") if p)
    if not argv or not prefixes:
        raise SystemExit(__doc__)
    seq = read_sequence(argv[0], want_images=True, want_masks=False)
    truth = {int(f.stamp_ns): np.asarray(f.truth, float) for f in seq.frames if f.truth is not None}
    own = frame_prediction.predict

    def predict(tr, ctx):
        x = own(tr, ctx)
        t = truth.get(int(ctx.frame_index))
        if t is not None and len(t) == len(x):
            idx = [i for i, n in enumerate(tr.model.dof_names) if n.startswith(prefixes)]
            x = np.array(x, dtype=float)
            x[idx] = t[idx]
        return x

    frame_prediction.predict = predict
    try:
        return oracle_track.main(argv)
    finally:
        frame_prediction.predict = own


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
