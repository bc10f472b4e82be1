"""The optimizer comparison of yeguas_ea_vs_pf_mocap §5.2-5.4 on our sequences (pure runner pieces).

A *design* is the product algorithms × models × budgets × seeds × sequences; one *cell* is one
tracking run of one sequence. :func:`prepare_sequence` synthesizes a sequence once into a cache
(exact silhouettes, ground truth, 39-DOF truth model), :func:`run_cell` tracks it offline (no ROS)
with :class:`~isa_mocap_ros.tracking.Tracker` and returns a JSON-able record, :func:`summarize`
turns records into the paper's outputs: mean error per cell, the Friedman/Holm ranking per model
and budget (Tables 4-5, problems = sequences, each problem's value = the mean over seeds, as the
paper averages its 30 runs), per-family tables over (DOF, budget) (Tables 6-7), holistic vs
hierarchical and 28 vs 39 DOF pairs, and our best algorithm against the reference peers.

Protocol choices (documented in ``docs/evaluation.md``):

* the tracker sees the exact silhouettes (the comparison is about the optimizers, not the
  segmentation) and starts from the ground truth of the first frame, projected onto the tracking
  model by DOF name ("manually initialized to fit the subject in the first frame", §5.1); the
  first frame is not scored;
* the tracking model's body shape is calibrated from the sequence's silhouettes (``shape="auto"``, the default:
  :mod:`.compare_shape`, once per sequence); ``shape="truth"`` (the subject's own shape, as the papers'
  calibrated subjects) is a diagnostic;
* every algorithm gets exactly ``budget`` evaluations per frame (the optimizer driver's budget),
  the same energy, search box (0.5 rad joints, the tracker's defaults) and prediction;
* error = EA-vs-PF Eq. 20 over the markers both models share, averaged over the frames.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from isa_mocap_ros.optim import inner_optimizer
from isa_mocap_ros.resources import cmu_walk_bvh

from .stats import StatsError, ranking_table

__all__ = ["ALGORITHMS", "PEER_ALGORITHMS", "HIERARCHICAL_PAIRS", "SHAPES", "QUICK_CALIB", "SequenceSpec", "Design",
           "make_design", "cell_key", "prepare_sequence", "run_cell", "summarize", "label", "findings", "peer_targets",
           "plot_summary"]

ALGORITHMS = ("isa", "h-isa", "apf", "psapf", "cmaes", "h-cmaes", "de", "h-de", "pso", "h-pso")
PEER_ALGORITHMS = ("pycma", "scipy-de")
#: (holistic, hierarchical) pairs of the paper's §3.3 (PSAPF is the hierarchical APF)
HIERARCHICAL_PAIRS = (("isa", "h-isa"), ("apf", "psapf"), ("cmaes", "h-cmaes"), ("de", "h-de"), ("pso", "h-pso"))
#: the tracking model's shape: calibrated from the images (default, .compare_shape) or the truth (diagnostic)
SHAPES = ("auto", "truth")
QUICK_CALIB = (("window_frames", 4), ("n_frames", 2), ("rounds", 2), ("shape_evals", 120))  # the quick design's
#: the CMU walk in the shared data beside the checkout (or $ISA_MOCAP_SHARED); may be absent
CMU_WALK = cmu_walk_bvh()


@dataclass(frozen=True)
class SequenceSpec:
    """A sequence to synthesize: a generated motion name or a BVH path, rendered into ``views``
    cameras of :func:`~isa_mocap_ros.vision.default_rig` at ``width × height`` (the optimizer comparison's
    sequences, and the robustness bench's: ``bench/robustness.py``)."""

    name: str
    motion: str
    duration_s: float = 2.0
    fps: float = 10.0
    start_s: float = 0.0
    width: int = 160
    height: int = 120
    views: int = 4
    seed: int = 0
    #: ``mesh`` (a skinned human, the average man; scored by its skeleton's joint centres) or
    #: ``capsules`` (the tracking model itself, a control; scored against the ground-truth poses)
    body: str = "mesh"
    #: the mesh subject (``isa-mocap synth --subject``; the robustness and mesh benches)
    subject: str = "average_man"
    #: metres per BVH unit (None: detected; the CMU clips in shared/data/mocap/cmu need 0.056444)
    bvh_scale: float | None = None

    def cache_name(self) -> str:
        m = Path(self.motion).stem if self.motion.endswith(".bvh") else self.motion
        return (f"{self.name}_{m}_{self.duration_s:.4g}s_{self.fps:g}fps_from{self.start_s:g}_{self.width}x{self.height}"
                f"_v{self.views}_s{self.seed}" + ("_mesh" if self.body == "mesh" else "")
                + (f"_{self.subject}" if self.body == "mesh" and self.subject != "average_man" else "") + ".npz")


@dataclass(frozen=True)
class Design:
    """What to run (see :func:`make_design`)."""

    name: str
    algorithms: tuple
    models: tuple
    budgets: tuple
    seeds: tuple
    sequences: tuple
    frames: int | None = None
    notes: tuple = field(default_factory=tuple)
    shape: str = "auto"     # the model's shape: auto (calibrated from the images, .compare_shape) or truth
    calib: tuple = ()       # with auto: ShapeCalibrationConfig settings beyond the defaults, (name, value) pairs

    def cells(self) -> list[dict]:
        """Every run, ordered so that partial results cover all algorithms early (seed-major)."""
        out = []
        for seed in self.seeds:
            for seq in self.sequences:
                for budget in self.budgets:
                    for dof in self.models:
                        for alg in self.algorithms:
                            out.append({"algorithm": alg, "model": int(dof), "budget": int(budget), "seed": int(seed),
                                        "sequence": seq.name, "frames": self.frames, "shape": self.shape})
        return out

    def to_dict(self) -> dict:
        d = asdict(self)
        d["sequences"] = [asdict(s) for s in self.sequences]
        return d


def make_design(kind: str = "default", *, cmu_path: Path | str | None = CMU_WALK, body: str = "mesh",
                shape: str = "auto") -> Design:
    """The three designs of ``isa-mocap bench compare``.

    * ``"quick"``: 2 algorithms (isa, pycma), 39 DOF, 200 evaluations, 1 seed, the generated walk for
      0.14 s at 30 fps (4 frames, 3 scored) in 2 views of 96 × 72 — a smoke test.
    * ``"default"``: the 12 algorithms (10 of the paper's families incl. ISA/H-ISA, + pycma, scipy-de)
      × {28, 39} × {500, 1500, 3000} × 3 seeds × 5 sequences (CMU walk from 1 s if present, walk,
      jog, wave, box) of 31 frames at 30 fps (30 scored) in 4 views of 128 × 96 (11 frames until
      session 12: too short, see docs/evaluation.md).
    * ``"full"``: as default with 30 seeds and 2 s at 30 fps (60 frames) in 4 views of 320 × 240.

    ``body``: what every sequence shows (``mesh`` default, ``capsules`` the control). ``shape``: the tracking
    model's (``auto`` default: calibrated from each sequence's images; ``truth``: a diagnostic).
    """
    if body not in ("mesh", "capsules"):
        raise ValueError(f"body: expected 'mesh' or 'capsules', received {body!r}")
    if shape not in SHAPES:
        raise ValueError(f"shape: expected one of {', '.join(SHAPES)}, received {shape!r}")
    notes = []
    gen = ("walk", "jog", "wave", "box")
    if kind == "quick":
        seqs = (SequenceSpec("walk", "walk", duration_s=0.14, fps=30.0, width=96, height=72, views=2, body=body),)
        return Design("quick", ("isa", "pycma"), (39,), (200,), (0,), seqs, None, (), shape,
                      QUICK_CALIB if shape == "auto" else ())
    if kind == "default":
        dur, fps, w, h, seeds = 31 / 30, 30.0, 128, 96, (0, 1, 2)
    elif kind == "full":
        dur, fps, w, h, seeds = 2.0, 30.0, 320, 240, tuple(range(30))
    else:
        raise ValueError(f"kind: expected 'quick', 'default' or 'full', received {kind!r}")
    seqs = []
    if cmu_path is not None and Path(cmu_path).is_file():
        seqs.append(SequenceSpec("cmu_walk", str(cmu_path), duration_s=dur, fps=fps, start_s=1.0, width=w, height=h,
                                 body=body))
    else:
        notes.append(f"CMU walk skipped: {cmu_path} not found")
    seqs += [SequenceSpec(g, g, duration_s=dur, fps=fps, width=w, height=h, body=body) for g in gen]
    return Design(kind, ALGORITHMS + PEER_ALGORITHMS, (28, 39), (500, 1500, 3000), seeds, tuple(seqs), None,
                  tuple(notes), shape)


def cell_key(cell: dict) -> str:
    return f"{cell['algorithm']}|{cell['model']}|{cell['budget']}|{cell['sequence']}|{cell['seed']}"


def label(alg: str, dof: int, budget: int) -> str:
    """The paper's ``ALG(DOF,EVAL)`` label."""
    return f"{alg.upper()}({dof},{budget})"


# ------------------------------------------------------------------ sequences
def prepare_sequence(spec: SequenceSpec, cache_dir: Path | str) -> Path:
    """Synthesize ``spec`` once into ``cache_dir`` (an ``.npz``: packed masks, truth poses, truth model
    shape, rig size); return its path (an existing file is reused)."""
    from isa_mocap_ros.synth import SceneRenderer, plain_data, make_clip, make_renderer, marker_names
    from isa_mocap_ros.vision import default_rig, render_mask

    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    path = cache_dir / spec.cache_name()
    if path.is_file():
        return path
    clip = make_clip(spec.motion, dof=39, fps=spec.fps, start_s=spec.start_s, duration_s=spec.duration_s,
                     seed=spec.seed, body=spec.body)
    rig = default_rig(n_views=spec.views, width=spec.width, height=spec.height)
    masks = np.zeros((clip.n_frames, spec.views, spec.height, spec.width), dtype=bool)
    extra = {}
    if clip.mesh is not None:
        renderer = make_renderer(clip, rig, seed=spec.seed)
        markers = np.zeros((clip.n_frames, len(marker_names(clip)), 3))
        for k in range(clip.n_frames):
            for v, m in enumerate(renderer.reference_masks(k)):
                masks[k, v] = m > 0
            markers[k] = renderer.posed(k)[1]
        extra = {"markers": markers, "marker_names": json.dumps(marker_names(clip))}
    else:
        renderer = SceneRenderer(clip.model, rig, seed=spec.seed)
        for k, pose in enumerate(clip.poses):
            E = renderer.endpoints(pose)
            for v, cam in enumerate(rig.cameras):
                masks[k, v] = render_mask(cam, E, clip.model.capsule_radii) > 0
    shape = plain_data({"name": clip.model.shape["name"], "offsets": dict(clip.model.shape["offsets"]),
                    "radii": dict(clip.model.shape["radii"])})
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, masks=np.packbits(masks, axis=-1), truth=np.asarray(clip.poses, dtype=float),
                        shape=json.dumps(shape), spec=json.dumps(asdict(spec)), width=spec.width, fps=spec.fps,
                        **extra)
    tmp.replace(path)
    return path


