"""raybundle: global illumination by stochastic iteration with ray bundles.

Szirmay-Kalos, "Photorealistic image synthesis with ray bundles" (DSc thesis,
2000).  A standalone library (NumPy + Embree); the Blender add-on drives it.

Modules, one job each: :mod:`~raybundle.scene` (patches, validation, .npz),
:mod:`~raybundle.materials` (BRDFs), :mod:`~raybundle.sampling` (directions,
sequences), :mod:`~raybundle.visibility` (Embree, bundles),
:mod:`~raybundle.lights` (first shot), :mod:`~raybundle.solvers`,
:mod:`~raybundle.reconstruction` (linear interpolation of patch values),
:mod:`~raybundle.imaging` (camera images), :mod:`~raybundle.io` (EXR/PNG),
:mod:`~raybundle.scenes` (built-in scenes), :mod:`~raybundle.pipeline`
(one-call render), :mod:`~raybundle.cli`.
"""
__version__ = "0.1.0"
