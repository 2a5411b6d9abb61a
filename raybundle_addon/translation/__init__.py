"""The translation layer: Blender's data, as the evaluated depsgraph holds it, into the core's scene.

:mod:`.export` gathers the meshes, lamps, camera and world; :mod:`.shaders` reads the material
node trees, :mod:`.light_nodes` the lights' own, :mod:`.light_linking` light and shadow linking,
and :mod:`.node_links` follows their links.  What Blender itself must evaluate (node graphs on a
material's inputs, the world) it evaluates in a child process (:mod:`.blender_process`) running
:mod:`.material_bake` or :mod:`.world_render`, driven by :mod:`.node_graphs` and :mod:`.world`.
Nothing here imports the add-on's user interface (its settings, panels, operators, render
engine and bake job), which sits above it.
"""
