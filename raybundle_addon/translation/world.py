"""A Blender World as the core's :class:`raybundle.scene.world.World`, evaluated by Blender.

A world whose Background reads plain values (a color and a strength, or an RGB node) is a
constant world, read directly.  Any other node tree (an Environment Texture with its
Mapping and Texture Coordinate, a Sky Texture, gradients, Mix trees) is rendered by Cycles
into an equirectangular image, ``EQUIRECT_WIDTH`` x ``EQUIRECT_WIDTH / 2`` pixels at
``EQUIRECT_SAMPLES`` samples each (:mod:`.world_render`, in a process of its own: a render
cannot start another render in the same process), so nothing of the node tree is
reimplemented here.  Through a perspective camera the same process renders the world once
more through that camera, at the render's size, each pixel the mean over its area as
raybundle's own pixels are (:attr:`raybundle.scene.world.World.view`): what the camera sees of the world through a
window is then Blender's own pixel, not a panorama's blur.  The images are kept on disk per
world, node tree and view (:mod:`.bake_cache`).  The render can run while the caller goes on
(:func:`start_world_export`: the F12 engine and bakes lay out their patches meanwhile).

What is not modelled, warned: the world's volume; a Light Path node (the world lights the
scene as the camera sees it); a failed evaluation falls back to the Background's own color.
"""
from __future__ import annotations

import os
import time

import numpy as np

from .bake_cache import BakeCache, cache_folder, library_digest, task_key
from .blender_process import BlenderProcess, BlenderProcessError, temporary_folder

#: width of the equirectangular image a node-tree world is rendered into (pixels; height half of it)
EQUIRECT_WIDTH = 512
#: Cycles samples per pixel of that image (a small sun is a sub-pixel disk: its pixel's mean needs many)
EQUIRECT_SAMPLES = 64
#: seconds before the world's render is given up
RENDER_TIMEOUT = 300.0
#: Cycles samples per pixel of the camera's view of the world, at most (fewer on large renders:
#: :data:`VIEW_SAMPLE_BUDGET` samples in all, at least 4 per pixel)
VIEW_SAMPLES = 64
VIEW_SAMPLE_BUDGET = 30_000_000
#: the view is rendered at this many times the render's resolution in each axis (fewer where
#: that would pass :data:`VIEW_MAX_PIXELS`), each pixel's samples shared out over its sub-pixels:
#: where a window bar covers part of a pixel, the camera rays that miss it read the sky beside
#: the bar, not the mean of the sky behind it too (:meth:`raybundle.scene.world.World.view_radiance`)
VIEW_SUPERSAMPLE = 4
VIEW_MAX_PIXELS = 4_000_000

class WorldRenderError(RuntimeError):
    """Blender could not render the world (one-line reason)."""


def export_world(world, warn, view=None):
    """The :class:`~raybundle.scene.world.World` of a bpy World (None: black); ``view``:
    :func:`camera_view`'s description of the render's camera, for :attr:`~raybundle.scene.world.World.view`."""
    return start_world_export(world, warn, view).finish()


def start_world_export(world, warn, view=None, threads=0):
    """:func:`export_world` begun: a :class:`PendingWorld` whose Blender render (for a world
    that needs one) runs in its own process, on ``threads`` CPU threads (0: all), while the
    caller goes on."""
    from raybundle.scene.world import World

    constant, fallback = _constant_radiance(world, warn)
    if constant is not None:
        return PendingWorld(World.constant(constant))
    try:
        job = start_world_render(world, view=None if view is None else view[0], threads=threads)
    except WorldRenderError as e:
        return PendingWorld(_fallen_back(world, fallback, e, warn))
    pending = PendingWorld(None, job, world.name, fallback, view, warn)
    if job.done:                                      # read from the disk: final at once
        pending.now = pending.finish()
    return pending


