#!/usr/bin/env python3
"""The shape of a package, from its code: modules and lines, the longest functions, the import
graph inside the package, its longest chain and its cycles.

    python tools/package_map.py [core/raybundle] [--top 10]

Imports anywhere in a module count (inside functions too: they are dependencies all the same),
``from . import x`` as ``x``. A cycle is a strongly connected set of modules; the longest chain
is the longest path of the graph with each cycle taken as one node.
"""
from __future__ import annotations

import argparse
import ast
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def modules(pkg: pathlib.Path) -> dict[str, pathlib.Path]:
    """Dotted module name (relative to the package's parent) -> file."""
    return {".".join(p.relative_to(pkg.parent).with_suffix("").parts).removesuffix(".__init__"): p
            for p in sorted(pkg.rglob("*.py")) if "__pycache__" not in p.parts}


def imports(name: str, path: pathlib.Path, known: set[str]) -> set[str]:
    """The package's modules that ``name`` imports."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    out = set()
    for node in ast.walk(tree):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                mod = ".".join(base[:len(base) - node.level + 1] + ([mod] if mod else []))
            subs = [f"{mod}.{a.name}" for a in node.names]
            # `from pkg import module` depends on the module, not on pkg/__init__
            targets = [s for s in subs if s in known] or [mod]
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's components, each as a sorted list."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
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
            out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def longest_chain(graph: dict[str, set[str]], comps: list[list[str]]) -> list[str]:
    """The longest import path, with every cycle contracted to one node (named by its members)."""
    of = {v: i for i, c in enumerate(comps) for v in c}
    dag = {i: {of[w] for v in c for w in graph[v]} - {i} for i, c in enumerate(comps)}
    memo: dict[int, list[int]] = {}

    def walk(i):
        if i not in memo:
            memo[i] = [i] + max((walk(j) for j in sorted(dag[i])), key=len, default=[])
        return memo[i]

    best = max((walk(i) for i in sorted(dag)), key=len, default=[])
    return ["{" + ", ".join(comps[i]) + "}" if len(comps[i]) > 1 else comps[i][0] for i in best]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("package", nargs="?", default=str(ROOT / "core" / "raybundle"))
    ap.add_argument("--top", type=int, default=10, help="how many of the longest functions")
    a = ap.parse_args(argv)
    pkg = pathlib.Path(a.package).resolve()
    mods = modules(pkg)
    graph = {m: imports(m, p, set(mods)) for m, p in mods.items()}
    lines = {m: len(p.read_text(encoding="utf-8").splitlines()) for m, p in mods.items()}
    print(f"{len(mods)} modules, {sum(lines.values()):,} lines")
    for m in sorted(mods, key=lambda m: -lines[m]):
        print(f"  {lines[m]:6,}  {m}")
    funcs = []

    def collect(node, m, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                funcs.append((child.end_lineno - child.lineno + 1, f"{m}:{prefix}{child.name} (line {child.lineno})"))
                collect(child, m, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                collect(child, m, f"{prefix}{child.name}.")
            else:
                collect(child, m, prefix)

    for m, p in mods.items():
        collect(ast.parse(p.read_text(encoding="utf-8")), m, "")
    print(f"the {a.top} longest functions:")
    for n, f in sorted(funcs, reverse=True)[:a.top]:
        print(f"  {n:5}  {f}")
    comps = strongly_connected(graph)
    cycles = [c for c in comps if len(c) > 1]
    chain = longest_chain(graph, comps)
    print(f"longest import chain ({len(chain)} modules): {' -> '.join(chain)}")
    print(f"import cycles: {len(cycles)}" + "".join(f"\n  {' <-> '.join(c)}" for c in cycles))
    return 0


if __name__ == "__main__":
    sys.exit(main())