def _load_sequence(path: Path):
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.vision import default_rig

    z = np.load(path)
    spec = SequenceSpec(**json.loads(str(z["spec"])))
    masks = np.unpackbits(z["masks"], axis=-1, count=int(z["width"])).astype(np.uint8) * 255
    shape = json.loads(str(z["shape"]))
    truth_model = make_model(39, shape=shape)
    rig = default_rig(n_views=spec.views, width=spec.width, height=spec.height)
    markers = None
    if "markers" in z.files:
        markers = (json.loads(str(z["marker_names"])), np.asarray(z["markers"]))
    return spec, masks, np.asarray(z["truth"]), truth_model, shape, rig, markers


def _project(x_from: np.ndarray, model_from, model_to) -> np.ndarray:
    """A pose of ``model_from`` as one of ``model_to`` by DOF name (missing DOFs 0, clipped)."""
    x = np.zeros(model_to.dof)
    idx = {n: i for i, n in enumerate(model_from.dof_names)}
    for j, n in enumerate(model_to.dof_names):
        if n in idx:
            x[j] = x_from[idx[n]]
    return np.clip(x, model_to.lower, model_to.upper)


def run_cell(cell: dict, cache_path: Path | str, shape_file: Path | str | None = None) -> dict:
    """Track one cell's sequence (cached at ``cache_path``) with the body shape of ``shape_file`` (calibrated,
    :func:`.compare_shape.calibrate_sequence_shape`; default the sequence's true shape); return its record.

    The record holds the cell, ``mpjpe_mm`` (Eq. 20 over the scored frames), ``knee_rmse_deg``,
    ``max_frame_error_mm``, ``frames`` (scored), ``fell_back``, ``evals_per_frame`` (measured mean),
    ``max_evals_frame`` (largest count of a frame), ``seconds``, ``frame_errors_mm`` and
    ``frame_energies``.
    """
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.eval.peers import register_peers
    from isa_mocap_ros.eval.report import accuracy
    from isa_mocap_ros.tracking import Tracker, TrackerConfig

    register_peers()
    t0 = time.perf_counter()
    spec, masks, truth, truth_model, shape, rig, markers = _load_sequence(Path(cache_path))
    n = len(truth) if not cell.get("frames") else min(len(truth), int(cell["frames"]))
    if n < 2:
        raise ValueError(f"cell {cell_key(cell)}: expected >= 2 frames, received {n}")
    if shape_file is not None:
        from isa_mocap_ros.body import load_shape

        shape = load_shape(shape_file)
    model = make_model(int(cell["model"]), shape=shape)
    cfg = TrackerConfig.from_flat(optimizer=cell["algorithm"], evals=int(cell["budget"]), seed=int(cell["seed"]))
    tracker = Tracker(model, rig.cameras, cfg)
    tracker.initialize(pose=_project(truth[0], truth_model, model))
    est, energies, evals, fell = [], [], [], 0
    for k in range(1, n):
        r = tracker.step(list(masks[k]), k)
        x = r.x if r.x is not None else tracker.last_estimate
        est.append(x)
        energies.append(float(r.energy))
        evals.append(int(r.n_evals))
        fell += int(r.fell_back)
    if markers is not None:     # a mesh body: by the mesh skeleton's joint centres (knees in 3-D)
        from isa_mocap_ros.eval import score_markers

        acc = score_markers(model, np.array(est), markers[0], markers[1][1:n])
        acc["frame_errors_mm"] = [round(float(e), 2) for e in acc["frame_errors_mm"]]
    else:
        acc = accuracy(model, np.array(est), truth_model, truth[1:n])
    return {**cell, "key": cell_key(cell), "mpjpe_mm": acc["mpjpe_mm"], "knee_rmse_deg": acc["knee_rmse_deg"],
            "max_frame_error_mm": acc["max_frame_error_mm"], "frames": acc["frames"], "fell_back": fell,
            "evals_per_frame": float(np.mean(evals)), "max_evals_frame": int(max(evals)),
            "seconds": round(time.perf_counter() - t0, 3), "frame_errors_mm": acc["frame_errors_mm"],
            "frame_energies": [round(e, 6) for e in energies]}


