"""The compiled BSDF (:mod:`raybundle.scene.compiled_bsdf`) against the NumPy path of
:class:`~raybundle.scene.materials.MaterialTable`: the same arithmetic, so the same values."""
import numpy as np
import pytest

from raybundle.scene.materials import MaterialTable
from raybundle.scene.principled import principled_material
from raybundle.util import compiled


def _materials():
    """Each kind of lobe: diffuse, Mix with a tinted Glossy, a sharp mirror, Principled plastic
    (a dielectric layer), metal (F82 conductor) and half metal with a tinted layer (single GGX)."""
    return MaterialTable.from_list([
        dict(name="diffuse", diffuse=(0.5, 0.4, 0.3), emission=(0, 0, 0)),
        dict(name="mix", diffuse=(0.5,) * 3, glossy=(0.8, 0.6, 0.4), glossy_weight=0.4, roughness=0.3,
             emission=(0, 0, 0)),
        dict(name="mirror", glossy=(0.9,) * 3, glossy_weight=1.0, roughness=0.0, emission=(0, 0, 0)),
        principled_material((0.8, 0.2, 0.1), roughness=0.4, name="plastic"),
        principled_material((0.9, 0.7, 0.3), metallic=1.0, roughness=0.2, name="gold"),
        principled_material((0.5, 0.5, 0.5), metallic=0.5, roughness=0.6, specular_tint=(1, 0.5, 0.5),
                            distribution="GGX", name="half")])


def _numpy(monkeypatch, fn):
    with monkeypatch.context() as m:
        m.setattr(compiled, "ENABLED", False)
        m.setattr(compiled, "_warned", True)
        return fn()


def test_the_compiled_bsdf_gives_the_numpy_paths_values(monkeypatch):
    """Random points, normals and directions (both sides), every lobe switch and a texture scale:
    the same values to the last bits where the dot products are summed in NumPy's order (the
    F82 conductor's ``s ** 5`` is NumPy's own power, a bit apart); in another order, the sharp
    mirror's lobe moves by a few 1e-12 of itself."""
    mt = _materials()
    rng = np.random.default_rng(7)
    n = 20_000

    def unit(v):
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    normal, w_in, w_out = (unit(rng.normal(size=(n, 3))) for _ in range(3))
    w_out[np.einsum("ij,ij->i", normal, w_out) < 0] *= -1.0          # most towards the viewer's side
    w_out[:100] *= -1.0
    mat, scale = rng.integers(0, len(mt), n), rng.random((n, 3))
    assert compiled.ENABLED
    calls = [lambda: mt.brdf(mat, normal, w_in, w_out), lambda: mt.brdf(mat, normal, w_in, w_out, diffuse_scale=scale),
             lambda: mt.brdf(mat, normal, w_in, w_out, diffuse=False),
             lambda: mt.brdf(mat, normal, w_in, w_out, glossy=False, diffuse_scale=scale),
             lambda: mt.brdf(mat, normal, w_in, np.array([0.0, 0.0, 1.0])),
             lambda: mt.glossy_pdf(mat, normal, -w_in, w_out)]
    for call in calls:
        got, want = call(), _numpy(monkeypatch, call)
        assert got.shape == want.shape and np.any(want > 0)
        assert np.allclose(got, want, rtol=1e-10, atol=0.0), np.abs(got - want).max()


def test_the_compiled_lobe_moments_give_the_numpy_paths_values(monkeypatch):
    """The layer tables' quadrature (``microfacet._moments``: the GGX lobe's albedo and its
    Fresnel moments at 65 view angles, 8,192 points each) compiled, point by point, against
    the NumPy path's vectorised points: the same sums in another order, within 1e-13, from
    near-mirror to rough lobes and without a layer or under one."""
    from raybundle.scene.microfacet import _moments

    mu = tuple(np.maximum(np.linspace(0.0, 1.0, 65), 1e-4).tolist())
    assert compiled.ENABLED
    for alpha in (0.001, 0.05, 0.3, 1.0):
        for eta in (0.0, 1.45, 2.5):
            got = _moments.__wrapped__(alpha, eta, mu, 256, 32)
            want = _numpy(monkeypatch, lambda: _moments.__wrapped__(alpha, eta, mu, 256, 32))
            assert (eta > 1) == bool(np.any(want["Sd"] > 0))
            for k in ("E", "F5", "Ed", "Sd"):
                np.testing.assert_allclose(got[k], want[k], rtol=0, atol=1e-13, err_msg=f"{k} {alpha} {eta}")


