"""Optimizer comparison (EA-vs-PF §5.2-5.4): algorithms × models × budgets × seeds × sequences, Friedman/Holm.

``isa-mocap bench compare [--quick | --full] [--json] [--jobs N] [--resume DIR] [--out DIR]
[--write-results FILE] [--body mesh|capsules] [--seeds N] [--frames N]``. ``--body mesh`` (default):
every sequence shows a skinned human mesh, scored by its skeleton's joint centres; ``capsules`` the
tracking model's own capsules (a control). The designs are :func:`isa_mocap_ros.eval.compare.make_design`'s (see
``docs/evaluation.md``): sequences are synthesized once into ``OUT/cache``, the cells run offline
(no ROS) in a process pool with a progress bar, every finished cell is appended to
``OUT/cells.jsonl`` (``--resume OUT`` skips the cells already there), and the summary (mean error per
cell, the ranking tables per model and budget like Tables 4-5, per family like Tables 6-7, holistic
vs hierarchical, 28 vs 39 DOF, ours vs the peers) is printed, written to ``OUT/summary.json`` and,
with ``--write-results``, rendered as Markdown with the command and machine.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from isa_mocap_ros.bench._common import comma_list


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="tiny smoke design (2 algorithms, 1 model/budget/seed/sequence)")
    g.add_argument("--full", action="store_true", help="the paper's protocol: 30 seeds, 2 s at 30 fps, 320x240")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--jobs", type=int, default=2, metavar="N", help="worker processes (default 2; 1 = in process)")
    p.add_argument("--out", default=None, metavar="DIR", help="results directory (default: a new temporary one)")
    p.add_argument("--resume", default=None, metavar="DIR", help="continue the run in DIR (skip its finished cells)")
    p.add_argument("--algorithms", default=None, metavar="A,B", help="restrict the design to these algorithms")
    p.add_argument("--write-results", default=None, metavar="FILE", help="write the Markdown tables to FILE")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--body", choices=("mesh", "capsules"), default="mesh",
                   help="mesh (default): skinned human sequences; capsules: the tracking model's own (control)")
    p.add_argument("--seeds", type=int, default=None, metavar="N", help="use the first N seeds of the design")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="track only the first N frames of each sequence")
    p.add_argument("--shape", choices=("auto", "truth"), default="auto",
                   help="tracking model's shape: auto (default) calibrated once per sequence from its images (isa-mocap "
                        "calibrate's code); truth = the sequence's ground-truth shape (a diagnostic only)")


def _init_worker() -> None:
    # one thread per worker process: --jobs processes share the cores (set before the numeric
    # libraries load, which happens in the first _work of a spawned worker)
    for k in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[k] = "1"


def _work(cell: dict, cache: str, shape_file: str | None = None) -> dict:
    from isa_mocap_ros.eval.compare import run_cell

    return run_cell(cell, cache, shape_file)


def _machine() -> str:
    try:
        cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "")
    except OSError:
        cpu = ""
    return f"{platform.node()}: {os.cpu_count()} CPUs {cpu}, {platform.system()} {platform.release()}, " \
           f"Python {platform.python_version()}"


def run_design(design, out: Path, *, jobs: int = 2, progress: bool = True) -> list[dict]:
    """Run (or finish) ``design`` in ``out``; return all records of its cells.

    Raises ``ValueError`` when ``out`` already holds cells of other sequences (another design's
    frames, images or views): cells are found again by algorithm, model, budget, sequence name and
    seed only, so they would mix."""
    from tqdm import tqdm

    from isa_mocap_ros.eval.compare import cell_key, prepare_sequence

    out.mkdir(parents=True, exist_ok=True)
    jl = out / "cells.jsonl"
    new = json.loads(json.dumps(design.to_dict()))
    if jl.exists() and (out / "design.json").exists():
        old = json.loads((out / "design.json").read_text())
        if old.get("sequences") != new["sequences"] or old.get("shape", "truth") != new["shape"]:
            raise ValueError(f"{out} holds the cells of other sequences (design {old.get('name')!r}: "
                             f"{_seq_summary(old.get('sequences'))}, shape {old.get('shape', 'truth')}; now "
                             f"{_seq_summary(new['sequences'])}, shape {new['shape']}); "
                             "resume only the same design, or give a new --out")
    (out / "design.json").write_text(json.dumps(new, indent=2) + "\n")
    cache = {s.name: str(prepare_sequence(s, out / "cache")) for s in design.sequences}
    shapes = {s.name: None for s in design.sequences}
    if design.shape == "auto":
        # the shape calibrated once per sequence from its silhouettes (the design's first seed); every cell tracks with it
        from isa_mocap_ros.eval.compare_shape import calibrate_sequence_shape

        cal = []
        for s in design.sequences:
            if progress:
                print(f"bench compare: calibrating the body shape of {s.name}", file=sys.stderr, flush=True)
            cal.append(calibrate_sequence_shape(cache[s.name], design.calib, design.seeds[0]))
            shapes[s.name] = str(Path(cache[s.name]).parent / cal[-1]["shape_file"])
        (out / "calibrations.json").write_text(json.dumps(cal, indent=2) + "\n")
    done: dict[str, dict] = {}
    if jl.exists():
        for ln in jl.read_text().splitlines():
            if ln.strip():
                try:
                    r = json.loads(ln)
                except json.JSONDecodeError:       # a line cut by an interruption
                    continue
                done[r["key"]] = r
    cells = design.cells()
    todo = [c for c in cells if cell_key(c) not in done]
    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), unit="cell", desc="compare", file=sys.stderr,
               disable=not progress)
    with open(jl, "a") as fh:
        def finish(r):
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            done[r["key"]] = r
            bar.set_postfix_str(f"{r['key']} {r['mpjpe_mm']:.1f} mm")
            bar.update(1)

        if jobs <= 1:
            for c in todo:
                finish(_work(c, cache[c["sequence"]], shapes[c["sequence"]]))
        else:
            # spawn, not fork: the parent has used OpenMP (synthesis), which forked children cannot
            with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                     initializer=_init_worker) as ex:
                futs = [ex.submit(_work, c, cache[c["sequence"]], shapes[c["sequence"]]) for c in todo]
                for f in as_completed(futs):
                    finish(f.result())
    bar.close()
    keys = {cell_key(c) for c in cells}
    return [r for k, r in done.items() if k in keys]


def _seq_summary(seqs) -> str:
    """``name frames@fps WxH`` per sequence of a design's JSON."""
    try:
        return ", ".join(f"{s['name']} {round(s['duration_s'] * s['fps'])}@{s['fps']:g} {s['width']}x{s['height']}"
                         for s in seqs)
    except (TypeError, KeyError):
        return repr(seqs)


