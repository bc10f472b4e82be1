"""Issue #31's rules for a readable package: no module over ~600 lines outside kernel code, and no private
name (``_name``, or a name inside an ``_module``) imported from another subpackage."""
from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MAX_LINES = 600
#: compiled kernel code, allowed above MAX_LINES (one numba function per formula, kept together)
KERNELS = {"isa_mocap_ros/energy/silhouette_kernel.py"}


def _files():
    for pkg in ("isa_mocap_ros", "msg_adapters"):
        yield from sorted((REPO / pkg).rglob("*.py"))


def _subpackage(parts: list[str]) -> str:
    """``isa_mocap_ros.optim.isa`` -> ``isa_mocap_ros.optim``; a top-level module is its own subpackage."""
    return ".".join(parts[:2])


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def test_no_module_over_the_size_limit():
    long = {str(f.relative_to(REPO)): n for f in _files()
            if (n := len(f.read_text().splitlines())) > MAX_LINES and str(f.relative_to(REPO)) not in KERNELS}
    assert not long, f"modules over {MAX_LINES} lines (split them by responsibility): {long}"


def _private_imports(f: Path, root: Path) -> list[str]:
    """``from ... import`` lines of file ``f`` (under ``root``) that take a private name from another subpackage."""
    parts = list(f.relative_to(root).with_suffix("").parts)
    own = _subpackage(parts)
    base = parts[:-1]
    bad = []
    for node in ast.walk(ast.parse(f.read_text(), str(f))):
        if not isinstance(node, ast.ImportFrom):
            continue
        mod = node.module or ""
        if node.level:
            mod = ".".join(base[:len(base) - node.level + 1] + ([mod] if mod else []))
        if not mod.startswith(("isa_mocap_ros", "msg_adapters")):
            continue
        for a in node.names:
            target = f"{mod}.{a.name}".split(".")
            if _subpackage(target) != own and any(_private(p) for p in target[1:]):
                bad.append(f"{f.relative_to(root)}:{node.lineno}: from {mod} import {a.name}")
    return bad


def test_no_private_name_imported_across_subpackages():
    bad = [line for f in _files() for line in _private_imports(f, REPO)]
    assert not bad, "private names imported from another subpackage (make them public at the definition):\n" + \
        "\n".join(bad)


def test_the_check_sees_private_imports(tmp_path):
    """The rule fires on a private name or module of another subpackage, not on one of its own."""
    f = tmp_path / "isa_mocap_ros" / "tracking" / "demo.py"
    f.parent.mkdir(parents=True)
    f.write_text("from isa_mocap_ros.body.kinematics import _hidden, joint_positions\n"
                 "from isa_mocap_ros.energy import _kernel\n"
                 "from ..energy._kernel import run\n"
                 "from ._own import fine\n"
                 "from isa_mocap_ros.tracking.stages import _own_too\n")
    got = _private_imports(f, tmp_path)
    assert [g.split(": ", 1)[1] for g in got] == ["from isa_mocap_ros.body.kinematics import _hidden",
                                                  "from isa_mocap_ros.energy import _kernel",
                                                  "from isa_mocap_ros.energy._kernel import run"]
