"""The layer rule of the five packages, checked on their source: ``python tools/check_layers.py``.

The layers, lowest first: ``wmm_qp`` (computation) ← ``wmm_qp_robot`` (the robot side every robot
shares: hardware interface, referees, lease gate, shaper) ← ``wmm_qp_sim`` (the simulated robot) ←
``wmm_qp_service`` (processes, transport, the runtime's CLI) ← ``wmm_qp_tools`` (bench,
experiments, drills, the contract kit); an arrow reads "may be imported by". A module may import
its own package and the packages below it, never one above: so no cycle can close between the
packages either. Transport stays at the edge: ``zenoh`` is imported by the service and the tools
only, ROS 2 (``rclpy`` and its message packages) by their ``ros2`` packages only, and of those
only the stand-in robot (``wmm_qp_service.ros2.sim_robot``) imports the sim.

Inside and across the packages, no circle may close between files: module A importing B at load
time while B (directly or through others) imports A. Counted here: the imports a module runs when
it is loaded (module level, in a module-level ``if``/``try``; not under ``if TYPE_CHECKING:``,
not inside functions), each to the module it names — ``from pkg import name`` to the submodule
``pkg.name`` when there is one, else to ``pkg``'s ``__init__`` (so an ``__init__`` that re-exports
its submodules closes a circle with any of them that imports a name from the package).

Every import counts wherever it is written: at module level, inside a function or a class,
under ``if TYPE_CHECKING:``, in a ``try``, and ``importlib.import_module("...")`` or
``__import__("...")`` with a literal name. Each breach is one line ``path:line: what``; the
exit code is 0 when there is none, 1 when there is one (or a file does not parse), 2 for bad
usage.

Usage:
    python tools/check_layers.py [--root DIR]
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

LAYERS: tuple[tuple[str, str], ...] = (
    ("wmm_qp", "wmm_qp"),
    ("wmm_qp_robot", "robot/wmm_qp_robot"),
    ("wmm_qp_sim", "sim/wmm_qp_sim"),
    ("wmm_qp_service", "service/wmm_qp_service"),
    ("wmm_qp_tools", "tools/wmm_qp_tools"),
)
"""(package, its folder under the repository root), lowest layer first."""
RANK = {name: i for i, (name, _) in enumerate(LAYERS)}
EDGE_ONLY = {"zenoh": ("wmm_qp_service", "wmm_qp_tools")}
"""Third-party packages only the named layers (the service and the tools above it) may import."""
NOT_THE_SIM = ("wmm_qp_service.drivers.", "wmm_qp_service.drivers.sim_node")
"""A real robot's driver (a module under the prefix, but the sim's own node) never imports the sim:
what it shares with the sim (referees, lease gate, shaper) is ``wmm_qp_robot``'s."""
NOT_THE_SIM_ROS2 = ("wmm_qp_service.ros2.", "wmm_qp_service.ros2.sim_robot")
"""The same for the ROS 2 package: only its stand-in robot (``wmm-qp sim --ros2``) drives the sim."""
ROS2 = ("rclpy", "rosidl_runtime_py", "builtin_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs",
        "nav_msgs", "diagnostic_msgs", "visualization_msgs", "std_srvs")
"""ROS 2's client library and messages: imported only by a ``ros2`` package of the service or the
tools (``wmm_qp_service.ros2``), so every other module loads without a ROS 2 installation."""
RULE = " ← ".join(name for name, _ in LAYERS)


@dataclass(frozen=True)
class Import:
    """One import statement's target.

    Attributes:
        module: the absolute dotted name imported (``from a.b import c`` → ``a.b``; only its top
            package counts).
        node: the statement (or the call).
    """

    module: str
    node: ast.stmt | ast.expr

    @property
    def line(self) -> int:
        """Its line in the file."""
        return self.node.lineno

    @property
    def text(self) -> str:
        """The statement as the message shows it."""
        return ast.unparse(self.node)


def _module_name(path: Path, pkg_dir: Path, pkg: str) -> tuple[str, bool]:
    """The dotted module name of ``path`` inside ``pkg`` and whether it is a package's ``__init__``."""
    rel = path.relative_to(pkg_dir).with_suffix("")
    parts = [pkg, *rel.parts]
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), True
    return ".".join(parts), False


def _resolve(module: str | None, level: int, here: str, is_pkg: bool) -> str:
    """The absolute name of a (possibly relative) ``from`` import written in module ``here``."""
    if level == 0:
        return module or ""
    base = here.split(".") if is_pkg else here.split(".")[:-1]
    base = base[: len(base) - (level - 1)] if level > 1 else base
    return ".".join([*base, module] if module else base)


