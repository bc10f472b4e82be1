"""numba's on-disk cache keyed on the files whose compiled functions a module calls, not on its own file only.

numba keys a cached function (``@njit(cache=True)``) on its own source file: a compiled function that calls a
compiled function of another module carries that callee's machine code in its own, so after an edit (or a
``git pull``) of the callee's file it would load its old machine code, callee included. A module whose compiled
functions call another module's registers that module here (:func:`register_dependent_cache`, at import, after
importing it); the stamp then covers its dependencies' files and, transitively, theirs.
``test/test_numba_cache.py`` finds every compiled function that calls another module's and fails when its module
did not register that module. Pure: imports numba only.
"""
from __future__ import annotations

import hashlib
import os
from types import ModuleType

__all__ = ["register_dependent_cache", "registered", "dependencies", "dependency_names"]

#: Registered modules: the absolute path of a module's file → the absolute paths of the files its cache depends on
#: (its registered modules and, transitively, theirs; in a fixed order).
_REGISTRY: dict[str, tuple[str, ...]] = {}
_NAMES: dict[str, tuple[str, ...]] = {}


def registered() -> dict[str, tuple[str, ...]]:
    """A copy of the registry: each registered module's file → the files its numba cache depends on."""
    return dict(_REGISTRY)


def dependencies(path: str) -> tuple[str, ...]:
    """The files the numba cache of the module at ``path`` depends on besides its own (empty: not registered)."""
    return _REGISTRY.get(os.path.abspath(path), ())


def dependency_names(path: str) -> tuple[str, ...]:
    """The module names of :func:`dependencies` (``path``'s), in the same order."""
    return _NAMES.get(os.path.abspath(path), ())


def register_dependent_cache(path: str, modules: tuple[ModuleType, ...]) -> None:
    """Make numba's on-disk cache of the functions of the module at ``path`` depend on the files of ``modules``
    (the modules whose compiled functions they call, imported before) and on the files those depend on if they
    registered theirs. A locator placed first among numba's asks the locator numba would have chosen for everything
    but the stamp, which it extends with the dependencies' hashes. Best effort: if numba's (internal) caching API
    differs, the registry is kept (the test reads it) and numba's caching is unchanged.

    Why numba's private ``CacheImpl._locator_classes`` (and ``_CacheLocator``, the locators' base): numba
    (0.68) offers no public way to make a cached function's key depend on other files. Its documented
    options choose *where* the cache lives (``NUMBA_CACHE_DIR``) and *which* of its locators run
    (``NUMBA_CACHE_LOCATOR_CLASSES``, read from the process environment: it would replace the locator
    list of every package in the process, and a class named there still has to subclass the private
    ``_CacheLocator``); ``cache=False`` on these functions would recompile them (about a minute) in every
    process. The insertion touches the registered module's functions only: the locator returns None for any
    other file, and numba's own locator list follows unchanged."""
    here = os.path.abspath(path)
    deps: list[str] = []
    names: list[str] = []
    for m in modules:
        f = os.path.abspath(m.__file__)
        for d, n in zip((f,) + _REGISTRY.get(f, ()), (m.__name__,) + _NAMES.get(f, ())):
            if d != here and d not in deps:
                deps.append(d)
                names.append(n)
    _REGISTRY[here], _NAMES[here] = tuple(deps), tuple(names)
    try:
        from numba.core import caching
    except ImportError:                                                    # pragma: no cover
        return
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    if impl is None or not hasattr(caching, "_CacheLocator"):                # pragma: no cover
        return
    dep_tag = hashlib.sha256(" ".join(names).encode()).hexdigest()[:8]
    dep_files = tuple(deps)

    class _DependentLocator(caching._CacheLocator):
        def __init__(self, inner):
            self._inner = inner

        def ensure_cache_path(self):
            self._inner.ensure_cache_path()

        def get_cache_path(self):
            return self._inner.get_cache_path()

        def get_disambiguator(self):
            # the dependencies' module names are part of the cache files' names: an index pickles the kernel
            # module's types by module name, so an index written before a dependency was renamed would fail to
            # load (ModuleNotFoundError) instead of missing
            return f"{self._inner.get_disambiguator()}-{dep_tag}"

        def get_source_stamp(self):
            h = hashlib.sha256()
            for p in dep_files:
                with open(p, "rb") as f:
                    h.update(f.read())
            return self._inner.get_source_stamp(), h.hexdigest()

        @classmethod
        def from_function(cls, py_func, py_file):
            if os.path.abspath(py_file) != here:
                return None
            for other in impl._locator_classes:
                if other is not cls and getattr(other, "_isa_mocap_path", None) is None:
                    inner = other.from_function(py_func, py_file)
                    if inner is not None:
                        return cls(inner)
            return None

    impl._locator_classes[:] = [c for c in impl._locator_classes if getattr(c, "_isa_mocap_path", None) != here]
    _DependentLocator._isa_mocap_path = here
    impl._locator_classes.insert(0, _DependentLocator)
