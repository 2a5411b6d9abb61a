"""A light's settings from a Blender file, each against Cycles on the same small file: its own
node tree and IES profile, Cast Shadow, light and shadow linking; what is not modeled is warned,
never silently wrong.  A volume without a surface is left out.

Each comparison renders both sides with two seeds: the image means within 3% and the 8 x 8
regions within 4.5 standard errors (:func:`addon_helpers.regions_agree`)."""
from __future__ import annotations

import numpy as np
import pytest
from addon_helpers import (  # noqa: F401
    add_camera,
    add_light,
    add_object,
    addon,
    assert_like_cycles,
    box,
    bpy,
    fresh,
    new_with_nodes,
    node_material,
    render_cycles,
    render_raybundle,
)


def floor_and_block():
    """A grey floor, a black block hovering above it and a point lamp above and beside the
    block, seen from above by a 48 x 48 camera that sees only the floor and the block (a black
    block: the patches' bias in what the floor and block throw at each other would hide what
    is tested)."""
    add_object("floor", [(-4, -4, 0), (4, -4, 0), (4, 4, 0), (-4, 4, 0)], [(0, 1, 2, 3)],
               [node_material("floor", color=(0.5, 0.5, 0.5))])
    v, f = box((-0.5, -0.5, 0.6), (0.5, 0.5, 1.0))
    add_object("block", v, f, [node_material("block", color=(0.0, 0.0, 0.0))])
    lamp = add_light("POINT", location=(1.0, 0.6, 2.2), energy=300.0, shadow_soft_size=0.0,
                     use_soft_falloff=False)
    add_camera((0, -1.6, 4.0), rotation=(0.35, 0, 0), resolution=(48, 48), lens=35)
    bpy.context.scene.cycles.pixel_filter_type = "BOX"        # both sides: the references' 1 px box
    return lamp


def two_tiles():
    """:func:`floor_and_block`'s floor cut in two objects, tile A (x < 0) and tile B (x > 0)."""
    bpy.data.objects.remove(bpy.data.objects["floor"])
    for name, x0, x1 in (("tile A", -4, 0), ("tile B", 0, 4)):
        add_object(name, [(x0, -4, 0), (x1, -4, 0), (x1, 4, 0), (x0, 4, 0)], [(0, 1, 2, 3)],
                   [node_material(name, color=(0.5, 0.5, 0.5))])


def link_lighting_tile_a(emitter, receivers):
    """Give ``emitter`` the receiver collection ``receivers`` and a blocker collection that
    excludes the block (so everything else, and not the block, shadows it)."""
    blockers = bpy.data.collections.new("blocking")
    blockers.objects.link(bpy.data.objects["block"])
    blockers.collection_objects[0].light_linking.link_state = "EXCLUDE"
    emitter.light_linking.receiver_collection = receivers
    emitter.light_linking.blocker_collection = blockers


def light_nodes(lamp):
    """The node tree of ``lamp``'s light (Blender 4.x makes it with Use Nodes)."""
    if lamp.data.node_tree is None:
        lamp.data.use_nodes = True
    return lamp.data.node_tree


def against_cycles(tmp_path, iterations=24):
    """(ours (A, B), Cycles' (A, B)), two seeds each."""
    ours = [render_raybundle(tmp_path / f"rb{s}.exr", iterations=iterations, seed=s) for s in (1, 2)]
    theirs = [render_cycles(tmp_path / f"cy{s}.exr", samples=64, seed=s) for s in (1, 2)]
    return ours, theirs


def test_a_lights_node_tree_scales_its_emission_as_in_cycles(fresh, tmp_path):
    """Emission Strength 3 (through a Light Falloff's Quadratic output) and a reddish Color
    (an RGB node) on the lamp's own nodes: 3 x (1, 0.35, 0.2) its light, as Cycles renders it
    (the tree was not read: x0.6 of Cycles' mean)."""
    lamp = floor_and_block()
    nt = light_nodes(lamp)
    em = next(n for n in nt.nodes if n.type == "EMISSION")
    rgb, fall = nt.nodes.new("ShaderNodeRGB"), nt.nodes.new("ShaderNodeLightFalloff")
    rgb.outputs[0].default_value = (1.0, 0.35, 0.2, 1.0)
    fall.inputs["Strength"].default_value = 3.0
    nt.links.new(rgb.outputs[0], em.inputs["Color"])
    nt.links.new(fall.outputs["Quadratic"], em.inputs["Strength"])
    assert_like_cycles(*against_cycles(tmp_path))
    from raybundle_addon.properties import LAST_RUN

    assert not [w for w in LAST_RUN[bpy.context.scene.name]["warnings"] if "node tree" in w]


