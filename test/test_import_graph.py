"""The package's import graph: no circles (module level or inside functions), no ``optim`` → ``eval``,
the pure core imports no ROS, and every module imports."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("isa_mocap_ros", "msg_adapters")
ROS_OK = ("isa_mocap_ros.nodes", "isa_mocap_ros.cli", "isa_mocap_ros.bench", "msg_adapters")
ROS_MODULES = ("rclpy", "sensor_msgs", "std_msgs", "geometry_msgs", "visualization_msgs", "diagnostic_msgs",
               "builtin_interfaces", "rosgraph_msgs", "tf2_msgs")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for f in sorted((REPO / pkg).rglob("*.py")):
            parts = list(f.relative_to(REPO).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every module of ours that ``name`` imports anywhere in its file (function-local imports too)."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    got = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                mod = ".".join(base[:len(base) - node.level + 1] + ([mod] if mod else []))
            targets = [f"{mod}.{a.name}" for a in node.names] + [mod]
        else:
            continue
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                got.add(t)
    return got


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    return {m: _imports(m, p, set(mods)) for m, p in mods.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10_000)
    for v in graph:
        if v not in index:
            visit(v)
    return out


def _is_package_edge(a: str, b: str) -> bool:
    """A package's ``__init__`` re-exporting its own submodules, and those submodules reading a sibling
    through the package, is Python's ordinary layout, not a circle between concepts."""
    return b.startswith(a + ".") or a.startswith(b + ".")


def test_no_import_circles():
    g = _graph()
    pruned = {a: {b for b in bs if not _is_package_edge(a, b)} for a, bs in g.items()}
    assert _cycles(pruned) == []


def test_core_does_not_import_eval_cli_bench_or_ros():
    g = _graph()
    for m, deps in g.items():
        if m.startswith(("isa_mocap_ros.optim", "isa_mocap_ros.energy", "isa_mocap_ros.tracking",
                         "isa_mocap_ros.geometry", "isa_mocap_ros.body", "isa_mocap_ros.vision")):
            bad = {d for d in deps if d.startswith(("isa_mocap_ros.eval", "isa_mocap_ros.cli", "isa_mocap_ros.bench",
                                                    "isa_mocap_ros.nodes"))}
            assert not bad, f"{m} imports {sorted(bad)}"
        if m.startswith("msg_adapters"):
            assert not {d for d in deps if d.startswith("isa_mocap_ros")}, m
    for m, p in _modules().items():
        if m.startswith(ROS_OK) or m in ("isa_mocap_ros.launcher",):
            continue
        tree = ast.parse(p.read_text())
        roots = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        roots |= {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and not n.level}
        assert not roots & set(ROS_MODULES), f"{m} imports ROS: {sorted(roots & set(ROS_MODULES))}"


def test_graph_sees_a_circle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(g) == [["a", "b", "c"]]


def test_every_module_imports():
    """All modules import in one fresh interpreter (a static graph misses a module that fails to load)."""
    mods = [m for m in _modules() if not m.endswith("__main__")]
    code = "import importlib\n" + "".join(f"importlib.import_module({m!r})\n" for m in mods)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
