"""Blender's data walked, not the export's own list: every RNA property of the structs a render
reads (Object, Light of each type, Camera, World, ViewLayer, the render settings, their
``cycles`` groups and the view settings) and every shader node type is classed in
:mod:`blender_walk` as modeled (naming its test), warned (naming its warning, which must stand in
the add-on's source) or irrelevant to the image (with a reason).  A property or node type a
Blender release adds fails here until it is classed.  Runs on the newest Blender and, from
``make test-oldest``, on the oldest (it needs ``bpy`` only)."""
from __future__ import annotations

import glob
import os
import re
import sys
import tempfile

if "bpy" not in sys.modules:
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-blender-user-"))
import bpy  # noqa: E402
import pytest  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blender_walk as walk  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _structs():
    """label -> the set of property names Blender has for it (each light type's together)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if not hasattr(scene, "cycles"):
        import addon_utils

        addon_utils.enable("cycles", default_set=True)
    ob = bpy.data.objects.new("walk", bpy.data.meshes.new("walk"))
    cam = bpy.data.cameras.new("walk")
    world = bpy.data.worlds.new("walk")
    lights = [bpy.data.lights.new(t, t) for t in ("POINT", "SUN", "SPOT", "AREA")]
    layer = scene.view_layers[0]
    found = {"Object": [ob], "Object.cycles": [ob.cycles], "Light": lights, "Light.cycles": [ld.cycles for ld in lights],
             "Camera": [cam], "Camera.dof": [cam.dof], "World": [world], "World.cycles": [world.cycles],
             "ViewLayer": [layer], "ViewLayer.cycles": [layer.cycles], "RenderSettings": [scene.render],
             "Scene.cycles": [scene.cycles], "Scene.view_settings": [scene.view_settings]}
    return {label: {p.identifier for s in items for p in s.bl_rna.properties if p.identifier != "rna_type"}
            for label, items in found.items()}


def _sources(pattern):
    return "\n".join(open(f, encoding="utf-8").read() for f in glob.glob(os.path.join(ROOT, pattern)))


def test_every_render_setting_and_shader_node_of_blender_is_classed():
    structs = _structs()
    nodes = {t for t in dir(bpy.types) if t.startswith("ShaderNode")}
    missing = {label: sorted(names - set(walk.STRUCTS[label])) for label, names in structs.items()}
    missing["nodes"] = sorted(nodes - set(walk.NODES))
    missing = {k: v for k, v in missing.items() if v}
    assert not missing, f"Blender properties or node types not classed in tests/blender_walk.py: {missing}"
    counts = {"M": 0, "W": 0, "I": 0}
    for table, names in [(walk.STRUCTS[label], n) for label, n in structs.items()] + [(walk.NODES, nodes)]:
        for name in names:
            counts[table[name][0]] += 1
    print(f"\nBlender {bpy.app.version_string}: modeled {counts['M']}, warned {counts['W']}, "
          f"irrelevant {counts['I']}")


def test_each_class_names_a_test_or_a_warning_that_exists():
    """A modeled entry names a test that exists; a warned one names words the add-on's warnings
    hold; an irrelevant one gives a reason."""
    tests = {f: open(f, encoding="utf-8").read() for f in glob.glob(os.path.join(ROOT, "tests", "test_*.py"))}
    addon = _sources("raybundle_addon/*.py") + _sources("raybundle_addon/translation/*.py")
    bad = []
    for table in (*walk.STRUCTS.values(), walk.NODES):
        for name, (kind, what) in table.items():
            if kind == "M":
                path, _, test = what.partition("::")
                text = tests.get(os.path.join(ROOT, "tests", path), "")
                if not re.search(rf"^def {re.escape(test)}\(", text, re.M):
                    bad.append((name, what))
            elif kind == "W":
                if what not in addon:
                    bad.append((name, what))
            elif kind != "I" or not what:
                bad.append((name, kind, what))
    assert not bad, bad


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-s"]))
