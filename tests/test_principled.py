"""Blender's Principled BSDF against Cycles through the real ``bpy`` module.

A huge plane with a Principled BSDF under a uniform white world (strength 1), seen
by an orthographic camera: every pixel's radiance is the directional albedo
a(w_out) of the material (the plane sees only the world; Filter Glossy off).  The
base color (1, 0.5, 0.05) puts a white, a mid-grey and a black-ish base into one
render (the Principled BSDF acts per channel).  Compared with
:meth:`MaterialTable.albedo` of :func:`principled_material`, and with the plain
Mix(Diffuse, Glossy GGX) a naive exporter would build, which is off by up to 87%
at 80 degrees (a black-ish metal) and by 44% head-on (a rough white metal).
"""
import os
import sys

import bpy  # noqa: E402  (the test set-up installs bpy: a missing one must fail)
import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tools"))
import cycles_reference as cr  # noqa: E402

from raybundle.scene.materials import MaterialTable
from raybundle.scene.microfacet import f0_from_ior
from raybundle.scene.principled import principled_material

BASE = (1.0, 0.5, 0.05)
#: Cycles' own lookup tables (32 x 32 GGX albedo, 16^3 Fresnel factor) differ from the
#: exact integrals by up to 9e-4 at these points (measured: E at roughness 0.2, 80 deg),
#: and our 65-point tables in cos(theta) interpolate to < 5e-4: an absolute budget.
TABLE_ERROR = 1.5e-3


def cycles_principled_albedo(tmp_path, base, metallic, roughness, cos_view, distribution="MULTI_GGX", ior=1.5,
                             specular_ior_level=0.5, specular_tint=(1, 1, 1), samples=1024, res=8):
    """(pixels (res*res, 3)) radiance of a Principled plane under a white world, seen at cos_view."""
    cr.reset()
    mat = cr.new_with_nodes(bpy.data.materials, "principled")
    node = mat.node_tree.nodes["Principled BSDF"]
    node.distribution = distribution
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Metallic"].default_value = metallic
    node.inputs["Roughness"].default_value = roughness
    node.inputs["IOR"].default_value = ior
    node.inputs["Specular IOR Level"].default_value = specular_ior_level
    node.inputs["Specular Tint"].default_value = (*specular_tint, 1.0)
    return cr.plane_under_white_world(mat, cos_view, res, samples, tmp_path / "principled.exr")


CASES = [  # (metallic, roughness, cos_view, extra Principled inputs)
    (0.0, 0.2, 0.174, {}), (0.0, 0.5, 0.5, {}), (0.0, 0.8, 1.0, {}),
    (1.0, 0.2, 0.5, {}), (1.0, 0.5, 1.0, {}), (1.0, 0.8, 0.342, {}),
    (0.0, 0.5, 0.342, dict(distribution="GGX")), (1.0, 0.5, 0.866, dict(distribution="GGX")),
    (0.4, 0.6, 0.5, dict(base=(0.9, 0.6, 0.3))),
    (1.0, 0.3, 0.174, dict(base=(0.9, 0.6, 0.3), specular_tint=(1.0, 0.4, 0.1))),
    (0.0, 0.3, 0.5, dict(specular_ior_level=1.0)), (0.0, 0.5, 0.174, dict(ior=2.0)),
]


@pytest.mark.parametrize("metallic,roughness,cos_view,extra", CASES)
def test_principled_albedo_matches_cycles(tmp_path, metallic, roughness, cos_view, extra):
    extra = dict(extra)
    base = extra.pop("base", BASE)
    px = cycles_principled_albedo(tmp_path, base, metallic, roughness, cos_view, **extra)
    cyc, se = px.mean(axis=0), px.std(axis=0, ddof=1) / np.sqrt(len(px))
    mt = MaterialTable.from_list([principled_material(base, metallic, roughness, **extra)])
    mt.validate()
    ours = mt.albedo(np.array([0]), np.array([cos_view]))[0]
    assert np.all(np.abs(ours - cyc) < 4.5 * se + TABLE_ERROR), (ours, cyc, se)


def naive_mix(base, metallic, roughness, ior=1.5):
    """What an exporter without the layered model would do: Mix(Diffuse(base), Glossy GGX(tint), fac)
    with fac = metallic + (1 - metallic) F0 and the tint blending base and white by metallic."""
    f0 = f0_from_ior(ior)
    g = metallic + (1 - metallic) * f0
    ks = (metallic * np.asarray(base) + (1 - metallic) * f0) / g
    return MaterialTable.from_list([dict(diffuse=base, glossy=ks, glossy_weight=g, roughness=roughness)])


@pytest.mark.parametrize("metallic,roughness,cos_view,channel,worse_than", [
    (0.0, 0.5, 0.174, 2, 0.40),     # dielectric, black-ish base at 80 deg: Fresnel makes it 2.2x brighter
    (1.0, 0.8, 1.0, 0, 0.40),       # rough white metal head-on: multiscatter restores 44% more light
])
def test_plain_mix_is_off_by_more_than_2_percent(tmp_path, metallic, roughness, cos_view, channel, worse_than):
    """Why the layered model exists: the best plain Mix a naive exporter builds misses by far more than 2%."""
    px = cycles_principled_albedo(tmp_path, BASE, metallic, roughness, cos_view)
    cyc = px.mean(axis=0)[channel]
    naive = naive_mix(BASE, metallic, roughness).albedo(np.array([0]), np.array([cos_view]))[0, channel]
    ours = MaterialTable.from_list([principled_material(BASE, metallic, roughness)]).albedo(
        np.array([0]), np.array([cos_view]))[0, channel]
    assert abs(naive - cyc) / cyc > worse_than
    assert abs(ours - cyc) / cyc < 0.02


def test_principled_defaults_are_what_the_mapping_assumes():
    cr.reset()
    mat = cr.new_with_nodes(bpy.data.materials, "p")
    node = mat.node_tree.nodes["Principled BSDF"]
    assert node.distribution == "MULTI_GGX"
    assert node.inputs["IOR"].default_value == pytest.approx(1.5)
    assert node.inputs["Specular IOR Level"].default_value == pytest.approx(0.5)
    assert node.inputs["Diffuse Roughness"].default_value == 0.0        # Lambertian base (Oren-Nayar if > 0)
    spec = principled_material(tuple(node.inputs["Base Color"].default_value))
    assert spec["specular_ior"] == pytest.approx(1.5) and spec["multiscatter"] == 1