@pytest.mark.parametrize("field", ["roughness", "specular_ior"])
def test_the_compiled_bsdf_follows_a_changed_material(field):
    """The kernels' packed copy of the parameters is made again when a material changes in place."""
    mt = _materials()
    normal = np.tile([[0.0, 0.0, 1.0]], (1, 1))
    w_in, w_out = np.array([[0.3, 0.0, -0.954]]), np.array([[-0.2, 0.1, 0.975]])
    before = mt.brdf([3], normal, w_in, w_out)
    getattr(mt, field)[3] = {"roughness": 0.1, "specular_ior": 1.8}[field]
    after = mt.brdf([3], normal, w_in, w_out)
    mt._albedo_tables.clear()
    assert np.array_equal(after, mt.brdf([3], normal, w_in, w_out)) and not np.allclose(before, after)


def test_the_compiled_glossy_sampler_gives_the_numpy_paths_directions_and_weights(monkeypatch):
    """:meth:`MaterialTable.sample_glossy` (visible normals, the sampler's weight times the tint or
    the layered factor): the same directions and weights on both paths, for every kind of lobe,
    normals of both hemispheres and views from both sides."""
    mt = _materials()
    rng = np.random.default_rng(11)
    n = 20_000

    def unit(v):
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    normal, w_out = unit(rng.normal(size=(n, 3))), unit(rng.normal(size=(n, 3)))
    w_out[np.einsum("ij,ij->i", normal, w_out) < 0] *= -1.0
    w_out[:100] *= -1.0
    mat, u = rng.integers(0, len(mt), n), rng.random((n, 2))
    got = mt.sample_glossy(mat, normal, w_out, u)
    want = _numpy(monkeypatch, lambda: mt.sample_glossy(mat, normal, w_out, u))
    for g, w in zip(got, want):
        assert np.any(w > 0)
        assert np.allclose(g, w, rtol=1e-10, atol=1e-13), np.abs(g - w).max()


_SIGNATURES = """
import json
from raybundle.app import pipeline
from raybundle.imaging.settings import RenderSettings
from raybundle.scene.builtin import load_scene
from raybundle.util import compiled
pipeline.compile_kernels(None, None)
sc = load_scene("cornell-glossy")
sc.camera = sc.camera.with_resolution(32, 32)
r = pipeline.make_renderer(pipeline.prepare(sc, 300), RenderSettings(seed=1))
for _ in range(3):
    r.step()
    r.image_pass()
r.image()
r.tracer.close()
print(json.dumps({k.__name__: len(k._compiled.signatures) - len(k.samples) for k in compiled._KERNELS
                  if k._compiled is not None}))
"""


def test_a_render_calls_the_kernels_as_they_were_compiled_before_it():
    """A glossy scene's render (lamps with MIS, glossy eye paths, bundles) calls every kernel with
    the argument types its set-up phase compiled (one signature a sample): none compiles again
    during the run, where a cold first render would wait for it and the phase would not show it
    (read-only views, as ``broadcast_to`` gives, made four kernels compile a second time)."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _SIGNATURES], capture_output=True, text=True, check=True).stdout
    counts = json.loads(out.strip().splitlines()[-1])
    assert counts and all(n == 0 for n in counts.values()), counts


_PHASE_OF_COMPILES = """
import json, sys
from raybundle.app import phases
from raybundle.util import arrays, compiled
arrays.RADIX_MIN = 2                 # every sort by the kernel, as a large room's export sorts
now, seen = ["(before any phase)"], {}
call, get = phases.PhaseClock.__call__, compiled.Kernel.compiled
def stage(self, text):
    now[0] = text
    return call(self, text)
def kernel(self):
    if self._compiled is None:
        seen[self.__name__] = now[0]
    return get(self)
phases.PhaseClock.__call__, compiled.Kernel.compiled = stage, kernel
from raybundle_addon.__main__ import main
code = main([sys.argv[1], "--out", sys.argv[2], "--iterations", "1"])
print(json.dumps(seen))
"""


def test_the_add_ons_kernels_compile_in_their_own_phase(tmp_path):
    """A render through the add-on, in a fresh process, compiles (or loads) every kernel it uses
    in the phase "compiling the kernels", which comes first: a large room's export sorts with one
    (here every sort), and a cold cache's compile (seconds) then showed as the export's time."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _PHASE_OF_COMPILES, "demo_scenes/cornell_box.blend",
                          str(tmp_path / "c.exr")], capture_output=True, text=True, check=True).stdout
    seen = json.loads(out.strip().splitlines()[-1])
    assert seen and set(seen.values()) == {"compiling the kernels"}, seen
