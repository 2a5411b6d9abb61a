"""Replace a converted room's flat mesh emitters by Blender area lights of the same place, size,
orientation and power, as a Blender user lighting a room for a clay render would.

    python demo_scenes/interiors/emitters_to_area_lights.py IN.blend OUT.blend   (needs bpy)

Why: the view layer's Material Override (the clay render of architecture) replaces every
material, an emitter's too, so a room lit by mesh emitters goes black in clay; lights are
not materials and keep shining.  An emitter here is a mesh object whose material's output is
an Emission shader (what ``shared/tools/mitsuba_to_blend.py`` makes of a Mitsuba area
emitter), with all its faces in one plane: a disk (many faces round a centre) becomes a DISK
light, a quad a RECTANGLE one.  The light emits on the side of the faces' normal (Mitsuba's
area emitters are one-sided; the converter's mesh emitters glowed on both sides in Cycles, the
``--one-sided-emitters`` caveat of its docstring), with radiance ``L`` = the Emission color times
its strength, so its power is ``P = pi A L`` [W] (a Lambertian emitter of area ``A``; Blender's
area light has radiance ``P / (pi A)``).  Non-planar emitters are left as they are, with a line
saying so.
"""
import math
import sys

import bpy
import mathutils
import numpy as np


def emission_radiance(mat):
    """(3,) Emission color times strength of ``mat``'s output shader, or None if it is not an
    Emission shader with unlinked inputs."""
    if mat is None or not mat.use_nodes:
        return None
    out = next((n for n in mat.node_tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None)
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    node = out.inputs["Surface"].links[0].from_node
    if node.type != "EMISSION" or node.inputs["Color"].is_linked or node.inputs["Strength"].is_linked:
        return None
    return np.array(node.inputs["Color"].default_value[:3]) * float(node.inputs["Strength"].default_value)


def convert(ob):
    """Add the area light that replaces ``ob`` and remove ``ob``; returns a line of what was done."""
    M = np.array(ob.matrix_world)
    v = np.array([M[:3, :3] @ np.array(x.co) + M[:3, 3] for x in ob.data.vertices])
    normals = np.array([M[:3, :3] @ np.array(p.normal) for p in ob.data.polygons])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    n = normals.mean(axis=0)
    n /= np.linalg.norm(n)
    if np.abs((v - v.mean(axis=0)) @ n).max() > 1e-4 * np.ptp(v, axis=0).max() or (normals @ n).min() < 0.9999:
        return f"{ob.name}: not flat, left as a mesh emitter"
    radiance = emission_radiance(ob.active_material)
    light = bpy.data.lights.new(ob.name + " light", "AREA")
    if len(ob.data.polygons) == 1 and len(v) == 4:
        e1, e2 = v[1] - v[0], v[3] - v[0]
        light.shape, light.size, light.size_y = "RECTANGLE", float(np.linalg.norm(e1)), float(np.linalg.norm(e2))
        x = e1 / np.linalg.norm(e1)
        area = float(np.linalg.norm(np.cross(e1, e2)))
    else:
        area = float(sum(p.area for p in ob.data.polygons)) * abs(np.linalg.det(M[:3, :3])) ** (2 / 3)
        light.shape, light.size = "DISK", 2.0 * math.sqrt(area / math.pi)
        x = v[0] - v.mean(axis=0)
        x = x - (x @ n) * n
        x /= np.linalg.norm(x)
        area = math.pi * (light.size / 2) ** 2
    z = -n                                     # an area light emits along its local -Z
    y = np.cross(z, x)
    peak = float(radiance.max())
    light.color = tuple(radiance / peak) if peak > 0 else (1.0, 1.0, 1.0)
    light.energy = math.pi * area * peak
    lob = bpy.data.objects.new(ob.name + " light", light)
    mw = np.eye(4)
    mw[:3, :3], mw[:3, 3] = np.column_stack([x, y, z]), v.mean(axis=0)
    lob.matrix_world = mathutils.Matrix(mw.tolist())
    for coll in ob.users_collection:
        coll.objects.link(lob)
    bpy.data.objects.remove(ob)
    size = f"{light.size:.3f} m across" if light.shape == "DISK" else f"{light.size:.3f} x {light.size_y:.3f} m"
    return (f"{lob.name}: {light.shape.lower()} {size}, "
            f"{light.energy:.2f} W, normal {np.round(n, 3).tolist()}")


def main(argv):
    src, dst = argv
    bpy.ops.wm.open_mainfile(filepath=src)
    emitters = [ob for ob in bpy.data.objects if ob.type == "MESH" and emission_radiance(ob.active_material) is not None
                and len(ob.material_slots) == 1]
    for ob in emitters:
        print(convert(ob))
    bpy.ops.wm.save_as_mainfile(filepath=dst, compress=True)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