def test_cast_shadow_off_lets_the_lamp_light_through_the_block_as_in_cycles(fresh, tmp_path):
    """With Cast Shadow off nothing blocks the lamp's light: the floor under the block is lit
    (it was not read: the shadow stayed)."""
    lamp = floor_and_block()
    lamp.data.use_shadow = False
    assert_like_cycles(*against_cycles(tmp_path))


def test_a_volume_without_a_surface_is_left_out_and_warned(fresh, tmp_path):
    """A cube with a Principled Volume and no surface shader between the lamp and the floor: the
    image is the image without it (it was an opaque black cube), and its warning stays."""
    floor_and_block()
    without = render_raybundle(tmp_path / "without.exr", iterations=8, seed=1)
    mat = new_with_nodes(bpy.data.materials, "fog")
    nt = mat.node_tree
    for n in list(nt.nodes):
        if n.type != "OUTPUT_MATERIAL":
            nt.nodes.remove(n)
    vol = nt.nodes.new("ShaderNodeVolumePrincipled")
    vol.inputs["Density"].default_value = 0.002
    nt.links.new(vol.outputs[0], nt.nodes["Material Output"].inputs["Volume"])
    v, f = box((-1.2, -1.2, 1.2), (1.2, 1.2, 1.8))
    add_object("fog", v, f, [mat])
    with_fog = render_raybundle(tmp_path / "with.exr", iterations=8, seed=1)
    from raybundle_addon.properties import LAST_RUN

    assert np.array_equal(with_fog, without)
    assert any("volumes are not modeled" in w and "'fog'" in w for w in LAST_RUN[bpy.context.scene.name]["warnings"])


def test_light_and_shadow_linking_on_lamps_as_in_cycles(fresh, tmp_path):
    """A spot lamp whose receiver collection includes floor tile A and, through a child collection
    set to Exclude, not tile B; and whose blocker collection excludes the block (so nothing else
    in the scene, and not the block, shadows it); an unlinked point lamp lights both tiles and is
    blocked.  As Cycles renders the same file (the linking was not read: x1.4 Cycles' mean)."""
    from raybundle_addon.properties import LAST_RUN

    floor_and_block()
    two_tiles()
    spot = add_light("SPOT", location=(0.3, -0.4, 2.6), rotation=(0.1, 0.0, 0), energy=900.0, spot_size=1.8,
                     shadow_soft_size=0.0, use_soft_falloff=False)
    receivers, excluded = bpy.data.collections.new("lit"), bpy.data.collections.new("not lit")
    receivers.objects.link(bpy.data.objects["tile A"])
    receivers.children.link(excluded)
    excluded.objects.link(bpy.data.objects["tile B"])
    receivers.collection_children[0].light_linking.link_state = "EXCLUDE"
    link_lighting_tile_a(spot, receivers)
    assert_like_cycles(*against_cycles(tmp_path))
    assert not [w for w in LAST_RUN[bpy.context.scene.name]["warnings"] if "linking" in w]


#: an asymmetric type C profile: brighter towards horizontal angle 90 and at 30-60 degrees from
#: straight down, nothing above the horizon
IES_TEXT = """IESNA:LM-63-2002
[TEST] raybundle
TILT=NONE
1 1000 1.0 7 5 1 2 0.1 0.1 0.0
1.0 1.0 100
0 30 60 90 120 150 180
0 90 180 270 360
400 600 500 200 0 0 0
400 1200 1500 300 0 0 0
400 700 600 250 0 0 0
400 500 400 150 0 0 0
400 600 500 200 0 0 0
"""


