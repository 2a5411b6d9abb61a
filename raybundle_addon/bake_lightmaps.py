"""A bake's lightmaps (:mod:`.bake`): the meshes to bake with their active UV maps, then, after the
budget, one lightmap at a time: its texels located and lit directly over their footprints, the
texels next to concave edges and contacts gathered in blocks
(:class:`raybundle.imaging.lightmap.TexelGather`), and its image.  A stop keeps the texels gathered
so far and interpolates the rest, and the lightmaps not begun (warned)."""
from __future__ import annotations

import bpy
import numpy as np

from .properties import FIXED_GATHER_RAYS


class LightmapBake:
    """The lightmaps of bake ``job`` (a :class:`.bake.BakeJob`: its export, solver, settings and
    warnings).  :attr:`targets`: ``(export object entry, UV triangles (T, 3, 2), UV map name)``."""

    def __init__(self, job):
        self.job = job
        self.targets = []
        #: the lightmap being gathered: ``(target, TexelGather)``; those done: ``(target, image)``; the next
        self._texels, self._images, self._next = None, [], 0
        self._edges = self._rng = None

    def pick(self, objects=None):
        """The targets: each mesh object rendered (of ``objects``, names; None: all) with a UV map."""
        job, seen = self.job, set()
        for info in job.export.objects:
            if info.is_instance or info.original in seen:
                continue
            if objects is not None and info.original not in objects:
                continue
            seen.add(info.original)
            ob = bpy.data.objects.get(info.original)
            if ob is None:
                continue
            ev = ob.evaluated_get(job.depsgraph)
            me = ev.data if ev.type == "MESH" else None
            layer = me.uv_layers.active if me is not None else None
            if layer is None or len(me.loops) != info.n_loops:
                job.warn(f"object {info.original!r} has no UV map: no lightmap (add one, e.g. UV > Smart UV "
                         "Project or Lightmap Pack)")
                continue
            uv = np.empty(2 * info.n_loops, np.float32)
            layer.uv.foreach_get("vector", uv)
            tri = np.arange(info.first_triangle, info.first_triangle + info.n_triangles)
            loops = job.export.triangle_loops[tri]
            self.targets.append((info, uv.reshape(-1, 2)[loops].astype(float), layer.name))
        for name in sorted(set(objects or ()) - seen):
            ob = bpy.data.objects.get(name)
            if ob is not None and ob.type == "MESH":
                job.warn(f"object {name!r} is not rendered (hidden or excluded): no lightmap")

    @property
    def done(self):
        """Lightmaps done, with the share of the current one's texels gathered."""
        return self._next - 1 + self._texels[1].gather.fraction if self._texels else float(self._next)

    @property
    def phase(self):
        """The progress display's text while a lightmap is gathered, else None."""
        if self._texels is None:
            return None
        (info, _, _), work = self._texels
        g = work.gather
        return (f"lightmap {self._next} of {len(self.targets)} ({info.original}): gathering {g.gathered:,} of "
                f"{len(g.todo):,} texels by edges, {g.rays:,} rays each")

    def rays(self):
        """Gather rays per vertex-like point: Gather Rays, or :data:`~.properties.FIXED_GATHER_RAYS` when
        automatic (lightmaps are baked after the budget)."""
        rays = self.job.bake.gather_rays
        return FIXED_GATHER_RAYS if rays < 0 else rays

    def step(self, budget):
        """Gather the current lightmap's texels for about ``budget`` seconds, or finish it and set up
        the next; False once every lightmap is done."""
        margin = self.job.bake.lightmap_margin
        if self._texels is not None:
            target, work = self._texels
            if not work.gather.done:
                work.gather.advance(budget)
                return True
            self._images.append((target, work.image(margin).astype(np.float32)))
            self._texels = None
        if self._next >= len(self.targets):
            return False
        self._next += 1
        self._texels = self._texel_gather(self._next - 1, self.rays())
        return True

    def images(self):
        """``(target, image)`` of each lightmap: those done, the one being gathered with the texels
        gathered so far, then those not begun, interpolated (a stop before the lightmaps ended,
        warned)."""
        job, margin = self.job, self.job.bake.lightmap_margin
        yield from self._images
        if self._texels is not None:
            target, work = self._texels
            g = work.gather
            if not g.done:
                job.warn(f"stopped: lightmap of {target[0].original!r} with {g.gathered:,} of {len(g.todo):,} "
                         "texels by edges gathered, the rest interpolated from the patches")
            yield target, work.image(margin)
        rest = range(self._next, len(self.targets))
        if rest and self.rays():
            job.warn("stopped: the lightmaps of " + ", ".join(repr(self.targets[k][0].original) for k in rest)
                     + " interpolated from the patches (no gather by edges)")
        for k in rest:
            got = self._texel_gather(k, 0)
            if got is not None:
                yield got[0], got[1].image(margin)

    def _texel_gather(self, k, rays):
        """Set up target ``k``'s texels (:class:`raybundle.imaging.lightmap.TexelGather`, ``rays``
        per vertex-like point, 0: interpolated): ``(target, work)``, or None (warned) when its UV map
        covers no texel."""
        from raybundle.imaging.baking import locate_points
        from raybundle.imaging.gather import EdgeGather
        from raybundle.imaging.lightmap import TexelGather, texel_footprints, texel_points

        job = self.job
        target = self.targets[k]
        info, uv, _ = target
        size = job.bake.lightmap_size
        tx = texel_points(uv, size, size)
        if tx.overlap:
            job.warn(f"object {info.original!r}: overlapping UV islands ({tx.overlap} texels claimed twice); "
                     "use a UV map without overlaps (e.g. Lightmap Pack) for lightmaps")
        if len(tx.texel) == 0:
            job.warn(f"object {info.original!r}: its UV map covers no texel centre of a {size}² lightmap; "
                     "no lightmap")
            return None
        seed, solver, ex = job.plan.settings.seed, job.solver, job.export
        if self._edges is None:
            self._edges = EdgeGather(solver.scene, solver.tracer, seed)
            self._rng = np.random.default_rng([seed, 21])
        pts = locate_points(ex.scene, solver.scene, solver.tracer, info.first_triangle + tx.triangle, tx.bary)
        # a million texels: a vertex's shadow rays find where a texel is lit, shadowed or in a penumbra,
        # but a penumbra takes 4 times as many, where a vertex takes 16 (CHANGELOG: 16 times everywhere took
        # 2 minutes on a 1024² floor; a quarter for the decision left penumbrae read as lit)
        n = job.bake.light_samples
        faces = info.first_triangle + np.arange(len(uv))
        work = TexelGather(solver, tx, pts, size, self._edges, rays, (seed, 22 + k), n, self._rng,
                           penumbra_samples=4 * n,
                           footprint=texel_footprints(ex.scene, faces, uv, tx, size, size), final=job.final_gather)
        return target, work
