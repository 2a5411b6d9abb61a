"""Export of Blender scenes to the core's arrays (real ``bpy``, evaluated depsgraphs).

Everything here is exact (no rendering): triangle counts, areas, materials,
light units (blender.md §4.4), world, camera, warnings.
"""
import math
import time

import numpy as np
import pytest
from addon_helpers import add_camera, add_light, add_object, addon, box, bpy, fresh, node_material, set_world  # noqa: F401
from cycles_reference import new_with_nodes

from raybundle.scene.model import SceneError


def export(**kw):
    from raybundle_addon.translation.export import export_scene

    return export_scene(bpy.context.evaluated_depsgraph_get(), **kw)


def quad(size=1.0):
    s = size / 2
    return [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0)], [(0, 1, 2, 3)]


def minimal(fresh, world=True):
    """A camera and a dim world so that scenes with only a mesh are valid."""
    add_camera((0, 0, 10))
    if world:
        set_world((1, 1, 1), 0.1)


def object_area(ex, name):
    sc = ex.scene
    k = [o.name for o in ex.objects].index(name)
    return sc.triangle_area[ex.triangle_object[sc.triangle_source] == k].sum()


def test_modifiers_are_applied(fresh):
    minimal(fresh)
    v, f = quad(2.0)
    plane = add_object("plane", v, f)
    arr = plane.modifiers.new("array", "ARRAY")
    arr.count = 3
    arr.relative_offset_displace = (1.0, 0.0, 0.0)
    cv, cf = box((-1, -1, -1), (1, 1, 1))
    cube = add_object("cube", cv, cf, location=(0, 10, 0))
    sub = cube.modifiers.new("subsurf", "SUBSURF")
    sub.levels = sub.render_levels = 1
    ex = export()
    sc = ex.scene
    assert ex.counts["triangles"] == 3 * 2 + 6 * 4 * 2                 # array x3 of a quad, cube subdivided once
    assert object_area(ex, "plane") == pytest.approx(12.0)
    xs = sc.vertices[sc.triangles[ex.triangle_object[sc.triangle_source] == 0]].reshape(-1, 3)[:, 0]
    assert xs.min() == pytest.approx(-1) and xs.max() == pytest.approx(5)
    assert object_area(ex, "cube") < 24.0                                # Catmull-Clark shrinks the cube
    assert np.all(sc.triangle_two_sided)


def test_collection_instances_ngon_and_missing_material(fresh):
    minimal(fresh)
    col = bpy.data.collections.new("parts")                  # not linked to the scene: only instanced
    me = bpy.data.meshes.new("tile")
    v, f = quad(1.0)
    me.from_pydata(v, [], f)
    col.objects.link(bpy.data.objects.new("tile", me))
    for k, scale in enumerate((1.0, 2.0)):
        e = bpy.data.objects.new(f"inst{k}", None)
        e.instance_type, e.instance_collection = "COLLECTION", col
        e.location, e.scale = (5.0 * k, 0, 0), (scale,) * 3
        bpy.context.scene.collection.objects.link(e)
    r = 1.0                                                  # a regular pentagon: one ngon, three triangles
    pent = [(r * math.cos(2 * math.pi * k / 5), r * math.sin(2 * math.pi * k / 5), 3.0) for k in range(5)]
    add_object("pentagon", pent, [tuple(range(5))])
    ex = export()
    sc = ex.scene
    inst = [o for o in ex.objects if o.is_instance]
    assert sorted(o.instancer for o in inst) == ["inst0", "inst1"] and all(o.name == "tile" for o in inst)
    areas = sorted(sc.triangle_area[ex.triangle_object[sc.triangle_source] == k].sum()
                   for k, o in enumerate(ex.objects) if o.is_instance)
    assert areas == pytest.approx([1.0, 4.0])
    assert len(sc.triangles) == 2 + 2 + 3
    assert object_area(ex, "pentagon") == pytest.approx(2.5 * r * r * math.sin(math.radians(72)))
    assert ex.material_names == ["(no material)"]
    assert np.allclose(sc.materials.diffuse[0], 0.8) and sc.materials.glossy_weight[0] == 0