class PendingWorld:
    """A world being exported (:func:`start_world_export`): :attr:`now` is the world to build
    the scene with at once (the final one, or while Blender renders it a stand-in,
    :meth:`raybundle.scene.world.World.stand_in_for_render`); :meth:`finish` waits for the
    render and gives the final world (Blender's failure: the Background's color, warned);
    :meth:`cancel` stops the render."""

    def __init__(self, world, job=None, name=None, fallback=None, view=None, warn=None):
        from raybundle.scene.world import World

        self._world, self._job, self._name, self._fallback, self._view, self._warn = \
            world, job, name, fallback, view, warn
        self.now = world if job is None else World.stand_in_for_render()
        #: seconds :meth:`finish` waited for the render
        self.waited = 0.0

    def finish(self):
        from raybundle.scene.world import World

        if self._job is not None:
            t0 = time.perf_counter()
            try:
                image, seen = self._job.result()
                if seen is None:
                    self._world = World(image)
                else:
                    _, camera, (x0, y0, bw, bh), s = self._view
                    top = seen.shape[0] - s * (y0 + bh)         # the border counts rows from the bottom
                    self._world = World(image, view=seen[top:top + s * bh, s * x0:s * (x0 + bw)],
                                        view_camera=camera.with_resolution(s * bw, s * bh))
            except WorldRenderError as e:
                self._world = _fallen_back(self._name, self._fallback, e, self._warn)
            self._job = None
            self.waited = time.perf_counter() - t0
        return self._world

    @property
    def running(self):
        """Whether Blender's render is still to be waited for."""
        return self._job is not None

    def cancel(self):
        if self._job is not None:
            self._job.cancel()
            self._job = None


def _fallen_back(name, fallback, error, warn):
    from raybundle.scene.materials import color_text
    from raybundle.scene.world import World

    name = getattr(name, "name", name)
    warn(f"world {name!r}: Blender could not evaluate it ({error}); using its Background color "
         f"{color_text(fallback)} from every direction")
    return World.constant(fallback)


def _constant_radiance(world, warn):
    """``(radiance, fallback)``: (3,) radiance when the world is the same from every
    direction and is read without Blender's help (radiance None otherwise); ``fallback``
    the Background's own color x strength."""
    from .node_links import follow_reroutes

    black = np.zeros(3)
    if world is None:
        return black, black
    nt = world.node_tree
    if nt is None:
        color = np.array(world.color[:3], float)
        return color, color
    out = nt.get_output_node("CYCLES") or nt.get_output_node("ALL")
    if out is not None and "Volume" in out.inputs and out.inputs["Volume"].is_linked:
        warn(f"world {world.name!r}: its volume (fog, atmosphere) is not modeled: the scene is rendered "
             "without it")
    if out is None or not out.inputs["Surface"].is_linked:
        return black, black
    if any(n.type == "LIGHT_PATH" for n in nt.nodes):
        warn(f"world {world.name!r}: a Light Path node may make what the camera sees differ from what "
             "lights the scene; the scene is lit by the world as the camera sees it")
    node = follow_reroutes(out.inputs["Surface"].links[0].from_node)
    if node is None:
        return black, black
    if node.type != "BACKGROUND":
        return None, np.array(world.color[:3], float)
    color_sock, strength_sock = node.inputs["Color"], node.inputs["Strength"]
    color = np.array(color_sock.default_value[:3], float)
    strength = max(float(strength_sock.default_value), 0.0)
    fallback = color * strength
    if strength_sock.is_linked:
        return None, fallback
    if color_sock.is_linked:
        src = follow_reroutes(color_sock.links[0].from_node)
        if src is None or src.type != "RGB":
            return None, fallback
        color = np.array(src.outputs[0].default_value[:3], float)
    return color * strength, color * strength