# ------------------------------------------------------------------ analysis
def _mean_table(records: Iterable[dict]) -> dict:
    """``{(alg, dof, budget, seq): (mean mpjpe over seeds, n seeds, std)}``."""
    acc: dict = {}
    for r in records:
        acc.setdefault((r["algorithm"], int(r["model"]), int(r["budget"]), r["sequence"]), []).append(r["mpjpe_mm"])
    return {k: (float(np.mean(v)), len(v), float(np.std(v))) for k, v in acc.items()}


def _table(means: dict, columns: Sequence[tuple], names: Sequence[str], sequences: Sequence[str], alpha: float):
    """Ranking table over the sequences where every column has a value (None if < 1 problem or < 2 columns)."""
    seqs = [s for s in sequences if all((c + (s,)) in means for c in columns)]
    if len(columns) < 2 or not seqs:
        return None
    E = np.array([[means[c + (s,)][0] for c in columns] for s in seqs])
    try:
        t = ranking_table(E, list(names), alpha=alpha)
    except StatsError:
        return None
    d = t.to_dict()
    d["problems"] = seqs
    return t, d


def _pairs(means: dict, a: tuple, b: tuple, contexts: Sequence[tuple]) -> dict | None:
    """Matched comparison of two configurations over contexts (tuples completing their keys)."""
    from scipy.stats import wilcoxon

    xa, xb = [], []
    for c in contexts:
        ka, kb = a + c, b + c
        if ka in means and kb in means:
            xa.append(means[ka][0])
            xb.append(means[kb][0])
    if not xa:
        return None
    xa, xb = np.array(xa), np.array(xb)
    p = None
    if len(xa) >= 2 and np.any(xa != xb):
        try:
            p = float(wilcoxon(xa, xb).pvalue)
        except ValueError:
            p = None
    return {"n": int(len(xa)), "mean_a_mm": float(xa.mean()), "mean_b_mm": float(xb.mean()),
            "b_better": int(np.sum(xb < xa)), "a_better": int(np.sum(xa < xb)), "wilcoxon_p": p}


