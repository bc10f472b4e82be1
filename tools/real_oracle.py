#!/usr/bin/env python3
"""Is the real recording's error the energy's or the search's, and what is its knee error? (issue 34)

    .venv/bin/python tools/real_oracle.py [--oracle] BAG --out DIR [isa-mocap track options...]
    .venv/bin/python tools/real_oracle.py --knee BAG TRACK_DIR [TRACK_DIR ...]

``BAG`` is the imported demo (``bench real``'s ``demo_bag_320``, docs/real_cameras.md section 3). The first form runs
``isa-mocap track`` in this process (the same code and options) and after every step poses the tracking model to
the peer's points (:func:`real_floor.ik_to_peer`, bounded least squares from the estimate: the "peer pose") and
records the tracker's own energy (``Tracker.total_energy``: the silhouette data term plus the prior, without the
keypoint term, under the frame's filtered masks) of the peer pose and of the estimate. With ``--oracle`` every
frame's external prediction is the peer pose fitted from the previous estimate (the search starts at the peer's
points; the first frame is initialized as usual). It prints, per third, the share of frames whose peer pose has the
lower energy and the mean energies, and writes them to ``DIR/oracle_energies.json``. ``--offsets SUMMARY``: the peer's points first moved by each joint's mean offset of
that track (``summary.json``'s ``per_marker_offset_mm``, the estimate's minus the peer's in the peer hips' axes), so
the peer pose is the one the offset-removed score would call exact, not the one bent to the peer's definitions.

``--knee``: per track, the knee angles (3-D, thigh against shank, as ``bench real`` scores them) of the estimate
against the peer's raw points and against its Butterworth-filtered output (``reference/*_butterworth.trc``), per side
and third: the mean signed error (a bias: a definition or a systematic pose) and the standard deviation around it,
and the peer's own frame-to-frame knee jitter (raw against filtered). A diagnostic that uses the peer's points: nothing
here may be tuned on.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from real_floor import ik_to_peer  # noqa: E402
from track_hooks import pop_option, reference_markers, track_args, track_patched  # noqa: E402

SIDES = ("left", "right")


def _knee_deg(P: np.ndarray, names: list[str], side: str) -> np.ndarray:
    from isa_mocap_ros.eval.metrics import knee_flexion_from_points

    return np.degrees(knee_flexion_from_points(*(P[:, names.index(f"{side}_{j}")] for j in ("hip", "knee", "ankle"))))


def _thirds(n: int, parts: int = 3) -> list[np.ndarray]:
    return np.array_split(np.arange(n), parts)


def _filtered_reference(names: list[str], n: int) -> np.ndarray | None:
    """The peer's Butterworth-filtered points (F, J, 3) in the bag's world, in ``names`` order (rows = the scored
    frames in order, as ``bench real`` reads them); None without the file or when its length is not ``n``."""
    from isa_mocap_ros.bench import real
    from isa_mocap_ros.eval.trc import TRC_TO_WORLD, joint_names_of, read_trc

    ref = real.demo_dir() / "reference" / "balancing_pose2sim_butterworth.trc"
    if not ref.is_file():
        return None
    trc = read_trc(ref)
    if len(trc.points) != n:
        return None
    theirs = list(joint_names_of(trc.names))
    P = trc.in_world(TRC_TO_WORLD)
    return np.stack([P[:, theirs.index(m)] if m in theirs else np.full(P.shape[::2], np.nan) for m in names], 1)


def knee_report(bag: Path, tracks: list[Path]) -> int:
    from isa_mocap_ros.cli.run_report import published_model, read_estimates
    from isa_mocap_ros.eval.metrics import marker_positions

    names, truth = reference_markers(bag)
    for tr in tracks:
        model = published_model(tr / "estimates")
        poses = read_estimates(tr / "estimates", model)["poses"]
        stamps = sorted(s for s in poses if s in truth)
        T = np.array([truth[s] for s in stamps])
        Tf = _filtered_reference(names, len(truth)) if len(stamps) == len(truth) else None
        joints = [f"{s}_{j}" for s in SIDES for j in ("hip", "knee", "ankle")]
        P = marker_positions(model, np.array([poses[s] for s in stamps]), joints=joints)
        print(f"== {tr.name} ({len(stamps)} frames)")
        for side in SIDES:
            ke, kt = _knee_deg(P, joints, side), _knee_deg(T, names, side)
            e = ke - kt
            print(f"  {side} knee: ours {np.nanmean(ke):.1f}°, peer {np.nanmean(kt):.1f}° (peer range "
                  f"{np.nanmin(kt):.0f}-{np.nanmax(kt):.0f}); error RMSE {np.sqrt(np.nanmean(e * e)):.1f}°, bias "
                  f"{np.nanmean(e):+.1f}°, sd {np.nanstd(e):.1f}°; per third bias/sd "
                  + " / ".join(f"{np.nanmean(e[s]):+.1f}/{np.nanstd(e[s]):.1f}" for s in _thirds(len(e)))
                  + f"; correlation ours-peer {np.corrcoef(ke[np.isfinite(kt)], kt[np.isfinite(kt)])[0, 1]:.2f}"
                  + f"; frame-to-frame change ours {np.nanmean(np.abs(np.diff(ke))):.1f}°, "
                    f"peer {np.nanmean(np.abs(np.diff(kt))):.1f}°", flush=True)
            if Tf is not None:
                kf = _knee_deg(Tf, names, side)
                ef = ke - kf
                print(f"    against the peer's filtered points: RMSE {np.sqrt(np.nanmean(ef * ef)):.1f}°, bias "
                      f"{np.nanmean(ef):+.1f}°, sd {np.nanstd(ef):.1f}°; the peer's raw against its filtered: RMSE "
                      f"{np.sqrt(np.nanmean((kt - kf) ** 2)):.1f}°", flush=True)
    return 0


def oracle_run(argv: list[str]) -> int:
    from isa_mocap_ros.tracking import tracker as tracker_module

    argv = list(argv)
    summary = pop_option(argv, "--offsets")     # a track's summary.json: its per_marker_offset_mm (est − peer, body axes)
    offsets: dict = json.loads(Path(summary).read_text())["per_marker_offset_mm"] if summary is not None else {}
    oracle, args, bag, out = track_args(argv, "--oracle", __doc__)
    out = Path(out)
    names, truth = reference_markers(bag)
    if offsets:                             # the peer's points moved by those offsets: what the score compares
        from isa_mocap_ros.eval.metrics import body_frames

        ks = sorted(truth)
        T = np.array([truth[k] for k in ks])
        B = body_frames(T, names.index("left_hip"), names.index("right_hip"))
        off = np.array([offsets.get(n, [0.0, 0.0, 0.0]) for n in names]) / 1e3
        T = T + np.einsum("fij,mj->fmi", B, off)
        truth = {k: T[i] for i, k in enumerate(ks)}
    rows: list[dict] = []
    last: list = []
    step = tracker_module.Tracker.step

    def peer_pose(model, x, t):
        shared = [model.joint_names[j] for j in model.markers if model.joint_names[j] in names]
        Pt = t[[names.index(n) for n in shared]][None]
        return ik_to_peer(model, np.asarray(x, float)[None], Pt, shared)[0]

    def recording_step(self, masks, frame_index, **kw):
        t = truth.get(int(frame_index))
        if oracle and t is not None and last:
            kw["prediction"] = peer_pose(self.model, last[-1], t)
        r = step(self, masks, frame_index, **kw)
        if r.x is not None:
            last.append(np.asarray(r.x, float))
            if t is not None:
                xp = peer_pose(self.model, r.x, t)
                e = self.total_energy(np.stack([xp, r.x]))
                rows.append({"stamp": int(frame_index), "energy_peer_pose": float(e[0]),
                             "energy_estimate": float(e[1])})
        return r

    rc = track_patched(args, [(tracker_module.Tracker, "step", recording_step)])
    if rc or not rows:
        return rc or 1
    starts = [i for i in range(len(rows)) if i == 0 or rows[i]["stamp"] <= rows[i - 1]["stamp"]]
    rows = rows[starts[-1]:]                # the last track (a calibration tracks the first frames before it)
    E = np.array([(r["energy_peer_pose"], r["energy_estimate"]) for r in rows])
    res = {"oracle": oracle, "frames": len(E), "peer_pose_lower_share": float(np.mean(E[:, 0] < E[:, 1])),
           "thirds": [{"peer_pose_lower_share": float(np.mean(E[s, 0] < E[s, 1])),
                       "energy_peer_pose": float(E[s, 0].mean()), "energy_estimate": float(E[s, 1].mean())}
                      for s in _thirds(len(E))]}
    print(json.dumps(res))
    (out / "oracle_energies.json").write_text(json.dumps({**res, "per_frame": rows}))
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--knee"]:
        return knee_report(Path(argv[1]), [Path(a) for a in argv[2:]])
    return oracle_run(argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
