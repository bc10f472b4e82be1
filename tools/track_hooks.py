"""`isa-mocap track` run in this process with some of the package's functions replaced: the research tools' hook
(oracle_track, real_oracle, real_terms, untwist_trace) for recording or steering what the tracker does, frame by frame."""
from __future__ import annotations

import numpy as np

from isa_mocap_ros.cli.main import main as isa_main


def track_args(argv: list[str], flag: str, usage: str | None) -> tuple[bool, list[str], str, str]:
    """A research tool's command line, ``BAG --out DIR [track's options] [FLAG]``: whether ``flag`` was given,
    track's arguments (``argv`` without it), the bag and the output directory. Without a bag or ``--out`` it exits
    printing ``usage`` (the tool's docstring)."""
    given = flag in argv
    args = [a for a in argv if a != flag]
    if not args or "--out" not in args:
        raise SystemExit(usage)
    return given, args, args[0], args[args.index("--out") + 1]


def pop_option(argv: list[str], flag: str) -> str | None:
    """The value of ``flag VALUE`` in ``argv``, both taken out of it (``None`` when ``flag`` is not there)."""
    if flag not in argv:
        return None
    i = argv.index(flag)
    value = argv[i + 1]
    del argv[i:i + 2]
    return value


def reference_markers(bag) -> tuple[list[str], dict[int, np.ndarray]]:
    """A bag's reference markers (an imported recording's TRC): their names and, per frame stamp, their positions
    ``(M, 3)``; a bag without any exits saying so."""
    from isa_mocap_ros.cli.track_io import read_sequence

    seq = read_sequence(bag, want_images=True, want_masks=False)
    truth = {int(f.stamp_ns): np.asarray(f.truth_markers, float) for f in seq.frames if f.truth_markers is not None}
    if not truth:
        raise SystemExit(f"{bag}: expected reference markers, found none")
    return list(seq.truth_marker_names), truth


def track_patched(args: list[str], patches: list[tuple[object, str, object]]) -> int:
    """``isa-mocap track ARGS`` with each ``(owner, name, replacement)`` of ``patches`` set on its owner (a class or
    module) for the run and the originals put back after it, also when it raises. Returns track's exit code."""
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in patches]
    for owner, name, new in patches:
        setattr(owner, name, new)
    try:
        return isa_main(["track", *args])
    finally:
        for owner, name, old in saved:
            setattr(owner, name, old)
