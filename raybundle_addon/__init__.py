"""RayBundle GI, the Blender extension (thin glue over the ``raybundle`` library).

Scene export, the render engine, the bake operator and the panel come with the
add-on issue; the core library in ``core/`` already reads the ``.npz`` scenes
the exporter will write.
"""
