"""Invariance bench: the Cornell ``.blend`` described in many ways a Blender user would, each
exported by the add-on and solved by the core against the file as it is (``tools/invariance.py``).

Usage (the bpy module is in the project's venv; about 10 minutes on 2 cores)::

    python tools/bench_invariance.py --out out/bench-invariance [--batches 20] [--per-batch 16]

Cases, each a change made with ``bpy``/``bmesh`` to ``demo_scenes/cornell_box.blend``:
every mesh subdivided 2, 4, 16 and 64 times (Subdivide, 1, 3, 15 and 63 cuts);
triangulated; normals flipped; every face its own object; all meshes joined into one; the
short block an instance (a linked duplicate of a new block) against a real copy;
object transforms applied into the meshes; the whole scene scaled by 100 and by 0.01 (lamp
powers in W by the square of the factor; mesh emission, sun and world strengths unchanged);
the objects renamed into the reverse order.  For each: the region means' differences in
standard errors and percent, and ``b``, the spread between two layouts of the unmodified
file (4,000 and 4,400 patches) beyond their noise.  Then the patch count as a convergence:
region means at 500 ... 64,000 patches against the 64,000 value.

Writes ``invariance.csv``, ``summary.json`` and ``summary.md`` into ``--out``.  With
``--images SECONDS``: the issue's own table instead, images through the add-on's command line
(the file and copies subdivided 2, 4, 8 and 16 times, wall by wall), ``images.json``.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time

from raybundle.app.bench_page import add_page_argument, checked_page, command_line, table, write_section

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLEND = os.path.join(_ROOT, "demo_scenes", "cornell_box.blend")


def _open():
    import bpy

    bpy.ops.wm.open_mainfile(filepath=BLEND)
    return bpy


def _meshes(bpy):
    return [ob for ob in bpy.data.objects if ob.type == "MESH"]


def _bmesh_all(bpy, fn):
    import bmesh

    done = set()
    for ob in _meshes(bpy):
        if ob.data.name in done:
            continue
        done.add(ob.data.name)
        bm = bmesh.new()
        bm.from_mesh(ob.data)
        fn(bmesh, bm)
        bm.to_mesh(ob.data)
        bm.free()


def subdivide(cuts):
    def case(bpy):
        _bmesh_all(bpy, lambda bmesh, bm: bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=cuts,
                                                                    use_grid_fill=True))
    return case


def triangulate(bpy):
    _bmesh_all(bpy, lambda bmesh, bm: bmesh.ops.triangulate(bm, faces=bm.faces[:]))


def flip(bpy):
    _bmesh_all(bpy, lambda bmesh, bm: bmesh.ops.reverse_faces(bm, faces=bm.faces[:]))


def _world_polygons(ob):
    import numpy as np

    m = np.array(ob.matrix_world)
    v = np.array([(m @ np.array([*p.co, 1.0]))[:3] for p in ob.data.vertices])
    return v, [(list(p.vertices), p.material_index) for p in ob.data.polygons]


def _new_object(bpy, name, verts, faces, materials):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, x)) for x in verts], [], [f for f, _ in faces])
    for mat in materials:
        me.materials.append(mat)
    for poly, (_, mi) in zip(me.polygons, faces):
        poly.material_index = mi
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def split(bpy):
    """Every face its own object (world-space vertices, identity transforms)."""
    for ob in _meshes(bpy):
        v, faces = _world_polygons(ob)
        mats = [s.material for s in ob.material_slots]
        for k, (f, mi) in enumerate(faces):
            _new_object(bpy, f"{ob.name}.{k}", v[f], [(list(range(len(f))), mi)], mats)
        bpy.data.objects.remove(ob)


def join(bpy):
    """All meshes one object (its material slots the union of theirs)."""
    verts, faces, mats = [], [], []
    for ob in _meshes(bpy):
        v, fs = _world_polygons(ob)
        slot = {}
        for k, s in enumerate(ob.material_slots):
            if s.material not in mats:
                mats.append(s.material)
            slot[k] = mats.index(s.material)
        base = sum(len(x) for x in verts)
        verts.append(v)
        faces += [([base + i for i in f], slot.get(mi, 0)) for f, mi in fs]
        bpy.data.objects.remove(ob)
    import numpy as np

    _new_object(bpy, "joined", np.concatenate(verts), faces, mats)


def _extra_block(bpy, instanced):
    """A second, half-size short block beside the first: instanced from a collection by an
    Empty (Blender's instancing: the depsgraph's instance path) or a real copy placed there."""
    import mathutils

    src = bpy.data.objects["short_block"]
    ob = src.copy()
    ob.data = src.data.copy()
    ob.scale = (0.5, 0.5, 0.5)
    shift = mathutils.Matrix.Translation((-0.2 if src.location.x > 0 else 0.2, 0.0, 0.0))
    if instanced:
        coll = bpy.data.collections.new("extra_block")
        coll.objects.link(ob)
        empty = bpy.data.objects.new("extra_block_instance", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", coll
        empty.matrix_world = shift
        bpy.context.scene.collection.objects.link(empty)
    else:
        bpy.context.scene.collection.objects.link(ob)
        bpy.context.view_layer.update()
        ob.matrix_world = shift @ ob.matrix_world


def instance(bpy):
    _extra_block(bpy, True)


def copy(bpy):
    _extra_block(bpy, False)


def apply_transforms(bpy):
    import mathutils

    for ob in _meshes(bpy):
        if ob.data.users > 1:
            ob.data = ob.data.copy()
        ob.data.transform(ob.matrix_world)
        ob.matrix_world = mathutils.Matrix.Identity(4)


def scale(factor):
    def case(bpy):
        import mathutils

        s = mathutils.Matrix.Scale(factor, 4)
        for ob in bpy.data.objects:
            if ob.parent is None:
                ob.matrix_world = s @ ob.matrix_world
            if ob.type == "LIGHT" and ob.data.type in ("POINT", "SPOT", "AREA"):
                ob.data.energy *= factor ** 2
            if ob.type == "CAMERA":
                ob.data.clip_start *= factor
                ob.data.clip_end *= factor
    return case


def reorder(bpy):
    """Objects renamed into the reverse order, and every mesh's vertices and faces reversed."""
    obs = sorted(bpy.data.objects, key=lambda o: o.name)
    for k, ob in enumerate(reversed(obs)):
        ob.name = f"{k:02d}_{ob.name}"
    for ob in _meshes(bpy):
        me = ob.data
        n = len(me.vertices)
        verts = [tuple(me.vertices[n - 1 - i].co) for i in range(n)]
        faces = [[n - 1 - i for i in p.vertices] for p in reversed(me.polygons)]
        mats = [p.material_index for p in reversed(me.polygons)]
        me.clear_geometry()
        me.from_pydata(verts, [], faces)
        for poly, mi in zip(me.polygons, mats):
            poly.material_index = mi
        me.update()