def test_flipped_normals_export_the_same_two_sided_surfaces(fresh):
    minimal(fresh)
    v, f = box((0, 0, 0), (1, 2, 3))
    add_object("a", v, f, [node_material("m")])
    add_object("b", v, [tuple(reversed(q)) for q in f], [node_material("m2")], location=(5, 0, 0))
    ex = export()
    sc = ex.scene
    a, b = (ex.triangle_object[sc.triangle_source] == k for k in (0, 1))
    assert a.sum() == b.sum() == 12
    assert sc.triangle_area[a].sum() == pytest.approx(sc.triangle_area[b].sum()) == pytest.approx(22.0)
    assert np.allclose(sc.triangle_normal[a].sum(0), 0) and np.all(sc.triangle_two_sided)
    assert np.allclose(np.sort(sc.triangle_normal[a] @ [1, 2, 3]), np.sort(-sc.triangle_normal[b] @ [1, 2, 3]))


def test_material_slots_and_hidden_objects(fresh):
    minimal(fresh)
    v, f = box((0, 0, 0), (1, 1, 1))
    ob = add_object("two_mats", v, f, [node_material("red", color=(0.7, 0.1, 0.1)),
                                       node_material("blue", color=(0.1, 0.1, 0.7))])
    ob.data.polygons.foreach_set("material_index", np.array([0, 1, 1, 0, 0, 0], np.int32))
    ob.data.update()
    hidden = add_object("hidden", v, f, location=(3, 0, 0))
    hidden.hide_render = True
    ghost = add_object("ghost", v, f, location=(6, 0, 0))
    for k in ("visible_camera", "visible_diffuse", "visible_glossy", "visible_shadow", "visible_transmission"):
        setattr(ghost, k, False)
    ex = export()
    assert [o.name for o in ex.objects] == ["two_mats"]
    names = np.array(ex.material_names)[ex.scene.triangle_material]
    assert sorted(names.tolist()) == ["blue"] * 4 + ["red"] * 8


@pytest.fixture
def light_scene(fresh):
    add_camera((0, 0, 10))
    v, f = quad(4.0)
    add_object("floor", v, f, [node_material("white")])
    return fresh


def test_light_units(light_scene):
    """Blender's power units (blender.md §4.4) to the core's, exactly."""
    P = 100.0
    add_light("POINT", (1, 2, 3), energy=P, color=(1.0, 0.5, 0.25), shadow_soft_size=0.0)
    add_light("SPOT", (0, 0, 2), (math.radians(30), 0, 0), energy=P, spot_size=math.radians(60), spot_blend=0.2,
              exposure=1.0)
    add_light("SUN", rotation=(math.radians(30), 0, 0), energy=3.0, angle=math.radians(1))
    rect = add_light("AREA", (0, 0, 2), energy=P, shape="RECTANGLE", size=0.5, size_y=0.2)
    rect.scale = (2.0, 2.0, 1.0)
    add_light("AREA", (1, 0, 2), energy=P, shape="DISK", size=0.4)
    ex = export()
    sc = ex.scene
    pl, sun, area = sc.point_lights, sc.sun_lights, sc.area_lights
    assert len(pl) == 2 and len(sun) == 1 and len(area) == 2
    I = P / (4 * math.pi)
    k_point = int(np.argmax(pl.spot_cos_half_angle < -0.5))
    k_spot = 1 - k_point
    assert np.allclose(pl.position[k_point], (1, 2, 3))
    assert np.allclose(pl.intensity[k_point], I * np.array([1.0, 0.5, 0.25]))
    assert np.allclose(pl.intensity[k_spot], 2 * I)                            # exposure 1: x2, cone not renormalised
    assert pl.spot_cos_half_angle[k_spot] == pytest.approx(math.cos(math.radians(30)))
    assert pl.spot_blend[k_spot] == pytest.approx(0.2)
    assert np.allclose(pl.spot_direction[k_spot], (0, math.sin(math.radians(30)), -math.cos(math.radians(30))))
    assert np.allclose(sun.irradiance[0], 3.0) and sun.angle[0] == pytest.approx(math.radians(1))
    assert np.allclose(sun.direction[0], (0, math.sin(math.radians(30)), -math.cos(math.radians(30))))
    k_rect = int(np.argmin(area.shape))
    assert area.area[k_rect] == pytest.approx(1.0 * 0.4)                        # scale 2 on both axes
    assert np.allclose(area.radiance[k_rect], P / (math.pi * 0.4))
    assert np.allclose(area.normal[k_rect], (0, 0, -1))
    assert area.area[1 - k_rect] == pytest.approx(math.pi * 0.2 ** 2)
    assert np.allclose(area.radiance[1 - k_rect], P / (math.pi * math.pi * 0.04))


