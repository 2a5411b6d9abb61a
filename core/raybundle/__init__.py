"""raybundle: global illumination by stochastic iteration with ray bundles.

Szirmay-Kalos, "Photorealistic image synthesis with ray bundles" (DSc thesis,
2000).  A standalone library (NumPy + Embree); the Blender add-on drives it.

The subpackages are layers, each importing only from those before it.  Their order and every
module's role are the module map under "Code layout" in ``docs/method.md``, which
``tests/test_layers.py`` holds to the code.
"""
__version__ = "0.1.0"
