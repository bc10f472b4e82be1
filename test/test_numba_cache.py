"""numba's cache keyed on the files a compiled function calls into (isa_mocap_ros.numba_cache): every compiled
function that calls another module's compiled function belongs to a module registered with that module, so an
edit of the callee's file recompiles the caller instead of loading its old machine code."""
from __future__ import annotations

import hashlib
import importlib
import os
import sys
import types
from pathlib import Path

from numba.core.dispatcher import Dispatcher
from numba.core.extending import _Intrinsic

from isa_mocap_ros import numba_cache

PACKAGE = Path(__file__).resolve().parents[1] / "isa_mocap_ros"


def _codes(code):
    yield code
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            yield from _codes(c)


def _module_of(obj) -> str | None:
    if isinstance(obj, Dispatcher):
        return obj.py_func.__module__
    if isinstance(obj, _Intrinsic):
        return obj._defn.__module__
    return None


def cross_module_calls(mod) -> set[str]:
    """Names of the other modules whose compiled functions (njit dispatchers, intrinsics) the compiled functions
    defined in ``mod`` refer to, by a global name or an attribute of a module global."""
    out = set()
    for v in vars(mod).values():
        if not (isinstance(v, Dispatcher) and v.py_func.__module__ == mod.__name__):
            continue
        g = v.py_func.__globals__
        for code in _codes(v.py_func.__code__):
            for name in code.co_names:
                t = g.get(name)
                found = [t]
                if isinstance(t, types.ModuleType):
                    found = [getattr(t, a, None) for a in code.co_names]
                for f in found:
                    src = _module_of(f)
                    if src is not None and src != mod.__name__:
                        out.add(src)
    return out


def unregistered(mod) -> list[str]:
    deps = set(numba_cache.dependencies(mod.__file__))
    return [f"{mod.__name__} calls compiled code of {src} without register_dependent_cache on it"
            for src in sorted(cross_module_calls(mod)) if os.path.abspath(sys.modules[src].__file__) not in deps]


def _compiled_modules():
    for f in sorted(PACKAGE.rglob("*.py")):
        rel = f.relative_to(PACKAGE.parent)
        if rel.parts[1] in ("nodes", "cli") or "njit" not in f.read_text():
            continue
        yield importlib.import_module(".".join(rel.with_suffix("").parts))


def test_every_cross_module_compiled_caller_is_registered():
    mods = list(_compiled_modules())
    assert len(mods) > 10
    bad = [line for m in mods for line in unregistered(m)]
    assert not bad, "\n".join(bad)


def test_the_check_sees_an_unregistered_caller(tmp_path, monkeypatch):
    (tmp_path / "nc_callee.py").write_text("import numba\n\n@numba.njit\ndef twice(x):\n    return 2 * x\n")
    (tmp_path / "nc_caller.py").write_text(
        "import numba\nimport nc_callee\nfrom nc_callee import twice\n\n"
        "@numba.njit\ndef four(x):\n    return twice(twice(x))\n\n"
        "@numba.njit\ndef eight(x):\n    return nc_callee.twice(four(x))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    caller = importlib.import_module("nc_caller")
    assert cross_module_calls(caller) == {"nc_callee"}
    assert unregistered(caller) == ["nc_caller calls compiled code of nc_callee without register_dependent_cache on it"]
    numba_cache.register_dependent_cache(caller.__file__, (sys.modules["nc_callee"],))
    assert unregistered(caller) == []


def test_dependencies_are_transitive_and_stamp_the_cache():
    from isa_mocap_ros.body import kinematics
    from isa_mocap_ros.geometry import so3_kernel
    from isa_mocap_ros.optim import _fast_so3, compiled_search, compiled_stage

    deps = numba_cache.dependencies(compiled_search.__file__)
    # the rotation mean's 3x3 product is so3_kernel's (via _fast_so3), the energy kernels call kinematics
    for m in (_fast_so3, so3_kernel, kinematics):
        assert os.path.abspath(m.__file__) in deps
    assert set(numba_cache.dependencies(compiled_search.__file__)) < set(numba_cache.dependencies(compiled_stage.__file__))
    for fn in (compiled_search._partition, compiled_search.rotation_mean, compiled_stage._moved_isa,
               _fast_so3.exp_many):
        locator = fn._cache._impl.locator
        assert type(locator).__name__ == "_DependentLocator"
        h = hashlib.sha256()
        for path in numba_cache.dependencies(fn.py_func.__code__.co_filename):
            h.update(Path(path).read_bytes())
        assert locator.get_source_stamp()[1] == h.hexdigest()
        assert locator.get_disambiguator().startswith(locator._inner.get_disambiguator() + "-")