def test_a_lights_partial_ray_visibility_is_warned(light_scene):
    """Cycles keeps a light with its glossy rays off out of highlights; raybundle does not
    model per-ray-type visibility of lights and says so (before: silently fully visible).
    With neither diffuse nor glossy rays the light is left out."""
    lit = add_light("POINT", (0, 0, 2), energy=10.0)
    lit.name, lit.visible_glossy = "no_highlight", False
    dark = add_light("POINT", (1, 0, 2), energy=10.0)
    dark.visible_diffuse = dark.visible_glossy = False
    ex = export()
    assert len(ex.scene.point_lights) == 1
    said = [w for w in ex.warnings if "ray visibility" in w]
    assert len(said) == 1 and "'no_highlight'" in said[0] and "glossy off" in said[0], ex.warnings


def test_light_temperature_and_unnormalized(light_scene):
    pt = add_light("POINT", (0, 0, 2), energy=10.0, shadow_soft_size=0.5)
    pt.data.normalize = False
    ar = add_light("AREA", (0, 0, 2), energy=10.0, size=0.5)
    ar.data.normalize = False
    tl = add_light("POINT", (0, 0, 3), energy=10.0, shadow_soft_size=0.0)
    tl.data.use_temperature = True
    tl.data.temperature = 3000.0
    ex = export()
    pl, area = ex.scene.point_lights, ex.scene.area_lights
    by_z = {round(float(z), 3): k for k, z in enumerate(pl.position[:, 2])}
    assert np.allclose(pl.intensity[by_z[2.0]], 10.0 / (4 * math.pi) * math.pi * 0.25)   # Cycles: invarea = 1
    assert np.allclose(area.radiance[0], 10.0 / math.pi)
    warm = pl.intensity[by_z[3.0]] / (10.0 / (4 * math.pi))
    assert np.allclose(warm, np.array(tl.data.temperature_color[:3]))
    assert warm[0] > warm[2]                                                # 3000 K is reddish


def shader_tree(mat):
    nt = mat.node_tree
    nt.nodes.clear()
    return nt, nt.nodes.new("ShaderNodeOutputMaterial")


def new_mat(name):
    return new_with_nodes(bpy.data.materials, name)


