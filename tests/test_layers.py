"""The code's structure, checked (``tools/package_map.py`` reads it): the core's subpackages are
layers in the order of the module map in docs/method.md, which lists every module; no import
cycle between modules; no module imports another's private names."""
import ast
import pathlib
import re
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

from package_map import imports, modules, strongly_connected  # noqa: E402

CORE, ADDON = ROOT / "core" / "raybundle", ROOT / "raybundle_addon"


def module_map():
    """[(subpackage, {module names})] in the order of the table under docs/method.md's "Code layout"."""
    text = (ROOT / "docs" / "method.md").read_text().split("## Code layout", 1)[1]
    return [(sub, set(re.findall(r"`(\w+)`", cell)))
            for sub, cell in re.findall(r"^\| `raybundle\.(\w+)` \| (.*) \|$", text, re.M)]


def graph(pkg):
    mods = modules(pkg)
    return mods, {m: imports(m, p, set(mods)) for m, p in mods.items()}


def test_the_module_map_lists_every_module_of_every_subpackage():
    table = module_map()
    subs = sorted(p.name for p in CORE.iterdir() if (p / "__init__.py").exists())
    assert sorted(s for s, _ in table) == subs
    for sub, listed in table:
        actual = {p.stem for p in (CORE / sub).glob("*.py") if p.stem != "__init__"}
        assert listed == actual, (sub, sorted(actual - listed), sorted(listed - actual))


def test_each_subpackage_imports_only_from_itself_and_the_layers_before_it():
    order = [s for s, _ in module_map()]
    _, g = graph(CORE)

    def layer(m):
        """The package itself (its version) lies under every layer, ``__main__`` over them."""
        parts = m.split(".")
        if len(parts) == 1:
            return -1
        return order.index(parts[1]) if parts[1] in order else len(order)

    upward = sorted(f"{m} -> {d}" for m, deps in g.items() for d in deps
                    if len(m.split(".")) > 1 and layer(d) > layer(m))
    assert upward == []


@pytest.mark.parametrize("pkg", [CORE, ADDON], ids=["core", "add-on"])
def test_no_import_cycle_between_modules(pkg):
    _, g = graph(pkg)
    assert [c for c in strongly_connected(g) if len(c) > 1] == []


@pytest.mark.parametrize("pkg", [CORE, ADDON], ids=["core", "add-on"])
def test_no_module_imports_another_modules_private_names(pkg):
    private = []
    for m, path in modules(pkg).items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                private += [f"{m}: {node.module}.{a.name}" for a in node.names
                            if a.name.startswith("_") and not a.name.startswith("__")]
    assert private == []


#: no module over this many lines and no function over that many, in the core and the add-on
MODULE_LINES, FUNCTION_LINES = 600, 80


def lengths():
    """{"path" or "path:Class.function": lines} of every module and function in the core and the add-on."""
    out = {}
    for pkg in (CORE, ADDON):
        for m, path in modules(pkg).items():
            text = path.read_text(encoding="utf-8")
            name = path.relative_to(ROOT).as_posix()
            out[name] = len(text.splitlines())

            def walk(node, prefix):
                for child in ast.iter_child_nodes(node):
                    if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        out[f"{name}:{prefix}{child.name}"] = child.end_lineno - child.lineno + 1
                        walk(child, f"{prefix}{child.name}.")
                    elif isinstance(child, ast.ClassDef):
                        walk(child, f"{prefix}{child.name}.")
                    else:
                        walk(child, prefix)

            walk(ast.parse(text), "")
    return out


def test_no_module_or_function_is_over_its_length():
    """No module over :data:`MODULE_LINES` lines and no function over :data:`FUNCTION_LINES`
    (docstrings included) in the core and the add-on."""
    got = lengths()
    assert {k: n for k, n in got.items() if n > (FUNCTION_LINES if ":" in k else MODULE_LINES)} == {}


def test_patch_methods_share_an_abstract_base_and_none_inherits_another():
    """Every patch method derives from the abstract ``PatchSolution`` directly, not from another
    method (they once inherited the concrete bundle iteration)."""
    from raybundle.methods.patch_solution import PatchSolution
    from raybundle.methods.registry import SOLVERS

    patch = [cls for cls in SOLVERS.values() if not cls.image_only]
    assert len(patch) == 4 and all(PatchSolution in cls.__bases__ for cls in patch)
    assert PatchSolution.__abstractmethods__ == frozenset({"step"})
    # each declares what it is itself, nothing inherited from another method
    assert {c.name: (c.__dict__["iterates"], c.__dict__["merges_chains"]) for c in patch} == {
        "stochastic-iteration": (True, True), "ray-bundle-walk": (True, True), "radiosity": (False, True),
        "point-collocation": (True, False)}


def test_every_method_is_made_the_same_way():
    """One constructor convention for every method in the registry (they once had two)."""
    import inspect

    from raybundle.methods.registry import SOLVERS

    got = {name: list(inspect.signature(cls.__init__).parameters) for name, cls in SOLVERS.items()}
    assert got == {name: ["self", "scene", "tracer", "direct", "settings", "camera"] for name in SOLVERS}


def test_the_add_ons_translation_imports_nothing_of_its_interface():
    """``raybundle_addon.translation`` (Blender's data into the core's scene) sits under the
    add-on's interface (settings, panels, operators, render engine, bake job, command line)."""
    _, g = graph(ADDON)
    up = sorted(f"{m} -> {d}" for m, deps in g.items() if m.startswith("raybundle_addon.translation")
                for d in deps if not d.startswith("raybundle_addon.translation"))
    assert up == []
