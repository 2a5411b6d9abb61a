"""An evaluated Blender mesh read into arrays: positions, loop triangles, corners, materials,
shading normals, and the UVs, images and color attributes its materials' textures read.

Everything is read with ``foreach_get`` (``attributes["position"]``, ``.corner_vert``,
``loop_triangle_polygons``, the ``material_index`` attribute, ``corner_normals``).
"""
from __future__ import annotations

import numpy as np


def mesh_arrays(me):
    """Local arrays of an evaluated mesh: positions (V, 3) f32, triangle corners
    (T, 3) i32 (vertex ids), loops (T, 3) i32, triangle -> polygon (T,) i32,
    polygon material index (P,) i32, corner normals (L, 3) f32 (Blender's shading normals:
    smooth, auto smooth and custom normals; None where the API lacks them)."""
    nv = len(me.vertices)
    pos = np.empty(nv * 3, np.float32)
    pa = me.attributes.get("position")
    if pa is not None:
        pa.data.foreach_get("vector", pos)
    else:
        me.vertices.foreach_get("co", pos)
    nt = len(me.loop_triangles)
    loops = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    cv_attr = me.attributes.get(".corner_vert")
    if cv_attr is not None:
        cv = np.empty(len(me.loops), np.int32)
        cv_attr.data.foreach_get("value", cv)
        tri = cv[loops]
    else:
        tri = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
    tp = np.empty(nt, np.int32)
    me.loop_triangle_polygons.foreach_get("value", tp)
    mi_attr = me.attributes.get("material_index")
    if mi_attr is not None and mi_attr.domain == "FACE" and mi_attr.data_type == "INT":
        mi = np.empty(len(me.polygons), np.int32)
        mi_attr.data.foreach_get("value", mi)
    else:
        mi = np.zeros(len(me.polygons), np.int32)
    cn = None
    if hasattr(me, "corner_normals"):
        cn = np.empty(len(me.loops) * 3, np.float32)
        me.corner_normals.foreach_get("vector", cn)
        cn = cn.reshape(-1, 3)
    return pos.reshape(-1, 3), tri.reshape(-1, 3), loops.reshape(-1, 3), tp, mi, cn


def world_normals(n, M):
    """Normals ``n`` (..., 3) of an object with matrix ``M`` (4, 4) in world space, unit
    length: by the inverse transpose of its 3 x 3 part (a non-uniform scale tilts them)."""
    out = n @ np.linalg.pinv(M[:3, :3]).astype(np.float32)
    return out / np.maximum(np.linalg.norm(out, axis=-1, keepdims=True), 1e-30)