def _add_calibrations(summary: dict, out: Path, design) -> None:
    """The shape calibrations of a ``shape="auto"`` run (``OUT/calibrations.json``) into ``summary``."""
    summary["shape"] = design.shape
    f = out / "calibrations.json"
    if design.shape == "auto" and f.is_file():
        from isa_mocap_ros.eval.compare_shape import bone_error_summary

        summary["calibrations"] = json.loads(f.read_text())
        summary["calibration_bone_error"] = bone_error_summary(summary["calibrations"])


def collect(kind: str, out: Path, *, jobs: int = 2, progress: bool = True, algorithms=None, shape: str = "auto"):
    """Run (or resume) design ``kind`` in ``out``; return ``(summary, design, seconds)`` (``bench all``)."""
    from dataclasses import replace

    from isa_mocap_ros.eval.compare import make_design, summarize

    design = make_design(kind, shape=shape)
    if algorithms:
        design = replace(design, algorithms=tuple(algorithms))
    for n in design.notes:
        print(f"bench compare: {n}", file=sys.stderr)
    t0 = time.perf_counter()
    records = run_design(design, Path(out), jobs=jobs, progress=progress)
    seconds = time.perf_counter() - t0
    summary = summarize(records)
    summary["design"] = design.to_dict()
    summary["out"] = str(out)
    _add_calibrations(summary, Path(out), design)
    (Path(out) / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary, design, seconds


def results_markdown(summary: dict, design, *, command: str, seconds: float) -> str:
    from isa_mocap_ros.eval.compare import render_markdown

    smoke = design.name == "quick"
    head = ["# Optimizer comparison results", ""]
    if smoke:
        head += ["> **Smoke run** (`--quick` design: 2 algorithms, 1 model, 1 budget, 1 seed, 3 scored frames of",
                 "> one sequence at 96 × 72). It checks the pipeline end to end; its numbers say nothing about",
                 "> the algorithms. The default and full designs have not been run yet.", ""]
    head += [f"- command: `{command}`", f"- machine: {_machine()}",
             f"- design: {design.name} — algorithms {', '.join(design.algorithms)}; models {list(design.models)}; "
             f"budgets {list(design.budgets)}; seeds {len(design.seeds)}; sequences "
             f"{', '.join(s.name for s in design.sequences)}; body "
             f"{design.sequences[0].body if design.sequences else '?'}"
             + (f"; first {design.frames} frames" if design.frames else ""),
             f"- wall time: {seconds:.0f} s; records: {summary['records']}; frames that fell back: "
             f"{summary['fell_back_frames']}", "- protocol: see [docs/evaluation.md](evaluation.md)", shape_line(summary),
             ""]
    for n in design.notes:
        head.append(f"- note: {n}")
    return "\n".join(head) + "\n" + render_markdown(summary)


def shape_line(summary: dict) -> str:
    if summary.get("shape", "truth") == "truth":
        return "- body shape: the sequences' ground truth (**a diagnostic**: a user has no true shape)"
    e = summary.get("calibration_bone_error") or {}
    per = ", ".join(f"{c['sequence']} {c['bone_error_mm']:.1f}" for c in summary.get("calibrations", []))
    return ("- body shape: calibrated once per sequence from its silhouettes (`isa-mocap calibrate`'s code, the "
            f"first seed); mean bone-length error {e.get('bone_error_mm', float('nan')):.1f} mm ({per}; the default "
            f"shape's {e.get('bone_error_default_shape_mm', float('nan')):.1f} mm)")


def run(args: argparse.Namespace) -> int:
    from isa_mocap_ros.eval.compare import make_design, summarize

    if args.jobs < 1:
        print(f"isa-mocap bench compare: error: --jobs: expected an integer >= 1, received {args.jobs}", file=sys.stderr)
        return 2
    kind = "quick" if args.quick else "full" if args.full else "default"
    design = make_design(kind, body=getattr(args, "body", "mesh"), shape=getattr(args, "shape", "auto"))
    from dataclasses import replace
    if getattr(args, "seeds", None):
        design = replace(design, seeds=design.seeds[:args.seeds])
    if getattr(args, "frames", None):
        design = replace(design, frames=int(args.frames))
    if args.algorithms:
        from dataclasses import replace
        design = replace(design, algorithms=comma_list(args.algorithms))
    for n in design.notes:
        print(f"bench compare: {n}", file=sys.stderr)
    out = Path(args.resume or args.out or tempfile.mkdtemp(prefix="isa_mocap_compare_"))
    if args.resume and not (out / "cells.jsonl").exists():
        print(f"isa-mocap bench compare: error: --resume: expected a previous run's directory with cells.jsonl, "
              f"received {out}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    try:
        records = run_design(design, out, jobs=args.jobs, progress=not args.no_progress)
    except KeyboardInterrupt:
        print(f"\nbench compare: interrupted; resume with --resume {out}", file=sys.stderr)
        return 130
    except ValueError as exc:
        print(f"isa-mocap bench compare: error: {exc}", file=sys.stderr)
        return 2
    seconds = time.perf_counter() - t0
    summary = summarize(records)
    summary["design"] = design.to_dict()
    summary["out"] = str(out)
    _add_calibrations(summary, Path(out), design)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    command = "isa-mocap bench compare " + " ".join(a for a in sys.argv[3:] if a) if sys.argv[1:3] == ["bench", "compare"] \
        else f"isa-mocap bench compare{' --quick' if args.quick else ' --full' if args.full else ''}"
    md = results_markdown(summary, design, command=command.strip(), seconds=seconds)
    if args.write_results:
        Path(args.write_results).parent.mkdir(parents=True, exist_ok=True)
        Path(args.write_results).write_text(md)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(md)
        print(f"bench compare: wrote {out / 'cells.jsonl'}, {out / 'summary.json'}"
              + (f", {args.write_results}" if args.write_results else ""))
    return 0