def test_node_trees_flatten_to_lambert_ggx(fresh):
    from raybundle.scene.materials import MaterialTable

    minimal(fresh)
    mix = new_mat("mix")
    nt, out = shader_tree(mix)
    d, g, m = (nt.nodes.new(t) for t in ("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy", "ShaderNodeMixShader"))
    d.inputs["Color"].default_value = (0.8, 0.6, 0.4, 1)
    g.inputs["Color"].default_value = (1, 1, 1, 1)
    g.inputs["Roughness"].default_value = 0.3
    g.distribution = "GGX"
    m.inputs["Fac"].default_value = 0.25
    nt.links.new(d.outputs[0], m.inputs[1])
    nt.links.new(g.outputs[0], m.inputs[2])
    nt.links.new(m.outputs[0], out.inputs["Surface"])
    glow = new_mat("glow")
    nt, out = shader_tree(glow)
    e, d2, add = (nt.nodes.new(t) for t in ("ShaderNodeEmission", "ShaderNodeBsdfDiffuse", "ShaderNodeAddShader"))
    e.inputs["Color"].default_value = (1.0, 0.5, 0.25, 1)
    e.inputs["Strength"].default_value = 4.0
    d2.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1)
    nt.links.new(e.outputs[0], add.inputs[0])
    nt.links.new(d2.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Surface"])
    hot = node_material("hot", color=(1.5, 0.5, 0.5))                       # albedo > 1
    toon = new_mat("toon")
    toon.diffuse_color = (0.2, 0.4, 0.6, 1)
    nt, out = shader_tree(toon)
    nt.links.new(nt.nodes.new("ShaderNodeBsdfToon").outputs[0], out.inputs["Surface"])
    for k, mat in enumerate((mix, glow, hot, toon)):
        v, f = quad()
        add_object(f"o{k}", v, f, [mat], location=(2 * k, 0, 0))
    ex = export()
    mt = ex.scene.materials
    i = {n: k for k, n in enumerate(mt.names)}
    # the Mix's BRDF is (1 - fac) diffuse + fac glossy, whatever the split into kd, ks, g
    k = i["mix"]
    assert np.allclose(mt.diffuse_reflectance[k], 0.75 * np.array([0.8, 0.6, 0.4]))
    assert np.allclose(mt.glossy_weight[k] * mt.glossy[k], 0.25)
    assert mt.roughness[k] == pytest.approx(0.3)
    assert np.allclose(mt.emission[i["glow"]], [4.0, 2.0, 1.0]) and np.allclose(mt.diffuse[i["glow"]], 0.5)
    assert np.allclose(mt.diffuse[i["hot"]], [1.0, 0.5, 0.5])
    assert np.allclose(mt.diffuse[i["toon"]], [0.2, 0.4, 0.6]) and mt.glossy_weight[i["toon"]] == 0
    w = " | ".join(ex.warnings)
    assert "'hot'" in w and "albedo > 1" in w
    assert sum("'toon'" in x for x in ex.warnings) == 1 and "Toon BSDF" in w and "viewport color" in w
    mt.validate()
    assert isinstance(mt, MaterialTable)


def test_principled_image_texture_and_world(fresh, tmp_path):
    add_camera((0, 0, 10))
    p = node_material("plastic", "principled", color=(0.5, 0.2, 0.1), roughness=0.4)
    bsdf = p.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    bsdf.inputs["Emission Strength"].default_value = 0.5
    bsdf.inputs["Coat Weight"].default_value = 0.3
    tex = node_material("textured")
    img = bpy.data.images.new("checker", 4, 4, float_buffer=True)
    px = np.zeros((16, 4), np.float32)
    px[:, 3] = 1
    px[::2, :3] = (0.2, 0.4, 0.6)
    px[1::2, :3] = (0.6, 0.4, 0.2)
    img.pixels.foreach_set(px.ravel())
    tn = tex.node_tree.nodes.new("ShaderNodeTexImage")
    tn.image = img
    tex.node_tree.links.new(tn.outputs["Color"], tex.node_tree.nodes["Diffuse BSDF"].inputs["Color"])
    for k, mat in enumerate((p, tex)):
        v, f = quad()
        add_object(f"o{k}", v, f, [mat], location=(2 * k, 0, 0))
    w = set_world((0.5, 0.25, 1.0), 2.0)
    ex = export()
    mt = ex.scene.materials
    i = {n: k for k, n in enumerate(mt.names)}
    assert np.allclose(mt.emission[i["plastic"]], 0.5)
    assert np.allclose(mt.diffuse[i["plastic"]], (0.5, 0.2, 0.1)) and mt.roughness[i["plastic"]] == pytest.approx(0.4)
    assert mt.is_glossy[i["plastic"]]                                         # the specular layer
    assert np.allclose(mt.diffuse[i["textured"]], 0.4)                        # the image's mean color
    assert any("coat is ignored" in x for x in ex.warnings)
    assert any("'checker'" in x and "mean color" in x for x in ex.warnings)
    assert ex.scene.world.is_constant and np.allclose(ex.scene.world.image[0, 0], (1.0, 0.5, 2.0))
    bpy.context.scene.world = None
    assert not export().scene.world.emits                       # no world: black
    img.filepath_raw = str(tmp_path / "checker.exr")       # Blender evaluates the world from the saved file
    img.file_format = "OPEN_EXR"
    img.save()
    w.node_tree.nodes.new("ShaderNodeTexEnvironment").image = img
    env = w.node_tree.nodes["Environment Texture"]
    w.node_tree.links.new(env.outputs["Color"], w.node_tree.nodes["Background"].inputs["Color"])
    bpy.context.scene.world = w
    ex = export()
    # a textured world is evaluated by Blender into an image by direction: green is 0.4 x 2
    # everywhere, red and blue change with the direction (the checker's columns)
    world = ex.scene.world
    assert not world.is_constant and world.image.shape[2] == 3
    assert world.mean()[1] == pytest.approx(0.8, rel=1e-3) and np.allclose(world.image[..., 1], 0.8, rtol=1e-3)
    assert world.image[..., 0].min() < 0.5 and world.image[..., 0].max() > 1.1
    assert not any("world" in x for x in ex.warnings), ex.warnings


def test_camera_resolution_border_and_ortho(fresh):
    set_world((1, 1, 1), 0.1)
    v, f = quad()
    add_object("o", v, f)
    cam = add_camera((0, 0, 10), resolution=(80, 60), lens=35)
    r = bpy.context.scene.render
    r.resolution_percentage = 50
    full = export().scene.camera
    assert (full.width, full.height) == (40, 30)
    r.use_border = True
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.13, 0.77, 0.5, 0.93
    ex = export()
    x0, y0, w, h = ex.border
    assert (x0, y0, w, h) == (5, 15, 25, 12)                     # Blender truncates border * size
    crop = ex.scene.camera
    assert (crop.width, crop.height) == (w, h)
    # the cropped camera's pixel (i, j) is the full camera's pixel (x0 + i, (H - y0 - h) + j)
    i, j = np.array([0.5, 10.5, 24.5]), np.array([0.5, 5.5, 11.5])
    assert np.allclose(crop.ray_directions(i, j), full.ray_directions(i + x0, j + (30 - y0 - h)))
    r.use_border = False
    cam.data.type, cam.data.ortho_scale = "ORTHO", 3.0
    o = export().scene.camera
    assert o.orthographic and o.fx == pytest.approx(40 / 3.0)
    cam.data.type = "PANO"
    with pytest.raises(SceneError, match="panoramic"):
        export()


@pytest.mark.parametrize("case", ["no lights", "no meshes", "no camera"])
def test_unrenderable_scenes_raise_one_line_errors(fresh, case):
    v, f = quad()
    if case != "no meshes":
        add_object("o", v, f)
    if case != "no camera":
        add_camera((0, 0, 10))
    if case != "no lights":
        set_world((1, 1, 1), 1.0)
    with pytest.raises(SceneError) as e:
        export()
    msg = str(e.value)
    assert "\n" not in msg
    assert {"no lights": "no lights", "no meshes": "no visible mesh", "no camera": "no camera"}[case] in msg


def test_a_million_triangles_export_in_seconds(fresh):
    """A 1M-triangle grid (one object, built with foreach_set) exports in a few seconds."""
    n = 708                                                   # 707^2 quads = 999 698 triangles
    xs = np.linspace(-1, 1, n, dtype=np.float32)
    X, Y = np.meshgrid(xs, xs)
    co = np.stack([X.ravel(), Y.ravel(), 0.05 * np.sin(7 * X.ravel()) * np.cos(5 * Y.ravel())], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    quads = np.stack([a, a + 1, a + n + 1, a + n], 1).astype(np.int32)
    me = bpy.data.meshes.new("grid")
    me.vertices.add(len(co))
    me.vertices.foreach_set("co", co.ravel())
    me.loops.add(quads.size)
    me.loops.foreach_set("vertex_index", quads.ravel())
    me.polygons.add(len(quads))
    me.polygons.foreach_set("loop_start", np.arange(0, quads.size, 4, dtype=np.int32))
    me.update()
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("grid", me))
    add_camera((0, 0, 3))
    set_world((1, 1, 1), 1.0)
    t = time.perf_counter()
    ex = export()
    seconds = time.perf_counter() - t
    print(f"\nexport of {ex.counts['triangles']} triangles: {seconds:.2f} s "
          f"(add-on part {ex.seconds:.2f} s incl. build_scene)")
    assert ex.counts["triangles"] == 2 * (n - 1) ** 2
    assert seconds < 15.0


def test_particle_and_geometry_node_instances(fresh):
    """Particles (object render type, emitter hidden) and Instance on Points (geometry nodes)
    are exported as instances of the cube, at their own transforms."""
    minimal(fresh)
    v, f = box((-0.1, -0.1, -0.1), (0.1, 0.1, 0.1))
    cube = add_object("cube", v, f, location=(0, 0, -5))
    pts = add_object("points", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], location=(3, 0, 0))
    ng = bpy.data.node_groups.new("gn", "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = ng.nodes.new("NodeGroupInput"), ng.nodes.new("NodeGroupOutput")
    iop, oi = ng.nodes.new("GeometryNodeInstanceOnPoints"), ng.nodes.new("GeometryNodeObjectInfo")
    oi.inputs["Object"].default_value = cube
    ng.links.new(gi.outputs[0], iop.inputs["Points"])
    ng.links.new(oi.outputs["Geometry"], iop.inputs["Instance"])
    ng.links.new(iop.outputs[0], go.inputs[0])
    pts.modifiers.new("gn", "NODES").node_group = ng
    em = add_object("emitter", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2, 3)], location=(-5, 0, 0))
    s = em.modifiers.new("ps", "PARTICLE_SYSTEM").particle_system.settings
    s.count, s.frame_start, s.frame_end, s.lifetime = 7, 1, 1, 100
    s.render_type, s.instance_object, s.physics_type, s.particle_size = "OBJECT", cube, "NO", 1.0
    em.show_instancer_for_render = em.show_instancer_for_viewport = False
    bpy.context.scene.frame_set(1)
    ex = export()
    kinds = sorted((o.instancer or "-", o.is_instance) for o in ex.objects)
    assert kinds == [("-", False)] + [("emitter", True)] * 7 + [("points", True)] * 4
    assert ex.counts["triangles"] == 12 * 12
    sc = ex.scene
    gn = [k for k, o in enumerate(ex.objects) if o.instancer == "points"]
    centres = np.array([sc.vertices[sc.triangles[ex.triangle_object[sc.triangle_source] == k]].reshape(-1, 3)
                        .mean(0) for k in gn])
    assert np.allclose(np.sort(centres[:, 0]), [3, 3, 4, 4]) and np.allclose(centres[:, 2], 0)