def texture_uvs(me, ob, slots, tri_poly, poly_mat, loops, converter, images, warn):
    """For an object whose materials have albedo textures (``converter.textures``), cut-outs
    (``converter.cutouts``) or normal maps (``converter.normal_maps``): ((T, 3, 2) corner UVs,
    (T,) image index into ``images`` (-1 untextured, -2 the corner colors), (T, 3, 3) corner
    colors of a color attribute, (T,) coverage map index into ``images`` (-1 opaque), (T,)
    normal map index into ``images`` (-1 none), (T,) bool: that map is a bump's), or None.
    ``images`` (key -> (index, bpy Image or :class:`.shaders.EvaluatedImage`, its kind:
    "albedo", "alpha" or "normal", read at the nearest texel)) grows as new images are met."""
    for m in slots:
        converter.convert(m)                  # (cached) fills converter.textures, .cutouts, .normal_maps
    tex = [converter.texture_of(ob, m) for m in slots] or [None]
    cut = [converter.cutouts.get(m.name_full) if m is not None else None for m in slots] or [None]
    nrm = [converter.normal_maps.get(m.name_full) if m is not None else None for m in slots] or [None]
    if not any(tex) and not any(cut) and not any(nrm):
        return None
    slot = np.clip(poly_mat[tri_poly], 0, len(tex) - 1)
    uv = np.zeros((len(loops), 3, 2))
    img = np.full(len(loops), -1, np.int64)
    alpha = np.full(len(loops), -1, np.int64)
    normal = np.full(len(loops), -1, np.int64)
    bump = np.zeros(len(loops), bool)
    colors = np.zeros((len(loops), 3, 3))
    layers = {}

    def read_uv(name, what, sel, k):
        layer = (me.uv_layers.get(name) if name else
                 next((l for l in me.uv_layers if l.active_render), me.uv_layers.active))
        if layer is None:
            warn(f"object {ob.name!r}: material {slots[k].name!r} has {what} but the mesh has no UV "
                 f"map{' ' + repr(name) if name else ''}: {'its mean color is used' if 'image' in what else 'opaque'}")
            return False
        if layer.name not in layers:
            a = np.empty(2 * len(me.loops), np.float32)
            layer.uv.foreach_get("vector", a)
            layers[layer.name] = a.reshape(-1, 2)
        uv[sel] = layers[layer.name][loops[sel]]
        return True

    for k, (got, cover, nmap) in enumerate(zip(tex, cut, nrm)):
        sel = np.nonzero(slot == k)[0]
        if len(sel) == 0:
            continue
        read = None                               # the UV map this slot's faces hold
        if got is not None and got.attribute is not None:
            colors[sel] = corner_colors(me, got.attribute, ob, slots[k], warn)[loops[sel]]
            img[sel] = -2
        elif got is not None and read_uv(got.uv, f"the image texture {got.image.name!r}", sel, k):
            img[sel] = images.setdefault((got.image.name_full, got.closest, got.extend),
                                         (len(images), got.image, "albedo", got.closest, got.extend))[0]
            read = got.uv
        for what, m, label in (("alpha", cover, "cut-out (Alpha)"), ("normal", nmap, "normal or bump map")):
            if m is None:
                continue
            if m.uv is not None:                  # a map: through the UVs read already, or its own
                if read is not None and read != m.uv:
                    warn(f"object {ob.name!r}: material {slots[k].name!r} reads its {label} through another UV map "
                         f"than its albedo or cut-out: the first one's ({read or 'the active one'}) is used for all")
                elif read is None:
                    if not read_uv(m.uv, f"a {label}", sel, k):
                        continue
                    read = m.uv
            index = images.setdefault((what, m.image.name_full), (len(images), m.image, what, False, False))[0]
            if what == "alpha":
                alpha[sel] = index
            else:
                normal[sel], bump[sel] = index, m.bump
    if np.all(img == -1) and np.all(alpha == -1) and np.all(normal == -1):
        return None
    return uv, img, colors, alpha, normal, bump


def corner_colors(me, name, ob, mat, warn):
    """(corners, 3) linear RGB of color attribute ``name`` ("" = the active render one) of
    mesh ``me`` per face corner; black, warned, when the mesh does not have it (as Cycles)."""
    ca = me.color_attributes
    attr = ca.get(name) if name else (ca[ca.render_color_index] if len(ca) and ca.render_color_index >= 0 else None)
    if attr is None or attr.domain not in ("POINT", "CORNER"):
        warn(f"object {ob.name!r}: material {mat.name!r} reads the color attribute {name or '(active)'!r}, which "
             "the mesh does not have: black, as in Cycles")
        return np.zeros((len(me.loops), 3))
    vals = np.empty(4 * len(attr.data), np.float32)
    attr.data.foreach_get("color", vals)             # linear for byte and float colors alike
    vals = vals.reshape(-1, 4)[:, :3].astype(float)
    if attr.domain == "CORNER":
        return vals
    return vals[corner_vertices(me)]


def corner_vertices(me):
    """(corners,) int32: the vertex of each face corner of mesh ``me`` (the fast hidden
    ``.corner_vert`` attribute, else the loops)."""
    cv = np.empty(len(me.loops), np.int32)
    attr = me.attributes.get(".corner_vert")
    if attr is not None:
        attr.data.foreach_get("value", cv)
    else:
        me.loops.foreach_get("vertex_index", cv)
    return cv
