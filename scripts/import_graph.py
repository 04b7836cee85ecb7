"""The import graph of `service` and `clients`, drawn from the source with `ast`.

Why: issue 16 asks for no import cycles (TYPE_CHECKING imports included) and no import from
the core up into a surface. Reading the imports from the text (not importing anything) sees
every edge, lazy ones inside functions and type-only ones alike, so the check cannot be fooled
by an import that only runs on some path.

    python scripts/import_graph.py            # cycles, layer violations, figures; exit 1 if any
    python scripts/import_graph.py --edges    # every edge, one a line

Layers, lowest first: a module may import its own layer and the ones below it, never above.
Checked: `service`, `clients`, `bench` and the ROS node's `armfleet_ros` (packaging/armfleet-ros);
and nothing outside `clients` imports the client's private modules (`clients._*`).
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# (folder the package is imported from, package): the ROS node's package is imported from its
# colcon/pip project folder, the rest from the repository's root.
PACKAGES: tuple[tuple[str, str], ...] = (
    ("", "service"),
    ("", "clients"),
    ("", "bench"),
    ("packaging/armfleet-ros", "armfleet_ros"),
)

# (prefix, rank): the longest matching prefix decides a module's layer.
LAYERS: tuple[tuple[str, int], ...] = (
    # the client library: under everything (the core reads its wire and ROS rules); its apps
    # and test harness import only the library, and the CLI starts the apps
    ("clients", -2),
    ("clients.apps", -1),
    ("clients.testing", -1),
    ("service.core", 0),  # errors: under every room
    # the rooms of the core, lowest first (service/core/__init__.py says what each holds)
    ("service.core.process", 1),
    ("service.core.sim", 2),
    ("service.core.kinematics", 3),
    ("service.core.access", 4),
    ("service.core.streams", 5),
    ("service.core.commands", 6),
    ("service.core.cameras", 7),
    ("service.core.contract", 8),
    ("service.core.metrics", 9),
    ("service.core.surface", 10),
    ("service.engines", 11),
    ("service.persistence", 12),
    ("service.surfaces", 13),
    # the app: everything else under service/ (api/, app, runtime, serving, cli), so that a
    # module added at the top is above every layer, never below one
    ("service", 14),
    # the bench: beside the app (`armfleet bench` runs it; it drives the service's parts)
    ("bench", 14),
    # the ROS node, on top: it imports only the client library, and nothing imports it
    ("armfleet_ros", 15),
)
# What the client library keeps to itself: nothing outside `clients` imports these.
PRIVATE = "clients._"


def module_name(path: Path, base: Path = ROOT) -> str:
    """`service/core/sim/loop.py` -> `service.core.sim.loop`; a package's `__init__` is the
    package; `base`: the folder the package is imported from."""
    parts = list(path.relative_to(base).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def discover() -> dict[str, Path]:
    """Every module of the packages, by dotted name."""
    found: dict[str, Path] = {}
    for folder, pkg in PACKAGES:
        base = ROOT / folder
        for path in sorted((base / pkg).rglob("*.py")):
            found[module_name(path, base)] = path
    return found


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The module a dotted name lands in: itself, or its nearest enclosing package/module."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def imports_of(mod: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The project modules `mod` imports, anywhere in its text."""
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join([*base, node.module] if node.module else base)
            else:
                prefix = node.module or ""
            # `from pkg import sub` names the submodule when one exists, else the package.
            targets = [
                f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in modules else prefix
                for a in node.names
            ]
        for t in targets:
            hit = _resolve(t, modules)
            if hit and hit != mod:
                out.add(hit)
    return out


def graph() -> dict[str, set[str]]:
    modules = discover()
    return {m: imports_of(m, p, modules) for m, p in modules.items()}


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = 0

    def visit(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
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

    sys.setrecursionlimit(10000)
    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def layer(mod: str) -> int | None:
    best: tuple[int, int] | None = None
    for prefix, rank in LAYERS:
        if (mod == prefix or mod.startswith(prefix + ".")) and (
            best is None or len(prefix) > best[0]
        ):
            best = (len(prefix), rank)
    return None if best is None else best[1]


def upward(g: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Edges from a lower layer into a higher one (e.g. core -> surfaces)."""
    bad = []
    for src, dsts in g.items():
        ls = layer(src)
        for dst in dsts:
            ld = layer(dst)
            if ls is not None and ld is not None and ld > ls:
                bad.append((src, dst))
    return sorted(bad)


def private(g: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Edges from outside the client library into its private modules (`clients._*`): the
    library's public face is what others may use (issue 37)."""
    return sorted(
        (src, dst)
        for src, dsts in g.items()
        if not (src == "clients" or src.startswith("clients."))
        for dst in dsts
        if dst.startswith(PRIVATE)
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--edges", action="store_true", help="print every edge")
    args = ap.parse_args()
    g = graph()
    if args.edges:
        for src in sorted(g):
            for dst in sorted(g[src]):
                print(f"{src} -> {dst}")
        return 0
    cyc = cycles(g)
    up = upward(g)
    for comp in cyc:
        print("cycle: " + " <-> ".join(comp))
    hidden = private(g)
    for src, dst in up:
        print(f"upward: {src} -> {dst}")
    for src, dst in hidden:
        print(f"private: {src} -> {dst}")
    print(
        f"{len(g)} modules, {sum(map(len, g.values()))} edges, {len(cyc)} cycles, {len(up)} upward"
        f", {len(hidden)} into the client's private modules"
    )
    return 1 if cyc or up or hidden else 0


if __name__ == "__main__":
    sys.exit(main())