def camera_view(cam_ob, render, size, camera, border):
    """What :mod:`.world_render` needs to render the world through the perspective camera
    object ``cam_ob`` (evaluated) as ``render`` renders it at ``size`` (W, H) pixels, with the
    exported ``camera`` (:class:`~raybundle.scene.camera.Camera`) and render ``border``
    (x0, y0, w, h) or None, at
    ``s`` times the render's resolution (:data:`VIEW_SUPERSAMPLE`): ``(params, camera, border,
    s)``; None for other cameras (an orthographic one sees one direction of the world)."""
    if cam_ob is None or camera is None or cam_ob.data.type != "PERSP":
        return None
    cd = cam_ob.data
    w, h = size
    s = next((s for s in range(VIEW_SUPERSAMPLE, 1, -1) if s * s * w * h <= VIEW_MAX_PIXELS), 1)
    per_pixel = max(4, min(VIEW_SAMPLES, VIEW_SAMPLE_BUDGET // (w * h)))
    params = dict(matrix=[x for row in cam_ob.matrix_world for x in row], type=cd.type, lens=cd.lens,
                  sensor_width=cd.sensor_width, sensor_height=cd.sensor_height, sensor_fit=cd.sensor_fit,
                  shift_x=cd.shift_x, shift_y=cd.shift_y, ortho_scale=cd.ortho_scale, size=[s * w, s * h],
                  pixel_aspect=[render.pixel_aspect_x, render.pixel_aspect_y],
                  samples=int(max(1, per_pixel // (s * s))))
    return params, camera, border or (0, 0, w, h), s


def render_world(world, width=EQUIRECT_WIDTH, samples=EQUIRECT_SAMPLES, view=None):
    """``(image, seen)``: (width / 2, width, 3) float32 equirectangular radiance of the bpy World
    ``world`` (:mod:`raybundle.scene.world`'s layout), rendered by Cycles in a separate process,
    and with ``view`` (:func:`camera_view`'s parameters) the (h, w, 3) world that camera's
    pixels see (None without).  Raises :class:`WorldRenderError`."""
    return start_world_render(world, width, samples, view).result()


def start_world_render(world, width=EQUIRECT_WIDTH, samples=EQUIRECT_SAMPLES, view=None, threads=0):
    """:func:`render_world` begun in its own process, on ``threads`` CPU threads (0: all): a
    :class:`WorldRender` (its ``result()`` waits).  A world rendered before (the same node tree
    and view) is read from the disk (:mod:`.bake_cache`)."""
    import json

    tmp = temporary_folder("raybundle-world-")
    library = os.path.join(tmp.name, "world.blend")
    cache = BakeCache(cache_folder())
    try:
        key = task_key(dict(world=world.name_full, width=int(width), samples=int(samples), view=view),
                       [library_digest([world], library)])
    except (RuntimeError, OSError) as e:
        tmp.cleanup()
        raise WorldRenderError(f"writing it failed: {e}") from None
    kept = cache.load(key + "-world", (int(width) // 2, int(width)))
    seen = cache.load(key + "-view", view["size"][::-1]) if view is not None else None
    if kept is not None and (view is None or seen is not None):
        tmp.cleanup()
        return WorldRender(key, result=(kept, seen))
    out = os.path.join(tmp.name, "world.exr")
    args = [library, world.name, out, str(int(width)), str(int(samples)), str(int(threads))]
    seen = None
    if view is not None:
        seen = os.path.join(tmp.name, "view.exr")
        args.append(os.path.join(tmp.name, "view.json"))
        with open(args[-1], "w") as f:
            json.dump(dict(view, out=seen), f)
    # on all threads at a lower priority: it takes the cores the patches' layout leaves idle and
    # leaves the layout its own (on one thread the living room's set-up waited 3.5-4 s for it at
    # the end; at the same priority the dining room's layout took 2 s longer)
    try:
        proc = BlenderProcess("world_render.py", args, tmp, RENDER_TIMEOUT, lowest=True)
    except BlenderProcessError as e:
        raise WorldRenderError(str(e)) from None
    return WorldRender(key, proc, out, seen, cache=cache)


class WorldRender:
    """A render of a world under way (:func:`start_world_render`), or one already known."""

    def __init__(self, key, proc=None, out=None, seen=None, result=None, cache=None):
        self.key, self._proc, self._out, self._seen, self._result = key, proc, out, seen, result
        self._cache = cache

    @property
    def done(self):
        """Whether :meth:`result` has its images without waiting."""
        return self._result is not None

    def result(self):
        """``(image, seen)`` as :func:`render_world` returns them, once the render is done
        (at most :data:`RENDER_TIMEOUT` seconds after it started).  Raises :class:`WorldRenderError`."""
        from raybundle.util.io import read_exr

        if self._result is not None:
            return self._result
        paths = [self._out] + ([self._seen] if self._seen is not None else [])
        try:
            self._proc.wait(paths)
            images = [_radiance(read_exr(p)) for p in paths]
        except BlenderProcessError as e:
            raise WorldRenderError(f"its render failed: {e}") from None
        finally:
            self._proc.close()
        self._result = (images[0], images[1] if self._seen is not None else None)
        self._cache.store({self.key + "-world": images[0], **({self.key + "-view": images[1]} if len(images) > 1 else {})})
        return self._result

    def cancel(self):
        """Stop the render (a cancelled or failed export) and remove its files."""
        if self._proc is not None:
            self._proc.close()


def _radiance(img):
    """(H, W, 3) float32 radiance of an EXR's pixels: finite, non-negative."""
    img = img[..., :3].astype(np.float32)
    if not np.isfinite(img).all():
        img = np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0)
    return np.maximum(img, 0.0)
