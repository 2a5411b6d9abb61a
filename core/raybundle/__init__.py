"""raybundle: global illumination by stochastic iteration with ray bundles.

Szirmay-Kalos, "Photorealistic image synthesis with ray bundles" (DSc thesis,
2000).  A standalone library (NumPy + Embree); the Blender add-on drives it.

The subpackages are layers; each imports only from those listed before it:

* :mod:`raybundle.util`: ``arrays`` (unique rows, groups, components), ``io`` (EXR, PNG,
  JSON, outputs checked before the work and written atomically);
* :mod:`raybundle.tracing`: ``visibility`` (the Embree ray tracer, bundles), ``sampling``
  (directions, random and quasi-random sequences);
* :mod:`raybundle.scene`: ``model`` (the patch scene, its sides, lights as records),
  ``build`` (a scene from arrays, validated), ``npz`` (the file format), ``materials``
  (BRDFs), ``textures``, ``camera``, ``builtin`` (the built-in scenes);
* :mod:`raybundle.patches`: ``layout`` (subdivision), ``clusters`` (the patch layout of a
  scene), ``contacts`` (cuts where surfaces touch), ``reconstruction`` (smooth values from
  patch values);
* :mod:`raybundle.lights`: ``sources`` (mesh, point, area and sun lights), ``polygon``
  (analytic irradiance), ``direct`` (direct light per point), ``first_shot`` (per patch),
  ``caustics`` (the first shot's glossy reflections);
* :mod:`raybundle.imaging`: ``settings``, ``run`` (the one run loop and its budget),
  ``renderer`` (camera images from a solution: passes, direct light, resolve),
  ``glossy_paths`` (the glossy lobe the eye sees), ``caustic_splats``, ``splat`` (light tracing
  into pixels), ``gather`` (the final gather), ``baking`` (radiance at bake points);
* :mod:`raybundle.methods`: ``base`` (what every method declares), ``stochastic_iteration``
  (ray bundles, the patch methods' base), ``ray_bundle_walk``, ``radiosity``,
  ``point_collocation``, ``path_tracing``, ``single_ray_iteration``, and ``registry`` (the
  methods by name);
* :mod:`raybundle.app`: ``plan`` (the one set-up decision), ``pipeline`` (building what
  a plan says), ``auto``, ``cli``, ``bench``, ``metrics`` (the image error), ``chains`` and
  ``distributed`` (independent chains merged, on Dask).
"""
__version__ = "0.1.0"
