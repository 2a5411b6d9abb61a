"""Many lamps from a Blender file, against Cycles on the same file: the light tree
(:mod:`raybundle.lights.light_tree`) that picks among them per point."""
from __future__ import annotations

import numpy as np
import pytest
from addon_helpers import (  # noqa: F401
    add_camera,
    add_light,
    add_object,
    addon,
    bpy,
    fresh,
    node_material,
    render_cycles,
    render_raybundle,
)


def test_a_thousand_small_lamps_light_a_room_as_in_cycles(fresh, tmp_path):
    """A floor and a back wall under 1,000 point lamps of powers over two decades, at random
    above the floor: the lamps go through the light tree (one pick per pixel and pass, not a
    shadow ray per lamp), and the 6 x 6 regions of the image and its mean agree with Cycles
    (2 x 256 spp, whose halves differ by up to 4.3% a region) within the noise measured (seed 3:
    the regions' RMS error 1.9%, largest 4.4%, mean x0.992)."""
    rng = np.random.default_rng(7)
    add_object("floor", [(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2, 3)],
               [node_material("floor", color=(0.8, 0.8, 0.8))])
    add_object("wall", [(-2, 2, 0), (2, 2, 0), (2, 2, 2), (-2, 2, 2)], [(0, 1, 2, 3)],
               [node_material("wall", color=(0.6, 0.7, 0.8))])
    for k in range(1000):
        add_light("POINT", location=(rng.uniform(-1.9, 1.9), rng.uniform(-1.9, 1.9), rng.uniform(0.15, 1.6)),
                  energy=float(10 ** rng.uniform(-1.5, 0.5)), shadow_soft_size=0.0)
    add_camera((0, -3.2, 2.6), rotation=(0.85, 0, 0), resolution=(48, 36), lens=24)
    from raybundle_addon.translation.export import export_scene

    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    assert len(ex.scene.point_lights) == 1000
    a = render_cycles(tmp_path / "a.exr", samples=256, seed=1)
    b = render_cycles(tmp_path / "b.exr", samples=256, seed=2)
    ours = render_raybundle(tmp_path / "rb.exr", iterations=30, seed=3)
    from raybundle_addon.properties import LAST_RUN

    assert LAST_RUN[bpy.context.scene.name]["stats"]["light_tree"]

    def regions(x):
        return x.reshape(6, 6, 6, 8, 3).mean(axis=(1, 3))

    ref = regions(0.5 * (a + b))
    lit = ref.mean(axis=-1) > 0.02 * ref.mean(axis=-1).max()          # not the black sky past the wall
    rel = (regions(ours) / np.where(ref > 0, ref, 1) - 1)[lit]
    print("regions: RMS", np.sqrt((rel ** 2).mean()), "largest", np.abs(rel).max(), "mean",
          ours.mean() / (0.5 * (a + b)).mean())
    assert np.sqrt((rel ** 2).mean()) < 0.04 and np.abs(rel).max() < 0.1, rel
    assert ours.mean() / (0.5 * (a + b)).mean() == pytest.approx(1.0, abs=0.015)