def test_what_cycles_renders_and_the_export_leaves_out_is_warned(fresh):
    """A world volume, hair strands, Geometry Nodes points, a displacement, a Principled
    base color above 1, Cycles' film exposure and a material's Bump Map Correction turned off
    each get one warning (they were dropped or clipped silently)."""
    v, f = box((-1, -1, -1), (1, 1, 1))
    mat = node_material("p", kind="principled", color=(1.5, 0.5, 0.5))
    out = mat.node_tree.nodes["Material Output"]
    mat.node_tree.links.new(mat.node_tree.nodes.new("ShaderNodeDisplacement").outputs[0], out.inputs["Displacement"])
    ob = add_object("room", v, f, [mat])
    add_light("POINT", location=(0, 0, 0.5), energy=100)
    add_camera((0, 0, 0), rotation=(1.5, 0, 0))
    nt = set_world((0.1, 0.1, 0.1), 1.0).node_tree
    nt.links.new(nt.nodes.new("ShaderNodeVolumePrincipled").outputs[0], nt.nodes["World Output"].inputs["Volume"])
    ob.modifiers.new("hair", "PARTICLE_SYSTEM")
    ob.particle_systems[0].settings.type = "HAIR"
    pv, pf = box((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2))
    mod = add_object("pts", pv, pf).modifiers.new("gn", "NODES")
    g = bpy.data.node_groups.new("points", "GeometryNodeTree")
    g.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    g.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    i, o, m2p = (g.nodes.new(t) for t in ("NodeGroupInput", "NodeGroupOutput", "GeometryNodeMeshToPoints"))
    g.links.new(i.outputs[0], m2p.inputs[0])
    g.links.new(m2p.outputs[0], o.inputs[0])
    mod.node_group = g
    bpy.context.scene.cycles.film_exposure = 2.0
    mat.cycles.use_bump_map_correction = False
    text = "\n".join(export().warnings)
    for expected in ("world 'world': its volume", "hair particles ('hair') are not rendered",
                     "object 'pts': point clouds", "material 'p': its displacement is not modeled",
                     "base color (1.5, 0.5, 0.5) is above 1", "film exposure 2 is not applied",
                     "material 'p': Bump Map Correction off is not modeled"):
        assert text.count(expected) == 1, (expected, text)