def summarize(records: Sequence[dict], *, alpha: float = 0.05) -> dict:
    """The comparison's outputs from cell records (see the module docstring); JSON-able."""
    records = list(records)
    means = _mean_table(records)
    algs = sorted({k[0] for k in means}, key=lambda a: (ALGORITHMS + PEER_ALGORITHMS + (a,)).index(a))
    dofs = sorted({k[1] for k in means})
    budgets = sorted({k[2] for k in means})
    seqs = sorted({k[3] for k in means})
    out: dict = {"records": len(records), "algorithms": algs, "models": dofs, "budgets": budgets, "sequences": seqs,
                 "alpha": alpha}
    out["cells"] = [{"algorithm": k[0], "model": k[1], "budget": k[2], "sequence": k[3], "mpjpe_mm": v[0],
                     "runs": v[1], "std_mm": v[2]} for k, v in sorted(means.items())]
    # mean over sequences per (alg, dof, budget)
    overall = {}
    for a in algs:
        for d in dofs:
            for b in budgets:
                v = [means[(a, d, b, s)][0] for s in seqs if (a, d, b, s) in means]
                if v:
                    overall[label(a, d, b)] = float(np.mean(v))
    out["mean_over_sequences_mm"] = overall
    # Tables 4-5: per model and budget, all algorithms
    rt = []
    for d in dofs:
        for b in budgets:
            cols = [(a, d, b) for a in algs if any((a, d, b, s) in means for s in seqs)]
            t = _table(means, cols, [label(*c) for c in cols], seqs, alpha)
            if t is not None:
                rt.append({"model": d, "budget": b, **t[1]})
    out["ranking"] = rt
    # Tables 6-7: per family over (DOF, budget)
    fam = []
    for a in algs:
        cols = [(a, d, b) for d in dofs for b in budgets if any((a, d, b, s) in means for s in seqs)]
        t = _table(means, cols, [label(*c) for c in cols], seqs, alpha)
        if t is not None:
            fam.append({"algorithm": a, "hierarchical": inner_optimizer(a) is not None, **t[1]})
    out["families"] = fam
    # holistic vs hierarchical, matched over (dof, budget, sequence)
    ctx = [(d, b, s) for d in dofs for b in budgets for s in seqs]
    hh = []
    for h, hi in HIERARCHICAL_PAIRS:
        r = _pairs(means, (h,), (hi,), ctx)
        if r is not None:
            hh.append({"holistic": h, "hierarchical": hi, **r})
    out["holistic_vs_hierarchical"] = hh
    # 28 vs 39 DOF per algorithm, matched over (budget, sequence)
    dd = []
    if 28 in dofs and 39 in dofs:
        for a in algs:
            ctx2 = [(b, s) for b in budgets for s in seqs]
            r = _pairs(means, (a, 28), (a, 39), ctx2)
            if r is not None:
                dd.append({"algorithm": a, "a": "28 DOF", "b": "39 DOF", **r})
    out["dof_28_vs_39"] = dd
    # our best (by mean over sequences) against each peer, per model and budget, every sequence
    peers = []
    ours = [a for a in algs if a not in PEER_ALGORITHMS]
    for d in dofs:
        for b in budgets:
            cand = [(overall[label(a, d, b)], a) for a in ours if label(a, d, b) in overall]
            if not cand:
                continue
            best = min(cand)[1]
            for p in (x for x in algs if x in PEER_ALGORITHMS):
                per_seq = {s: {"ours_mm": means[(best, d, b, s)][0], "peer_mm": means[(p, d, b, s)][0]}
                           for s in seqs if (best, d, b, s) in means and (p, d, b, s) in means}
                if per_seq:
                    peers.append({"model": d, "budget": b, "ours": best, "peer": p, "per_sequence": per_seq,
                                  "ours_better_everywhere": all(v["ours_mm"] < v["peer_mm"] for v in per_seq.values())})
    out["ours_vs_peers"] = peers
    out["fell_back_frames"] = int(sum(r.get("fell_back", 0) for r in records))
    out["max_evals_frame"] = {a: int(max(r["max_evals_frame"] for r in records if r["algorithm"] == a)) for a in algs}
    return out


