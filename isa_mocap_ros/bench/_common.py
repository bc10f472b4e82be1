"""Helpers every benchmark module shares (no benchmark imports another one's private helpers)."""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path


def json_of(mod, argv: list[str]) -> dict:
    """Run bench module ``mod`` with ``argv + ["--json"]`` and return the JSON it printed."""
    bp = argparse.ArgumentParser()
    mod.add_arguments(bp)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = mod.run(bp.parse_args(argv + ["--json"]))
    if rc:
        raise RuntimeError(f"{mod.__name__} {argv}: exit code {rc}")
    text = buf.getvalue().strip()
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return json.loads(text.splitlines()[-1])


def comma_list(v) -> tuple | None:
    """A ``--flag A,B`` value as a tuple of its non-empty items (stripped); None for None (the flag not given)."""
    return None if v is None else tuple(x.strip() for x in str(v).split(",") if x.strip())


def energy_sizes(d: dict) -> str:
    """The fast energy's sample sizes and threads, when ``bench energy`` reports them."""
    parts = []
    if d.get("n_template") is not None:
        parts.append(f"{d['n_template']} model points")
    if d.get("n_mask_points") is not None:
        parts.append(f"{d['n_mask_points']} foreground points per view")
    if d.get("downsample") is not None:
        parts.append(f"downsample {d['downsample']}")
    if d.get("threads") is not None:
        parts.append(f"{d['threads']} threads")
    return "; fast energy: " + ", ".join(parts) if parts else ""


def write_result(bench: str, res: dict, json_path, markdown: str) -> int:
    """Write a bench's results ``res`` as one line of JSON to ``json_path``, print its markdown and where the
    JSON went; the bench's exit code (0)."""
    Path(json_path).parent.mkdir(parents=True, exist_ok=True)
    Path(json_path).write_text(json.dumps(res, default=float) + "\n")
    print(markdown)
    print(f"bench {bench}: wrote {json_path}")
    return 0


def collect_and_write(bench: str, collect, design, args: argparse.Namespace, render_markdown) -> int:
    """The shared tail of the mesh benches: ``collect(design, cache=, out=, jobs=)`` in ``args.out`` (a temporary
    directory when unset) with rendered bags in ``args.cache`` (default ``OUT/cache``), the wall time and the command
    line added, written by :func:`write_result` to ``args.json``; the bench's exit code."""
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix=f"isa_mocap_{bench}_"))
    cache = Path(args.cache) if args.cache else out / "cache"
    t0 = time.perf_counter()
    res = collect(design, cache=cache, out=out, jobs=args.jobs)
    res["seconds"] = round(time.perf_counter() - t0, 1)
    res["command"] = f"isa-mocap bench {bench} " + " ".join(sys.argv[3:])
    return write_result(bench, res, args.json, render_markdown(res))