def test_world_is_evaluated_by_blender_in_the_cores_layout(fresh):
    """A world whose color is its own direction (Texture Coordinate › Generated, mapped to
    0.5 + 0.5 w) comes back as the directions of :func:`raybundle.scene.world.pixel_directions`:
    Blender's render and the core's look-up agree on the layout."""
    from raybundle.scene.world import pixel_directions

    add_camera((0, 0, 10))
    v, f = quad()
    add_object("plate", v, f, [node_material("white")])
    w = set_world((0, 0, 0), 1.0)
    nt = w.node_tree
    tc, vm = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeVectorMath")
    vm.operation = "MULTIPLY_ADD"
    vm.inputs[1].default_value = vm.inputs[2].default_value = (0.5, 0.5, 0.5)
    nt.links.new(tc.outputs["Generated"], vm.inputs[0])
    nt.links.new(vm.outputs[0], nt.nodes["Background"].inputs["Color"])
    world = export().scene.world
    h, wd = world.image.shape[:2]
    got = 2.0 * world.image - 1.0
    got /= np.linalg.norm(got, axis=2, keepdims=True)
    angle = np.degrees(np.arccos(np.clip((got * pixel_directions(h, wd)).sum(axis=2), -1, 1)))
    rows = slice(h // 8, h - h // 8)          # near the poles a pixel's mean direction is shorter
    assert angle[rows].max() < 1.0, angle[rows].max()


def test_a_view_layers_world_override_is_its_world(fresh):
    """A view layer's World Override replaces the scene's world, as Cycles renders it (the scene's
    world was exported: a blue sky where the layer asks for a red one); and settings that change
    Cycles' image and are not modeled (bounce limits, clamping, culling, the world's ray
    visibility, the view layer's Environment filter) are warned, each once."""
    add_camera((0, 0, 10))
    v, f = quad()
    add_object("plate", v, f, [node_material("white")])
    set_world((0.1, 0.2, 0.9), 1.0)
    red = set_world((0.9, 0.1, 0.1), 1.0)
    scene = bpy.context.scene
    scene.world = bpy.data.worlds["world"]
    if not hasattr(scene.view_layers[0], "world_override"):
        pytest.skip("this Blender has no World Override")
    scene.view_layers[0].world_override = red
    assert np.allclose(export().scene.world.image.reshape(-1, 3).mean(axis=0), (0.9, 0.1, 0.1), atol=1e-6)
    scene.cycles.max_bounces, scene.cycles.sample_clamp_direct, scene.cycles.use_camera_cull = 2, 5.0, True
    red.cycles_visibility.camera = False
    scene.view_layers[0].use_sky = False
    text = "\n".join(export().warnings)
    for expected in ("bounce limits below its defaults (max bounces 2)", "sample clamping", "culling is not modeled",
                     "world ray visibility is not modeled (camera off)", "filter (Environment off)"):
        assert text.count(expected) == 1, (expected, text)


def test_material_override_and_portals(fresh):
    """The view layer's Material Override replaces every material, the lamp's emission too
    (Cycles' clay render); a light portal is no lamp."""
    add_camera((0, 0, 10))
    v, f = quad()
    add_object("tex", v, f, [node_material("red", color=(0.8, 0.1, 0.1))])
    add_object("lamp", v, f, [node_material("glow", "emission", color=(1, 1, 1), strength=5.0)], location=(2, 0, 0))
    add_light("AREA", location=(0, 0, 3), size=1.0, energy=100.0)
    portal = add_light("AREA", location=(0, 0, 2), size=1.0, energy=1000.0)
    portal.data.cycles.is_portal = True
    set_world((1, 1, 1), 1.0)
    ex = export()
    assert len(ex.scene.area_lights) == 1 and np.allclose(ex.scene.area_lights.radiance, 100 / np.pi)
    assert any("portal" in x and repr(portal.name) in x for x in ex.warnings)
    assert ex.scene.materials.is_emitter.any()
    clay = node_material("clay", color=(0.8, 0.8, 0.8))
    bpy.context.view_layer.material_override = clay
    ex = export()
    mt = ex.scene.materials
    assert mt.names == ["clay"] and not mt.is_emitter.any()
    assert np.allclose(mt.diffuse[0], 0.8)


def test_coplanar_overlaps_are_warned_and_cycles_renders_them_darker(fresh, tmp_path):
    """A strip of one object lying on another's floor, both facing up (the dining room of the
    interior bench has such a strip): the export names both objects and the overlap's area,
    and Cycles, on the same file, renders the overlap darker than the floor beside it (in the
    sun: measured 0.0 against 0.72, every shadow ray meets the other face), as the warning
    tells the user.  The old export said nothing."""
    from addon_helpers import render_cycles

    add_camera((0, 0, 5), resolution=(32, 32), ortho_scale=4.0)
    add_object("floor", [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2, 3)], [node_material("white")])
    add_object("strip", [(1, -2, 0), (2, -2, 0), (2, 2, 0), (1, 2, 0)], [(0, 1, 2, 3)], [node_material("white")])
    add_light("SUN", rotation=(0.3, 0.2, 0), energy=3.0)
    set_world((0, 0, 0), 0.0)
    ex = export()
    said = [x for x in ex.warnings if "z-fighting" in x]
    assert len(said) == 1 and "'floor'" in said[0] and "'strip'" in said[0] and "over 4 m^2" in said[0], ex.warnings
    img = render_cycles(str(tmp_path / "cycles.exr"), samples=16).mean(axis=2)
    beside, overlap = img[4:28, 10:20].mean(), img[4:28, 26:30].mean()       # x = -0.75..0.5 m and 1.25..1.75 m
    assert beside > 0.5 and overlap < 0.5 * beside, (beside, overlap)