def _fmt_p(p) -> str:
    if p is None or (isinstance(p, float) and not math.isfinite(p)):
        return "-"
    return f"{p:.2E}" if p < 1e-3 else f"{p:.3f}"


def render_markdown(summary: dict) -> str:
    """Markdown tables of :func:`summarize`'s output (the body of ``docs/RESULTS.md``)."""
    L = []
    seqs = summary["sequences"]
    L += ["### Mean joint error per cell (Eq. 20, mm; mean over seeds)", ""]
    cells = {(c["algorithm"], c["model"], c["budget"], c["sequence"]): c for c in summary["cells"]}
    L.append("| algorithm | DOF | evals | " + " | ".join(seqs) + " | mean |")
    L.append("|---|---|---|" + "---|" * (len(seqs) + 1))
    for a in summary["algorithms"]:
        for d in summary["models"]:
            for b in summary["budgets"]:
                if label(a, d, b) not in summary["mean_over_sequences_mm"]:
                    continue
                vals = [f"{cells[(a, d, b, s)]['mpjpe_mm']:.1f}" if (a, d, b, s) in cells else "" for s in seqs]
                L.append(f"| {a} | {d} | {b} | " + " | ".join(vals)
                         + f" | {summary['mean_over_sequences_mm'][label(a, d, b)]:.1f} |")

    def block(title, t):
        L.extend(["", f"#### {title}", "", "| Algorithm | Rank | p-value | Holm |", "|---|---|---|---|"])
        for r in t["rows"]:
            pv = _fmt_p(r["pvalue"])
            L.append(f"| {r['algorithm']} | {r['rank']:.3f} | {('**' + pv + '**') if r['reject'] else pv} | "
                     f"{'' if r['threshold'] is None else format(r['threshold'], '.3f')} |")
        f = t["friedman"]
        L.append(f"| *Fried. Stat.* | {f['statistic']:.3f} | p={_fmt_p(f['pvalue'])} (df {f['df']}, N={f['n_problems']}, "
                 f"critical {f['critical_value']:.3f}) | |")

    if summary["ranking"]:
        L += ["", "### Friedman / Holm ranking per model and budget (as Tables 4-5; problems = sequences)"]
        for t in summary["ranking"]:
            block(f"{t['model']} DOF, {t['budget']} evaluations", t)
    if summary["families"]:
        L += ["", "### Per algorithm over DOF and budget (as Tables 6-7)"]
        for t in summary["families"]:
            block(f"{t['algorithm']} ({'hierarchical' if t['hierarchical'] else 'holistic'})", t)
    if summary["holistic_vs_hierarchical"]:
        L += ["", "### Holistic vs hierarchical (matched over DOF × budget × sequence)", "",
              "| holistic | hierarchical | n | holistic mm | hierarchical mm | hierarchical better | Wilcoxon p |",
              "|---|---|---|---|---|---|---|"]
        for r in summary["holistic_vs_hierarchical"]:
            L.append(f"| {r['holistic']} | {r['hierarchical']} | {r['n']} | {r['mean_a_mm']:.1f} | {r['mean_b_mm']:.1f} "
                     f"| {r['b_better']}/{r['n']} | {_fmt_p(r['wilcoxon_p'])} |")
    if summary["dof_28_vs_39"]:
        L += ["", "### 28 vs 39 DOF (matched over budget × sequence)", "",
              "| algorithm | n | 28 DOF mm | 39 DOF mm | 39 better | Wilcoxon p |", "|---|---|---|---|---|---|"]
        for r in summary["dof_28_vs_39"]:
            L.append(f"| {r['algorithm']} | {r['n']} | {r['mean_a_mm']:.1f} | {r['mean_b_mm']:.1f} | "
                     f"{r['b_better']}/{r['n']} | {_fmt_p(r['wilcoxon_p'])} |")
    if summary["ours_vs_peers"]:
        L += ["", "### Our best algorithm vs the reference peers (mean over seeds, mm)", "",
              "| DOF | evals | ours | peer | " + " | ".join(seqs) + " | ours better everywhere |",
              "|---|---|---|---|" + "---|" * (len(seqs) + 1)]
        for r in summary["ours_vs_peers"]:
            vals = [f"{r['per_sequence'][s]['ours_mm']:.1f} vs {r['per_sequence'][s]['peer_mm']:.1f}"
                    if s in r["per_sequence"] else "" for s in seqs]
            L.append(f"| {r['model']} | {r['budget']} | {r['ours']} | {r['peer']} | " + " | ".join(vals)
                     + f" | {'yes' if r['ours_better_everywhere'] else 'no'} |")
    return "\n".join(L) + "\n"