def imports_of(tree: ast.AST, here: str, is_pkg: bool) -> Iterator[Import]:
    """Every import in a parsed module, at any depth (functions, classes, conditionals)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield Import(alias.name, node)
        elif isinstance(node, ast.ImportFrom):
            yield Import(_resolve(node.module, node.level, here, is_pkg), node)
        elif isinstance(node, ast.Call) and node.args:
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            arg = node.args[0]
            if (name in ("import_module", "__import__") and isinstance(arg, ast.Constant)
                    and isinstance(arg.value, str) and not arg.value.startswith(".")):
                yield Import(arg.value, node)


def breaches(root: Path) -> tuple[list[str], int, int]:
    """Check every module of the five packages under ``root``.

    Returns:
        the breaches (one line each, ``path:line: what``), the files read and the imports
        between the packages seen.
    """
    out: list[str] = []
    files = between = 0
    for pkg, folder in LAYERS:
        pkg_dir = root / folder
        for path in sorted(pkg_dir.rglob("*.py")):
            files += 1
            rel = path.relative_to(root)
            source = path.read_text(encoding="utf-8")
            try:
                tree = ast.parse(source, filename=str(path))
            except SyntaxError as e:
                out.append(f"{rel}:{e.lineno}: does not parse ({e.msg}): its imports cannot be checked")
                continue
            here, is_pkg = _module_name(path, pkg_dir, pkg)
            for imp in imports_of(tree, here, is_pkg):
                top = imp.module.split(".")[0]
                if top in RANK and top != pkg:
                    between += 1
                    if RANK[top] > RANK[pkg]:
                        out.append(f"{rel}:{imp.line}: {pkg} imports {top} ({imp.text!r}): a layer may import "
                                   f"only the ones below it ({RULE}; an arrow: may be imported by)")
                if top in ROS2 and not (pkg in ("wmm_qp_service", "wmm_qp_tools")
                                        and (here == f"{pkg}.ros2" or here.startswith(f"{pkg}.ros2."))):
                    out.append(f"{rel}:{imp.line}: {here} imports {top} ({imp.text!r}): ROS 2 is imported only "
                               "in wmm_qp_service.ros2 (and wmm_qp_tools.ros2)")
                if top == "wmm_qp_sim" and any(here.startswith(a) and not here.startswith(b)
                                               for a, b in (NOT_THE_SIM, NOT_THE_SIM_ROS2)):
                    out.append(f"{rel}:{imp.line}: the driver {here} imports the sim ({imp.text!r}): a real robot's "
                               "driver shares only wmm_qp_robot with it")
                elif top in EDGE_ONLY and pkg not in EDGE_ONLY[top]:
                    out.append(f"{rel}:{imp.line}: {pkg} imports {top} ({imp.text!r}): transport stays at the "
                               f"edge, only {' and '.join(EDGE_ONLY[top])} may import {top}")
    return out, files, between


def _load_time_imports(body: list[ast.stmt]) -> Iterator[ast.Import | ast.ImportFrom]:
    """The import statements a module runs when loaded (``TYPE_CHECKING`` blocks and functions skipped)."""
    for node in body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif isinstance(node, ast.If):
            test = node.test
            if "TYPE_CHECKING" not in ast.unparse(test):
                yield from _load_time_imports(node.body)
            yield from _load_time_imports(node.orelse)
        elif isinstance(node, ast.Try):
            for block in (node.body, *(h.body for h in node.handlers), node.orelse, node.finalbody):
                yield from _load_time_imports(block)


def circles(root: Path) -> list[str]:
    """Every circle of load-time imports between the packages' files, one line each (its modules)."""
    modules: dict[str, tuple[Path, bool]] = {}
    for pkg, folder in LAYERS:
        for path in sorted((root / folder).rglob("*.py")):
            name, is_pkg = _module_name(path, root / folder, pkg)
            modules[name] = (path, is_pkg)
    edges: dict[str, list[str]] = {}
    for name, (path, is_pkg) in modules.items():
        try:
            tree = ast.parse(path.read_text(encoding="utf-8"))
        except SyntaxError:
            continue  # breaches() reports it
        out: list[str] = []
        for node in _load_time_imports(tree.body):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = _resolve(node.module, node.level, name, is_pkg)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            out += [t for t in targets if t in modules and t != name]
        edges[name] = out
    # Tarjan's strongly connected components, iteratively
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[str] = []
    for start in modules:
        if start in index:
            continue
        work = [(start, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = len(index)
                stack.append(v)
                on_stack.add(v)
            if i < len(edges[v]):
                work.append((v, i + 1))
                w = edges[v][i]
                if w not in index:
                    work.append((w, 0))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    found.append("import circle: " + " → ".join(sorted(comp)))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return found


def main(argv: list[str] | None = None) -> int:
    """Print each breach of the layer rule; 0: none, 1: some, 2: bad usage."""
    p = argparse.ArgumentParser(prog="check_layers.py", description=__doc__.split("\n")[0])
    p.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent,
                   help="the repository root (default: this script's repository)")
    args = p.parse_args(argv)
    missing = [folder for _, folder in LAYERS if not (args.root / folder).is_dir()]
    if missing:
        print(f"check_layers.py: error: --root {args.root}: no folder {', '.join(missing)} "
              f"(give the repository root, which holds {', '.join(f for _, f in LAYERS)})", file=sys.stderr)
        return 2
    found, files, between = breaches(args.root)
    loops = circles(args.root)
    for line in found + loops:
        print(line)
    if found:
        print(f"layers: FAIL: {len(found)} import(s) break {RULE} ({files} files)")
    if loops:
        print(f"layers: FAIL: {len(loops)} import circle(s) between files")
    if found or loops:
        return 1
    print(f"layers: OK: {files} files, {between} imports between the packages, each one downward ({RULE}); "
          "no import circle between files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