def test_materials_converted_ahead_warn_only_where_an_exported_object_uses_them(fresh):
    """The export converts the materials that wait for no graph bake before its loop over the
    objects (their images decoded while Blender bakes): a material's warnings are told when an
    exported object first uses it, in the objects' order, and never for a material only an
    object no ray sees uses."""
    minimal(fresh)
    v, f = quad(2.0)
    mats = []
    for name in ("unseen", "second", "first"):
        mat = node_material(name, kind="principled", color=(1.5, 0.5, 0.5))      # above 1: warned
        mats.append(mat)
    hidden = add_object("hidden", v, f, [mats[0]], location=(0, 0, -3))
    for k in ("visible_camera", "visible_diffuse", "visible_glossy", "visible_shadow", "visible_transmission"):
        setattr(hidden, k, False)
    add_object("a", v, f, [mats[2]], location=(0, 0, -1))
    add_object("b", v, f, [mats[1]], location=(0, 0, -2))
    warned = [w for w in export().warnings if w.startswith("material")]
    assert [w.split("'")[1] for w in warned] == ["first", "second"], warned


def test_the_shadow_terminator_geometry_offset_is_exported_per_object(fresh):
    """Each smooth-shaded object's Shadow Terminator Geometry Offset reaches its faces (the
    object's property in Blender 5, its ``cycles`` group's in 4.2, as Cycles reads it); the normal
    and shading offsets, not modeled, are warned."""
    from raybundle.scene.shading import DEFAULT_GEOMETRY_OFFSET

    minimal(fresh)
    obs = []
    for k, offset in enumerate((None, 0.0, 0.4)):
        bpy.ops.mesh.primitive_uv_sphere_add(segments=8, ring_count=4, location=(3 * k, 0, 0))
        bpy.ops.object.shade_smooth()
        ob = bpy.context.active_object
        ob.name = f"ball{k}"
        holder = ob if hasattr(ob, "shadow_terminator_geometry_offset") else ob.cycles
        if offset is not None:
            holder.shadow_terminator_geometry_offset = offset
        obs.append((ob.name, DEFAULT_GEOMETRY_OFFSET if offset is None else offset))
    ex = export()
    sc = ex.scene
    face_object = ex.triangle_object
    for k, (name, want) in enumerate(obs):
        got = sc.shading.geometry_offset[face_object == [o.name for o in ex.objects].index(name)]
        assert len(got) and np.allclose(got, want), (name, np.unique(got))
    assert not any("terminator" in w for w in ex.warnings)
    holder = ob if hasattr(ob, "shadow_terminator_shading_offset") else ob.cycles
    setattr(holder, "shadow_terminator_shading_offset" if holder is ob else "shadow_terminator_offset", 0.2)
    assert any("shadow terminator normal and shading offsets are not modeled" in w for w in export().warnings)
