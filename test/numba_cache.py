"""Run a script twice against one fresh numba cache: the first process compiles, the second loads
(shared by the tests that check compiled and cache-loaded kernels compute the same bits)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def stdout_compiled_then_cached(script: str, cache_dir: Path, *, timeout: float, args: tuple[str, ...] = (),
                                **env) -> list[str]:
    """Standard output of ``python -c script args...`` run twice with ``NUMBA_CACHE_DIR=cache_dir`` (plus
    ``env``); asserts both runs succeeded."""
    full = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), **env)
    runs = [subprocess.run([sys.executable, "-c", script, *args], env=full, capture_output=True, text=True,
                           timeout=timeout) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr[-2000:]
    return [r.stdout for r in runs]