CASES = {"subdivide 2x": subdivide(1), "subdivide 4x": subdivide(3), "subdivide 16x": subdivide(15),
         "subdivide 64x": subdivide(63), "triangulate": triangulate, "flip normals": flip,
         "split into faces": split, "join into one": join, "apply transforms": apply_transforms,
         "scale x100": scale(100.0), "scale x0.01": scale(0.01), "reorder": reorder}
#: pairs compared with each other rather than with the file as it is
PAIRS = {"instance vs copy": (copy, instance)}


def exported(case=None):
    from raybundle_addon.translation.export import export_scene

    bpy = _open()
    if case is not None:
        case(bpy)
    return export_scene(bpy.context.evaluated_depsgraph_get()).scene


def images(seconds, cuts, out, seeds=(1, 2)):
    """The issue's table: the file and copies of it subdivided ``cuts`` times rendered by the
    add-on's command line (``seconds`` each, Patches 4,000, ``seeds`` averaged); the mean of
    each wall's pixels (its object's pixels, eroded 2 px) against the file's."""
    import subprocess

    import numpy as np
    from addon_helpers import erode, object_id_image

    from raybundle.util.io import read_exr
    from raybundle_addon.translation.export import export_scene

    bpy = _open()
    ex = export_scene(bpy.context.evaluated_depsgraph_get())
    names = [o.original for o in ex.objects]
    walls = ("floor", "ceiling", "back", "red", "green")
    masks = {w: erode(object_id_image(ex) == names.index(w), 2) for w in walls}
    files = [("as it is", BLEND)]
    for c in cuts:
        path = os.path.join(out, f"cornell_box-{c + 1}x.blend")
        bpy = _open()
        subdivide(c)(bpy)
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path))
        files.append((f"subdivided {c + 1}x", path))
    base, rows = None, []
    for label, path in files:
        means = []
        for seed in seeds:
            exr = os.path.join(out, f"image-{seed}.exr")
            subprocess.run([os.path.join(os.path.dirname(sys.executable), "raybundle-blender"), path, "--time",
                            str(seconds), "--seed", str(seed), "--patches", "4000", "--out", exr],
                           check=True, capture_output=True, cwd=_ROOT)
            img = read_exr(exr).mean(axis=2)
            means.append([img[masks[w]].mean() for w in walls])
        m = np.mean(means, axis=0)
        base = m if base is None else base
        rows.append({"file": label, **{w: round(100 * float(x / b - 1), 2) for w, x, b in zip(walls, m, base)},
                     "seed_spread_pct": round(float(100 * np.max(np.abs(np.subtract(*means[:2])) / m)), 2)})
        print(f"{label:16s} " + " ".join(f"{w} {rows[-1][w]:+.1f}%" for w in walls)
              + f"  (seeds differ by up to {rows[-1]['seed_spread_pct']:.1f}%)", flush=True)
    with open(os.path.join(out, "images.json"), "w") as f:
        json.dump(rows, f, indent=2)
    return 0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="out/bench-invariance")
    p.add_argument("--batches", type=int, default=20)
    p.add_argument("--per-batch", type=int, default=16)
    p.add_argument("--patches", type=int, default=4000)
    p.add_argument("--convergence", type=int, nargs="*", default=[500, 1000, 2000, 4000, 8000, 16000, 32000, 64000])
    p.add_argument("--images", type=float, metavar="SECONDS",
                   help="instead: the file and copies subdivided 2, 4, 8 and 16 times rendered for SECONDS each "
                        "through the add-on's command line, wall by wall (images.json)")
    p.add_argument("--cases", nargs="+", metavar="CASE", help="only these cases (default: all)")
    add_page_argument(p, "invariance")
    a = p.parse_args(argv)
    checked_page(a.page, "bench_invariance")
    sys.path.insert(0, _ROOT)
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    sys.path.insert(0, os.path.join(_ROOT, "tests"))
    import numpy as np
    from invariance import REGIONS, compare, region_batches

    import raybundle_addon

    raybundle_addon.register()
    os.makedirs(a.out, exist_ok=True)
    if a.images:
        return images(a.images, (1, 3, 7, 15), a.out)
    kw = dict(batches=a.batches, per_batch=a.per_batch)
    t0 = time.perf_counter()
    plain = exported()
    base = region_batches(plain, a.patches, **kw)
    d, se = compare(base, region_batches(plain, int(a.patches * 1.1), **kw))
    b = float(np.maximum(np.abs(d) - 2 * se, 0).max())
    print(f"b = {100 * b:.2f}% (4,000 against 4,400 patches: {np.round(100 * d, 2).tolist()} %, "
          f"SE {np.round(100 * se, 2).tolist()} %)", flush=True)
    rows = []

    def report(name, ref, other, triangles):
        d, se = compare(ref, other)
        z = np.abs(d) / np.maximum(se, 1e-12)
        ok = bool(np.all(np.abs(d) <= 4.5 * se + b))
        rows.append({"case": name, "triangles": triangles, "pass": ok, "max_sigma": float(z.max()),
                     **{f"{r}_pct": round(100 * x, 3) for r, x in zip(REGIONS, d)},
                     **{f"{r}_se_pct": round(100 * s, 3) for r, s in zip(REGIONS, se)}})
        print(f"{name:18s} {'pass' if ok else 'FAIL'}  max |d| {z.max():4.1f} SE  "
              + " ".join(f"{r} {100 * x:+.2f}%" for r, x in zip(REGIONS, d)) + f"  ({triangles:,} triangles)",
              flush=True)

    chosen = set(a.cases or [*CASES, *PAIRS])
    unknown = chosen - {*CASES, *PAIRS}
    if unknown:
        p.error(f"unknown case {sorted(unknown)[0]!r}; choose from {', '.join([*CASES, *PAIRS])}")
    for name, case in CASES.items():
        if name not in chosen:
            continue
        sc = exported(case)
        report(name, base, region_batches(sc, a.patches, **kw), len(sc.triangles))
    for name, (first, second) in PAIRS.items():
        if name not in chosen:
            continue
        one = exported(first)
        report(name, region_batches(one, a.patches, **kw), region_batches(exported(second), a.patches, **kw),
               len(one.triangles))
    conv = {n: region_batches(plain, n, **kw).mean(axis=0) for n in a.convergence}
    top = conv[max(conv)]
    convergence = [{"patches": n, **{r: round(100 * float(m / t - 1), 3) for r, m, t in zip(REGIONS, conv[n], top)}}
                   for n in sorted(conv)]
    for c in convergence:
        print(f"{c['patches']:6d} patches: " + " ".join(f"{r} {c[r]:+.2f}%" for r in REGIONS), flush=True)
    with open(os.path.join(a.out, "invariance.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    summary = {"b": b, "patches": a.patches, "batches": a.batches, "per_batch": a.per_batch, "cases": rows,
               "convergence": convergence, "seconds": round(time.perf_counter() - t0, 1)}
    with open(os.path.join(a.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    text = (f"b = {100 * b:.2f}%; pass: every region within 4.5 SE + b\n\n"
            + table(["case", "triangles", "", "max SE", *REGIONS],
                    [(r["case"], f"{r['triangles']:,}", "pass" if r["pass"] else "FAIL", f"{r['max_sigma']:.1f}",
                      *(f"{r[f'{x}_pct']:+.2f}%" for x in REGIONS)) for r in rows])
            + "\n" + table(["patches", *REGIONS],
                            [(f"{c['patches']:,}", *(f"{c[r]:+.2f}%" for r in REGIONS)) for c in convergence]))
    with open(os.path.join(a.out, "summary.md"), "w") as f:
        f.write(text)
    print(f"wrote {a.out}/invariance.csv, summary.json, summary.md ({time.perf_counter() - t0:.0f} s)")
    if a.page:
        write_section(a.page, a.section or "invariance", "Invariance: the same box described in other ways",
                      "`demo_scenes/cornell_box.blend` changed as a Blender user would (subdivided, triangulated, "
                      "flipped, split, joined, instanced, transforms applied, scaled, renamed), each exported by the "
                      f"add-on and solved by the core with {a.patches:,} patches ({a.batches} batches of "
                      f"{a.per_batch} iterations). Each region's mean against the file as it is; `b` is the spread "
                      "of two layouts of the unchanged file beyond their noise. Then the patch count's convergence: "
                      "region means against the largest count's.\n\n" + text,
                      command=command_line("tools/bench_invariance.py", argv))
        print(f"wrote its section of {a.page}")
    return 0 if all(r["pass"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
