"""Graph bakes kept on disk between runs, keyed by what they were baked from.

A graph baked by Blender (:mod:`.node_graphs`) is a function of its material (the node tree, its
nodes' settings, its images' settings and pixels), of the object it is baked on for a graph that
reads the point of the object (its mesh, UV maps, modifiers and transform) and of the task (the
input, its UV map, the texels a side), under one Blender version.  Its key is the SHA-1 of all
of these: the material and the object as Blender writes them alone into a library file
(:func:`library_digest`: the file holds Blender's version and every setting and node, and is
the same bytes from run to run), each image's pixels (:func:`image_digest`: for an image read
from a file the file's path, size and modification time) and the task.  A change to any of them
gives another key: nothing stale is read.

The bakes are ``<key>.npy`` files in the add-on's user folder (:func:`cache_folder`: Blender's
``extension_path_user`` for the extension, its user data files otherwise), written atomically
and read with a shape check; the least recently used are removed beyond :data:`CACHE_BYTES`.
A folder that cannot be written leaves every graph baked anew (a note on the console).  World
renders (:mod:`.world`) are kept the same way.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys

import numpy as np

#: bytes of bakes kept; the least recently used beyond this are removed
CACHE_BYTES = 1 << 30
#: False: nothing is read or kept (a benchmark times every run as a fresh session's first)
KEEP = True
#: changes when what a key stands for changes (the bake script's output)
FORMAT = 1


def cache_folder():
    """The folder the bakes are kept in (made if needed), or None when there is none or
    :data:`KEEP` is off."""
    return user_folder("graph-bakes") if KEEP else None


def user_folder(name):
    """The add-on's user folder ``name`` (made if needed): Blender's ``extension_path_user`` for
    the extension, its user data files when the add-on runs from source; None when it cannot
    be made (a note on the console)."""
    import bpy

    root = (__package__ or "").rpartition(".translation")[0]
    try:
        try:
            return bpy.utils.extension_path_user(root, path=name, create=True)
        except (ValueError, KeyError):        # the add-on loaded from source, not as an extension
            return bpy.utils.user_resource("DATAFILES", path=os.path.join("raybundle", name), create=True)
    except (OSError, RuntimeError) as e:
        print(f"raybundle: no user folder {name!r} ({e})", file=sys.stderr)
        return None


def library_digest(ids, path):
    """SHA-1 (hex) of the library file Blender writes of data-blocks ``ids`` alone, at ``path``."""
    import bpy

    for i in ids:
        for held in (i, getattr(i, "data", None), *getattr(i, "material_slots", ())):
            _settle(getattr(held, "material", held))
    bpy.data.libraries.write(path, set(ids), path_remap="ABSOLUTE", fake_user=True)
    with open(path, "rb") as f:
        return hashlib.sha1(f.read()).hexdigest()


def _settle(block):
    """Make the add-ons' settings groups of data-block ``block`` (None: nothing): Blender makes
    a group the first time it is read (the export reads ``Object.cycles``), which changes the
    library file but not the bake."""
    rna = getattr(block, "bl_rna", None)
    for p in rna.properties if rna is not None else ():
        if p.type == "POINTER" and p.is_runtime:
            getattr(block, p.identifier, None)


def image_digest(image):
    """SHA-1 (hex) standing for ``image``'s pixels: for an unchanged image read from a file, its
    path, size and modification time; for any other (packed, generated, edited), the pixels."""
    import bpy

    h = hashlib.sha1(repr((image.name_full, image.source, tuple(image.size))).encode())
    path = bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""
    if image.source == "FILE" and image.packed_file is None and not image.is_dirty and os.path.isfile(path):
        st = os.stat(path)
        h.update(repr((os.path.realpath(path), st.st_size, st.st_mtime_ns)).encode())
        return h.hexdigest()
    px = np.empty(int(image.size[0]) * int(image.size[1]) * int(image.channels), np.float32)
    try:
        image.pixels.foreach_get(px)
    except (RuntimeError, ValueError):
        return None
    h.update(px.tobytes())
    return h.hexdigest()


def task_key(task, digests):
    """The key of a bake ``task`` (a dict of plain values, no paths) given the ``digests`` of
    what it reads (library and image digests)."""
    return hashlib.sha1(json.dumps([FORMAT, task, digests], sort_keys=True).encode()).hexdigest()


class BakeCache:
    """The bakes kept in ``folder`` (None: none are kept)."""

    def __init__(self, folder):
        self.folder = folder

    def load(self, key, shape):
        """The bake of ``key`` if kept with ``shape`` (its first two axes), else None."""
        if self.folder is None:
            return None
        path = os.path.join(self.folder, key + ".npy")
        try:
            a = np.load(path)
            os.utime(path)                                    # recently used
        except (OSError, ValueError):
            return None
        return a if a.ndim == 3 and a.shape[:2] == tuple(shape) and a.shape[2] == 3 else None

    def store(self, values):
        """Keep ``values`` (key -> array), then remove the least recently used beyond :data:`CACHE_BYTES`."""
        if self.folder is None or not values:
            return
        try:
            for key, a in values.items():
                tmp = os.path.join(self.folder, f".{key}.{os.getpid()}.npy")
                np.save(tmp, a)
                os.replace(tmp, os.path.join(self.folder, key + ".npy"))
            kept = [(e.stat().st_mtime, e.stat().st_size, e.path) for e in os.scandir(self.folder)
                    if e.name.endswith(".npy") and not e.name.startswith(".")]
            total = sum(s for _, s, _ in kept)
            for _, size, path in sorted(kept):
                if total <= CACHE_BYTES:
                    break
                try:
                    os.remove(path)
                except FileNotFoundError:             # another Blender removed it first
                    pass
                total -= size
        except OSError as e:
            print(f"raybundle: graph bakes are not kept on disk ({e})", file=sys.stderr)
