"""Whether numpy's float64 ufuncs give libm's bits on this machine.

The compiled (numba) helpers call libm; their numpy references call numpy's ufuncs. On an AVX2
machine numpy's float64 exp, log, sin, cos, arccos and power are libm's to the bit, on an AVX-512
one (``np.show_runtime()``: X86_V4 / AVX512_SKX found) numpy has SIMD implementations of its own
that differ in the last bit now and then. Tests that compare a compiled helper with its numpy
reference ask bit equality where the probe says numpy is libm, else agreement to rounding.
"""
import math

import numpy as np


def _numpy_is_libm() -> bool:
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-700, 700, 2000), rng.uniform(-5, 5, 2000), rng.uniform(-1e-3, 1e-3, 500)])
    pos = np.abs(x) + 1e-300
    unit = np.clip(x / 700, -1, 1)
    pairs = [(np.exp, math.exp, x), (np.log, math.log, pos), (np.log10, math.log10, pos), (np.sin, math.sin, x),
             (np.cos, math.cos, x), (np.arccos, math.acos, unit), (lambda a: np.power(10.0, a), lambda a: 10.0 ** a,
                                                                   x / 100)]
    for f_np, f_libm, a in pairs:
        if not np.array_equal(f_np(a), np.array([f_libm(float(v)) for v in a])):
            return False
    return True


NUMPY_IS_LIBM = _numpy_is_libm()
