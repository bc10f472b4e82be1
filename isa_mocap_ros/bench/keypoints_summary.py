"""The keypoint section of the results page: ``bench all``'s reduced ``isa-mocap bench keypoints``.

:func:`collect` runs

* the ``cost`` kind on the shipped demo bag: the detector's CPU time (``time.thread_time``) per detection and
  per frame set at every rate of :data:`~isa_mocap_ros.bench.keypoints.COST_RATES` and the default one;
* the ``track`` kind without the term and with it at the default rate (``EVERY_K``, weight 1): mesh bodies
  (the three subjects, the CMU forward jumps clip where ``../shared`` has it and the generated walk, bag seed 0,
  2 s each) and capsule controls (generated walk and jog, bag seeds 0-2, 2 s each); scored by the mean joint
  error (Eq. 20), the frames tracked facing backwards and the leg-swap frames (``bench/keypoints_tracking.py``).

``quick``: the cost on the demo's first 20 frame sets and one capsule walk of 0.4 s. Without the landmark model
(``make models``) nothing runs and the section says so. :func:`render_markdown` writes the section.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

__all__ = ["collect", "render_markdown"]

_CMU_JUMPS = "01_01_forward_jumps_turn.bvh"


def _designs(quick: bool) -> list[tuple[str, list[str]]]:
    from isa_mocap_ros.resources import shared_data_dir

    if quick:
        return [("capsule controls", ["--body", "capsules", "--motions", "walk", "--seeds", "0", "--track-s", "0.4"])]
    jumps = shared_data_dir() / "mocap" / "cmu" / _CMU_JUMPS
    motions = ([str(jumps)] if jumps.is_file() else []) + ["walk"]
    return [("mesh bodies", ["--body", "mesh", "--motions", ",".join(motions), "--bvh-scale", "0.056444", "--seeds", "0",
                             "--track-s", "2"]),
            ("capsule controls", ["--body", "capsules", "--motions", "walk,jog", "--seeds", "0,1,2", "--track-s", "2"])]


def collect(*, quick: bool, out: Path) -> dict:
    """The section's measurements (module docstring); ``out``: bags and tracking output."""
    from isa_mocap_ros.bench import keypoints as bk
    from isa_mocap_ros.vision.landmark_model import ModelUnavailable, landmark_model_path

    try:
        landmark_model_path()
    except ModelUnavailable as exc:
        return {"skipped": f"landmark model not available (make models): {exc}"}
    p = argparse.ArgumentParser()
    bk.add_arguments(p)
    cost_args = p.parse_args(["--kinds", "cost"])
    cost_args.frames = 20 if quick else None
    res: dict = {"cost": bk.bench_cost(cost_args), "every_k": cost_args.every, "track": {}}
    for label, argv in _designs(quick):
        args = p.parse_args(["--kinds", "track", "--configs", "off,every", "--cache", str(Path(out) / "keypoints"),
                             *argv])
        res["track"][label] = {"command": "isa-mocap bench keypoints --kinds track --configs off,every " + " ".join(argv),
                               "runs": bk.bench_track(args)}
    return res


def _shown(text: str) -> str:
    """``text`` with this checkout's and the shared data's absolute paths written as the README writes them."""
    from isa_mocap_ros.resources import shared_data_dir

    root = Path(__file__).resolve().parents[2]
    return text.replace(str(shared_data_dir()), "../shared/data").replace(str(root) + "/", "")


def _f(v: float, fmt: str = "{:.1f}") -> str:
    return fmt.format(v) if v is not None and np.isfinite(v) else "n/a"


def render_markdown(d: dict) -> str:
    if "skipped" in d:
        return f"Not run: {d['skipped']}.\n"
    c = d["cost"]
    L = ["`isa-mocap bench keypoints` reduced (`isa_mocap_ros/bench/keypoints_summary.py`; the full measurements and "
         "the detector's limits: docs/keypoints.md).", "",
         f"**Cost** (`--kinds cost`, {_shown(c['bag'])}, {c['frame_sets']} frame sets, the keypoint node's schedule: each view's "
         f"first {c['dense_frames']} frames with a person, then every K-th): CPU time of the calling thread "
         f"(`time.thread_time`) per detection {_f(c['cpu_ms_per_detection_median'])} ms median (model invoke alone "
         f"{_f(c['cpu_ms_per_invoke_median'])} ms); on a loaded machine these are inflated (cache, SMT).", "",
         "| every K-th | detections | per frame set | CPU ms per frame set |", "|---|---|---|---|"]
    for k, r in sorted(c["rates"].items(), key=lambda kv: int(kv[0])):
        mark = " (default)" if int(k) == int(d["every_k"]) else ""
        L.append(f"| {k}{mark} | {r['detections']} | {r['detections_per_set']:.2f} | {_f(r['cpu_ms_per_frame_set'])} |")
    L += ["", "**Tracking with the term** (h-isa 1500, exact masks, automatic initialization, the bag's true shape; "
          "backwards: the torso heading more than 90° from the truth's; leg swap: the left knee and ankle closer to "
          "the true right ones):", ""]
    for label, t in d["track"].items():
        L += [f"{label} (`{_shown(t['command'])}`):", "",
              "| configuration | runs | mean joint error (mm) | backwards frames | runs with a backwards frame | leg-swap frames |",
              "|---|---|---|---|---|---|"]
        for name, runs in t["runs"].items():
            r = list(runs.values())
            L.append(f"| {'without the term' if name == 'off' else 'with the term, ' + name} | {len(r)} | "
                     f"{_f(float(np.mean([x['mpjpe_mm'] for x in r])))} | {sum(x['backwards'] for x in r)} | "
                     f"{sum(x['backwards'] > 0 for x in r)} | {sum(x['leg_swaps'] for x in r)} |")
        L.append("")
    return "\n".join(L) + "\n"