# ------------------------------------------------------------------ findings and targets (checked, not assumed)
#: the paper's particle filters and their evolutionary counterparts (holistic, hierarchical)
PF_COUNTERPARTS = (("cmaes", "apf"), ("de", "apf"), ("pso", "apf"),
                   ("h-cmaes", "psapf"), ("h-de", "psapf"), ("h-pso", "psapf"))
EVOLUTIONARY = ("cmaes", "h-cmaes", "de", "h-de", "pso", "h-pso")


def _verdict(wins: int, n: int, p) -> str:
    """``holds`` (better in most matched comparisons, Wilcoxon p < 0.05), ``not significant`` (better in most,
    p >= 0.05 or untestable), ``does not hold`` (not better in most), ``not tested`` (no data)."""
    if n == 0:
        return "not tested"
    if 2 * wins <= n:
        return "does not hold"
    return "holds" if (p is not None and p < 0.05) else "not significant"


def _matched(cells: dict, pairs) -> tuple[np.ndarray, np.ndarray]:
    a, b = [], []
    for ka, kb in pairs:
        if ka in cells and kb in cells:
            a.append(cells[ka])
            b.append(cells[kb])
    return np.array(a, dtype=float), np.array(b, dtype=float)


def _claim(name: str, claim: str, xa: np.ndarray, xb: np.ndarray, la: str, lb: str) -> dict:
    """Claim "b is better (lower error) than a" on matched values."""
    from scipy.stats import wilcoxon

    n = int(len(xa))
    wins = int(np.sum(xb < xa)) if n else 0
    p = None
    if n >= 2 and np.any(xa != xb):
        try:
            p = float(wilcoxon(xa, xb).pvalue)
        except ValueError:
            p = None
    return {"finding": name, "claim": claim, "n": n, "better": wins, "mean_a_mm": float(xa.mean()) if n else None,
            "mean_b_mm": float(xb.mean()) if n else None, "a": la, "b": lb, "wilcoxon_p": p,
            "verdict": _verdict(wins, n, p)}


