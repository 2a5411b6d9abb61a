"""Bake material inputs' node graphs with Cycles (run in a process of its own).

Usage (by :mod:`raybundle_addon.translation.node_graphs`, never imported by the add-on)::

    python material_bake.py LIBRARY.blend JOB.json THREADS
    blender -b --factory-startup --python material_bake.py -- LIBRARY.blend JOB.json THREADS

``JOB.json`` lists tasks, each ``{"material", "node", "socket", "size": [W, H], "uv_maps",
"images": {image node name: .npy}, "out": .npy}``.  For each task the material is loaded
from ``LIBRARY.blend`` and copied; in the copy the graph that drives input ``socket`` of node
``node`` is rewired into an Emission shader (strength 1) that is the only surface output (a
value input through a Math node, so that a color is converted to a value as the input does; a
normal input, a vector in [-1, 1], as ``(n + 1) / 2``),
every Image Texture node reads the linear RGBA pixels of its ``.npy`` (H, W, 4) with the
node's own interpolation, and Cycles bakes the emission (``EMIT``, one sample per texel, no
margin) of a unit square whose UV maps (``uv_maps``, and the default one) cover [0, 1]^2 once,
into a W x H float image: texel (i, j) is the graph's value at UV ((i + 0.5) / W, (j + 0.5) / H)
(where W, H are the image's own, every image is read at its own texel there).
A task with an ``"object"`` (its name in the library) bakes on that object instead, every face
of it with the rewired material, through its UV map ``uv_maps[0]``, its islands extended by
``"margin"`` texels.  Its (H, W, 3) linear RGB goes to ``out``
(row 0 at the bottom, as ``Image.pixels``).
"""
import json
import os
import sys


def main(argv):
    if hasattr(os, "nice"):         # below the caller, who goes on meanwhile
        os.nice(10)
    import bpy
    import numpy as np

    library, job, threads = argv[0], argv[1], int(argv[2])
    with open(job) as f:
        tasks = json.load(f)["tasks"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with bpy.data.libraries.load(library, link=False) as (src, dst):
        dst.materials = sorted({t["material"] for t in tasks})
        dst.objects = sorted({t["object"] for t in tasks if t.get("object")})
    sc = bpy.context.scene
    r = sc.render
    r.engine = "CYCLES"
    if threads > 0:
        r.threads_mode, r.threads = "FIXED", threads
    sc.cycles.device = "CPU"
    sc.cycles.samples = 1
    sc.render.bake.margin = 0
    images = {}
    for task in tasks:
        mat, target = _emitting_copy(task, images)
        ob = _baked_object(sc, task, mat)
        for other in sc.objects:
            other.select_set(other is ob)
        bpy.context.view_layer.objects.active = ob
        bpy.ops.object.bake(type="EMIT", margin=int(task.get("margin", 0)), use_clear=True, target="IMAGE_TEXTURES")
        w, h = task["size"]
        px = np.empty(w * h * 4, np.float32)
        target.pixels.foreach_get(px)
        np.save(task["out"], px.reshape(h, w, 4)[..., :3])
        sc.collection.objects.unlink(ob)


def _emitting_copy(task, images):
    """``(material, image)``: a copy of the task's material whose only output is an Emission of
    the graph on the task's input (a value as gray, a normal as (n + 1) / 2), and the float image
    it bakes into, active; its image textures hold the task's pixels (``images``: path -> image,
    loaded once)."""
    import bpy
    import numpy as np

    mat = bpy.data.materials[task["material"]].copy()
    nt = mat.node_tree
    sock = next(s for s in nt.nodes[task["node"]].inputs if s.identifier == task["socket"])
    source = sock.links[0].from_socket
    for node in nt.nodes:
        if node.type == "TEX_IMAGE" and node.name in task["images"]:
            path = task["images"][node.name]
            if path not in images:
                px = np.load(path)
                im = bpy.data.images.new(os.path.basename(path), px.shape[1], px.shape[0], alpha=True,
                                         float_buffer=True)
                im.alpha_mode = "STRAIGHT"
                im.pixels.foreach_set(np.ascontiguousarray(px, np.float32).ravel())
                images[path] = im
            node.image = images[path]
    for node in [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]:
        nt.nodes.remove(node)
    emission = nt.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    if sock.type == "VALUE":            # a color linked to a value input is converted there (to gray)
        value = nt.nodes.new("ShaderNodeMath")
        value.operation = "ADD"
        value.inputs[1].default_value = 0.0
        nt.links.new(source, value.inputs[0])
        source = value.outputs[0]
    elif sock.type == "VECTOR":         # a normal (x, y, z) in [-1, 1]: baked as (n + 1) / 2
        half = nt.nodes.new("ShaderNodeVectorMath")
        half.operation = "MULTIPLY_ADD"
        half.inputs[1].default_value = half.inputs[2].default_value = (0.5, 0.5, 0.5)
        nt.links.new(source, half.inputs[0])
        source = half.outputs[0]
    nt.links.new(source, emission.inputs["Color"])
    output = nt.nodes.new("ShaderNodeOutputMaterial")
    output.is_active_output = True
    nt.links.new(emission.outputs[0], output.inputs["Surface"])
    w, h = task["size"]
    target = bpy.data.images.new("bake", w, h, alpha=False, float_buffer=True)
    node = nt.nodes.new("ShaderNodeTexImage")
    node.image = target
    nt.nodes.active = node
    return mat, target


def _baked_object(sc, task, mat):
    """The object the task bakes on, linked into scene ``sc`` with material ``mat``: the task's
    object with its UV map active, or a unit square whose UV maps cover [0, 1]^2 once."""
    import bpy
    import numpy as np

    if task.get("object"):
        ob = bpy.data.objects[task["object"]]
        if ob.name not in sc.collection.objects:
            sc.collection.objects.link(ob)
        ob.hide_viewport = ob.hide_render = ob.hide_select = False
        if len(ob.material_slots):
            for slot in ob.material_slots:
                slot.material = mat
        else:
            ob.data.materials.append(mat)
        ob.data.uv_layers.active = ob.data.uv_layers[task["uv_maps"][0]]
        return ob
    me = bpy.data.meshes.new("unit square")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [], [(0, 1, 2, 3)])
    corners = np.array([0, 0, 1, 0, 1, 1, 0, 1], np.float32)
    for name in ["UVMap", *task["uv_maps"]]:
        if name and name not in me.uv_layers:
            me.uv_layers.new(name=name).uv.foreach_set("vector", corners)
    me.materials.append(mat)
    ob = bpy.data.objects.new("unit square", me)
    sc.collection.objects.link(ob)
    return ob

if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(args)