def test_an_ies_profile_shapes_a_lamps_light_as_in_cycles(fresh, tmp_path):
    """A point lamp whose Emission Strength is an IES Texture's output (an asymmetric type C
    profile in a text block, Strength 1.5): its light on the floor as Cycles renders it (the
    profile was ignored: x0.02 Cycles' mean)."""
    lamp = floor_and_block()
    bpy.data.objects.remove(bpy.data.objects["block"])
    lamp.location = (0.0, 0.4, 1.6)
    lamp.data.energy = 40.0
    text = bpy.data.texts.new("profile.ies")
    text.from_string(IES_TEXT)
    nt = light_nodes(lamp)
    ies = nt.nodes.new("ShaderNodeTexIES")
    ies.mode, ies.ies = "INTERNAL", text
    ies.inputs["Strength"].default_value = 1.5
    nt.links.new(ies.outputs[0], next(n for n in nt.nodes if n.type == "EMISSION").inputs["Strength"])
    assert_like_cycles(*against_cycles(tmp_path))
    from raybundle_addon.translation.export import export_scene

    twin = bpy.data.objects.new("twin", lamp.data)          # a second lamp of the same light data
    twin.location = (0.5, -0.5, 1.6)
    bpy.context.scene.collection.objects.link(twin)
    lights = export_scene(bpy.context.evaluated_depsgraph_get()).scene.point_lights
    assert len(lights) == 2 and len(lights.profiles) == 1 and list(lights.profile) == [0, 0]


def test_an_ies_texture_blender_cannot_read_is_warned(fresh):
    """An IES Texture without a text block: one warning naming the lamp and the node (the lamp
    then emits its own color and power)."""
    from raybundle_addon.translation.export import export_scene

    lamp = floor_and_block()
    nt = light_nodes(lamp)
    ies = nt.nodes.new("ShaderNodeTexIES")
    nt.links.new(ies.outputs[0], next(n for n in nt.nodes if n.type == "EMISSION").inputs["Strength"])
    text = "\n".join(export_scene(bpy.context.evaluated_depsgraph_get()).warnings)
    assert text.count("light 'point': its node tree is not modeled (the IES Texture 'IES Texture' has no text") == 1, \
        text


def test_light_linking_on_an_emitting_mesh_as_in_cycles(fresh, tmp_path):
    """A small glowing quad (the first shot's) whose receiver collection includes floor tile A
    only and whose blocker collection excludes the block: as Cycles renders the same file (its
    linking was warned and not applied before)."""
    from raybundle_addon.properties import LAST_RUN

    floor_and_block()
    two_tiles()
    glow = add_object("glow", [(-0.3, -0.3, 2.2), (0.3, -0.3, 2.2), (0.3, 0.3, 2.2), (-0.3, 0.3, 2.2)],
                      [(0, 1, 2, 3)], [node_material("glow", kind="emission", color=(1.0, 0.9, 0.8), strength=60.0)])
    receivers = bpy.data.collections.new("lit")
    receivers.objects.link(bpy.data.objects["tile A"])
    link_lighting_tile_a(glow, receivers)
    assert_like_cycles(*against_cycles(tmp_path))
    assert not [w for w in LAST_RUN[bpy.context.scene.name]["warnings"] if "linking" in w]


def test_linking_on_an_emitting_mesh_too_large_for_the_first_shot_is_warned(fresh):
    """An emitting mesh as large as the floor goes through the bundles, which carry its light to
    every surface: its linking is warned, once, naming it."""
    from raybundle_addon.translation.export import export_scene

    floor_and_block()
    glow = add_object("ceiling", [(-4, -4, 3), (4, -4, 3), (4, 4, 3), (-4, 4, 3)], [(0, 1, 2, 3)],
                      [node_material("glow", kind="emission", strength=2.0)])
    receivers = bpy.data.collections.new("lit")
    receivers.objects.link(bpy.data.objects["floor"])
    glow.light_linking.receiver_collection = receivers
    text = "\n".join(export_scene(bpy.context.evaluated_depsgraph_get()).warnings)
    assert text.count("emitting mesh 'ceiling': too large for the first shot") == 1, text