def findings(summary: dict) -> list[dict]:
    """The comparison paper's qualitative findings checked on :func:`summarize`'s cell means.

    * EA vs PF: each evolutionary algorithm against its particle-filter counterpart (holistic CMA-ES,
      DE, PSO vs APF; hierarchical H-CMAES, H-DE, H-PSO vs PSAPF), matched over DOF × budget × sequence;
    * hierarchical vs holistic: the pairs of :data:`HIERARCHICAL_PAIRS` (ISA/H-ISA included), matched
      over DOF × budget × sequence;
    * 39 vs 28 DOF: each evolutionary algorithm at 39 against 28 DOF (the paper: EAs gain from the
      39-DOF model, the particle filters do not), matched over budget × sequence; the particle
      filters' pairs are reported apart.

    A finding *holds* when the claimed side has the lower error in most matched comparisons and the
    Wilcoxon signed-rank test gives p < 0.05; *not significant* when it is lower in most but p >= 0.05;
    *does not hold* otherwise.
    """
    cells = {(c["algorithm"], int(c["model"]), int(c["budget"]), c["sequence"]): c["mpjpe_mm"]
             for c in summary["cells"]}
    ctx = sorted({k[1:] for k in cells})
    out = []
    pairs = [((pf,) + c, (ea,) + c) for ea, pf in PF_COUNTERPARTS for c in ctx]
    out.append(_claim("EA vs PF", "evolutionary algorithms beat their particle-filter counterparts (CMA-ES/DE/PSO vs "
                      "APF, H-CMAES/H-DE/H-PSO vs PSAPF)", *_matched(cells, pairs), "particle filters",
                      "evolutionary"))
    pairs = [((h,) + c, (hi,) + c) for h, hi in HIERARCHICAL_PAIRS for c in ctx]
    out.append(_claim("hierarchical vs holistic", "the hierarchical strategy beats the holistic one (ISA/H-ISA, "
                      "APF/PSAPF, CMA-ES/H-CMAES, DE/H-DE, PSO/H-PSO)", *_matched(cells, pairs), "holistic",
                      "hierarchical"))
    ctx2 = sorted({(k[2], k[3]) for k in cells})
    pairs = [((a, 28) + c, (a, 39) + c) for a in EVOLUTIONARY for c in ctx2]
    out.append(_claim("39 vs 28 DOF (EAs)", "evolutionary algorithms are more accurate with the 39-DOF model than "
                      "with 28 DOF", *_matched(cells, pairs), "28 DOF", "39 DOF"))
    pairs = [((a, 28) + c, (a, 39) + c) for a in ("apf", "psapf") for c in ctx2]
    r = _claim("39 vs 28 DOF (PFs)", "the particle filters do not gain from 39 DOF (the paper: \"the same is not "
               "true for the particle filters\"); shown for reference, holds when 39 DOF is NOT better",
               *_matched(cells, pairs), "28 DOF", "39 DOF")
    if r["n"]:
        r["verdict"] = "holds" if r["verdict"] == "does not hold" else \
            ("holds (39 DOF better, not significantly)" if r["verdict"] == "not significant" else "does not hold")
    out.append(r)
    return out


