"""RayBundle GI, the Blender extension: thin glue over the ``raybundle`` library.

Two layers.  Its user interface: :mod:`.properties` (``scene.raybundle`` settings),
:mod:`.engine` (the ``RAYBUNDLE`` render engine), :mod:`.bake` and :mod:`.operators` (the
``raybundle.bake`` operator: color attributes, lightmaps), :mod:`.ui` (panels), and
``raybundle-blender``, which renders or bakes a ``.blend`` headless (:mod:`.__main__`).  Under
it, the translation of Blender's data into the core's scene (:mod:`.translation`), which
imports nothing of the interface.
"""
from __future__ import annotations

import importlib

#: registered in this order (``bpy`` is imported with them, when Blender registers the
#: extension: ``raybundle-blender`` hears Ctrl-C before it imports ``bpy``)
_MODULES = ("properties", "engine", "operators", "ui")


def _modules():
    return [importlib.import_module(f"{__name__}.{name}") for name in _MODULES]


def register():
    from raybundle.util import compiled

    from .translation.bake_cache import user_folder

    compiled.CACHE_FOLDER = user_folder("kernels")     # the compiled kernels in the add-on's user folder
    for m in _modules():
        m.register()


def unregister():
    for m in reversed(_modules()):
        m.unregister()
