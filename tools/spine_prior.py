"""Write a pose-prior file that keeps the spine near straight (issue 33, the clean knee: the trunk chain's drift).

    .venv/bin/python tools/spine_prior.py OUT.npz [--sigma-deg 14.3]
    isa-mocap track BAG --prior OUT.npz --prior-eta 0.003 ...

A :class:`isa_mocap_ros.energy.prior.ParzenPrior` over the six spine angles only (``spine_lower_*``,
``spine_upper_*``; the 39-DOF model's layout) whose training poses are the straight spine (three copies of the zero
angles), with the window ``sigma`` given: with ``track --prior-eta η`` it adds ``η ‖q_spine‖² / 2σ²`` to the energy
(0.0066 for one spine angle at 30° with η 0.003, σ 0.25 rad). The measurement that tried it is in
``docs/history/issue33_knee_s31.md`` section 5 (an option, not a default). A diagnostic, not part of the tracker.
"""
from __future__ import annotations

import sys

import numpy as np

from isa_mocap_ros.body import make_model
from isa_mocap_ros.energy.prior import ParzenPrior


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        raise SystemExit(__doc__)
    sigma = np.radians(float(argv[argv.index("--sigma-deg") + 1])) if "--sigma-deg" in argv else 0.25
    m = make_model(39)
    dims = [i for i, n in enumerate(m.dof_names) if n.startswith("spine_")]
    ParzenPrior(np.zeros((3, m.dof)), dims=dims, sigma=float(sigma)).save(argv[0])
    print(f"{argv[0]}: spine prior over {[m.dof_names[i] for i in dims]}, sigma {sigma:.4f} rad")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