def peer_targets(summary: dict, budget: int = 1500) -> list[dict]:
    """Issue #7's target: our best estimator at ``budget`` evaluations beats pycma and scipy-DE on every
    sequence (per model; our best = lowest mean over sequences, as in :func:`summarize`)."""
    out = []
    for r in summary.get("ours_vs_peers", []):
        if int(r["budget"]) != budget:
            continue
        out.append({"model": r["model"], "budget": r["budget"], "ours": r["ours"], "peer": r["peer"],
                    "per_sequence": r["per_sequence"], "met": bool(r["ours_better_everywhere"])})
    return out


def plot_summary(summary: dict, path: Path | str) -> Path:
    """PNG: mean error over the sequences against the budget, one line per algorithm, one panel per model."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = {}
    for c in summary["cells"]:
        cells.setdefault((c["algorithm"], c["model"], c["budget"]), []).append(c["mpjpe_mm"])
    dofs = summary["models"]
    fig, ax = plt.subplots(1, len(dofs), figsize=(5.2 * len(dofs), 4.2), squeeze=False, sharey=True)
    for j, d in enumerate(dofs):
        a_ = ax[0, j]
        for alg in summary["algorithms"]:
            bs = [b for b in summary["budgets"] if (alg, d, b) in cells]
            if not bs:
                continue
            style = "--" if alg in PEER_ALGORITHMS else ("-" if inner_optimizer(alg) is not None else ":")
            a_.plot(bs, [np.mean(cells[(alg, d, b)]) for b in bs], style, marker="o", ms=3, label=alg)
        a_.set_title(f"{d} DOF", fontsize=9)
        a_.set_xlabel("evaluations per frame")
        a_.grid(alpha=0.3)
    ax[0, 0].set_ylabel("mean joint error over sequences (mm)")
    ax[0, -1].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return Path(path)
