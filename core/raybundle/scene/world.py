"""The world around the scene: radiance arriving from every direction, as Blender's World defines it.

``L_w(w)`` [W m^-2 sr^-1, linear RGB] is the radiance arriving at the scene from the
direction ``w`` (a unit vector from the scene towards the sky).  It is stored as an
equirectangular image in Blender's layout, the one a Cycles panoramic equirectangular
camera at rotation (90 deg, 0, -90 deg) renders and an Environment Texture reads:

    column u = 0.5 - atan2(w_y, w_x) / (2 pi)   (u = 0.5 looks along +X, u = 0.25 along +Y)
    row    v = acos(w_z) / pi                    (v = 0 is the zenith, the image's top row)

each pixel holding the mean radiance over its cell, whose solid angle is
``(2 pi / W) (cos theta_top - cos theta_bottom)``.  A constant world is a 1 x 1 image.

The add-on lets Blender evaluate the world's node tree into this image (an Environment
Texture with its Mapping, a Sky Texture, gradients, Mix trees); the core only looks it up.

A sun inside the image (a small region holding much of the world's power) is taken out of
the image the world lights with and handed to the lamps as a sun (:func:`split_sun`): the
first shot and the direct light at visible points then take it as they take a sun lamp,
with shadow rays, where bundles and gathers would meet it only by chance.  Camera rays
still see it (:attr:`World.camera_image`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: luminance weights of linear Rec. 709 RGB (Blender's default scene-linear space)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class World:
    """The world's radiance ``image`` (H, W, 3) [W m^-2 sr^-1] in the layout of the module
    docstring, the one bundles, gathers and paths that leave the scene read; and
    ``camera_image`` (same shape, or None for the same), the one camera rays see: it differs
    where a sun was taken out of ``image`` as a lamp (:func:`split_sun`); and ``view`` (h, w, 3)
    or None, what the scene's camera sees of the world pixel for pixel (Blender renders it
    through that camera, each pixel the mean over its area, at the camera's resolution or a
    multiple of it: :meth:`view_radiance`), sharper than any panorama can afford to be (a
    512-pixel panorama has 1.4 pixels per degree, a 320-pixel view 60 degrees wide 5.3)."""

    image: np.ndarray
    camera_image: np.ndarray | None = None
    view: np.ndarray | None = None
    #: the camera ``view`` was rendered through (a :class:`~raybundle.scene.camera.Camera`)
    view_camera: object = None
    #: a stand-in (:meth:`stand_in_for_render`) while the world's image is still being
    #: rendered: the layout and the method's choice take it as a world that lights the scene;
    #: nothing may read its light (:func:`~raybundle.scene.build.attach_world` replaces it)
    stand_in: bool = False

    def __post_init__(self):
        self.image = _checked(self.image, "world image")
        if self.view is not None:
            self.view = _checked(self.view, "world view")
            if self.view_camera is None or self.view.shape[:2] != (self.view_camera.height, self.view_camera.width):
                raise ValueError("the world's view needs the camera it was rendered through, of its size")
        if self.camera_image is not None:
            self.camera_image = _checked(self.camera_image, "world camera image")
            if self.camera_image.shape != self.image.shape:
                raise ValueError(f"the world's camera image {self.camera_image.shape} and image "
                                 f"{self.image.shape} differ in shape")

    @classmethod
    def constant(cls, rgb=(0.0, 0.0, 0.0)):
        """The world of one radiance ``rgb`` (3,) from every direction (Blender's world color x strength)."""
        return cls(np.broadcast_to(np.asarray(rgb, float), (3,)).reshape(1, 1, 3).copy())

    @classmethod
    def stand_in_for_render(cls):
        """A black stand-in (:attr:`stand_in`) for a world whose image is still being rendered."""
        return cls(np.zeros((1, 1, 3)), stand_in=True)

    @property
    def is_constant(self):
        return self.image.shape[:2] == (1, 1) and self.camera_image is None

    @property
    def emits(self):
        """The world sends light into the scene (its lighting image or a sun taken from it
        is not black; a world only the camera sees does not light)."""
        return self.stand_in or bool(np.any(self.image > 0))

    @property
    def seen(self):
        """The image camera rays see."""
        return self.image if self.camera_image is None else self.camera_image

    def pixel_solid_angles(self):
        """(H, 1) solid angle [sr] of one pixel in each row (all columns alike)."""
        h, w = self.image.shape[:2]
        z = np.cos(np.linspace(0.0, np.pi, h + 1))
        return ((z[:-1] - z[1:]) * (2.0 * np.pi / w))[:, None]

    def mean(self):
        """(3,) mean radiance over the sphere, ``(1 / 4 pi) integral L_w dw`` (the constant
        world that sends the same power into a closed scene)."""
        return np.einsum("hwc,hw->c", self.image, np.broadcast_to(self.pixel_solid_angles(), self.image.shape[:2])) \
            / (4.0 * np.pi)

    def radiance(self, directions, camera=False):
        """(N, 3) radiance arriving from the unit ``directions`` (N, 3) (from the scene
        towards the sky): the lighting image, or with ``camera`` the one camera rays see."""
        img = self.seen if camera else self.image
        d = np.asarray(directions, float).reshape(-1, 3)
        h, w = img.shape[:2]
        if h == 1 and w == 1:
            return np.broadcast_to(img[0, 0], (len(d), 3)).copy()
        return img[pixel_of(d, h, w)]

    def view_for(self, camera):
        """Whether :attr:`view` was rendered through ``camera``: the same pose and view, at
        the camera's resolution or a whole multiple of it (a finer view keeps the sky's
        detail inside a pixel: :meth:`view_radiance`)."""
        c = self.view_camera
        if self.view is None or camera is None or c.orthographic != camera.orthographic or \
                c.width % camera.width or c.height % camera.height or \
                c.width // camera.width != c.height // camera.height:
            return False
        same = camera.with_resolution(c.width, c.height)
        return bool(np.allclose([c.fx, c.fy, c.cx, c.cy], [same.fx, same.fy, same.cx, same.cy])
                    and np.allclose(c.matrix_world, camera.matrix_world))

    def view_pixel_means(self, camera):
        """(h * w, 3) the mean of :attr:`view` under each of the ``camera``'s pixel filters
        (row-major from the top left; :meth:`view_for` the camera): over the pixel for a box one
        pixel wide, else weighted by the filter (:meth:`~raybundle.scene.camera.Camera.filter_weights`,
        along x and y) over the view's sub-pixels it covers, normalised; beyond the image's edge
        the view's edge stands for the world there."""
        h, w = camera.height, camera.width
        s = self.view.shape[1] // w
        if camera.pixel_filter == "BOX" and camera.filter_width == 1.0:
            return self.view.reshape(h, s, w, s, 3).mean(axis=(1, 3)).reshape(-1, 3)
        r = int(np.ceil(camera.filter_margin))
        taps = np.arange(-r * s, (r + 1) * s)                 # sub-pixels from a pixel's first one
        weight = camera.filter_weights((taps + 0.5) / s - 0.5)
        keep = weight > 0
        taps, weight = taps[keep] + r * s, weight[keep] / weight[keep].sum()
        view = np.pad(self.view, ((r * s, r * s), (r * s, r * s), (0, 0)), mode="edge")
        start = np.arange(w) * s
        rows = sum(wk * view[:, start + k] for k, wk in zip(taps, weight))            # (H', w, 3)
        start = np.arange(h) * s
        return sum(wk * rows[start + k] for k, wk in zip(taps, weight)).reshape(-1, 3)

    def view_radiance(self, directions):
        """(N, 3) radiance of :attr:`view` along camera rays of unit ``directions`` (N, 3)
        (from the eye; :meth:`view_for` the camera): the view's pixel each passes through.
        With a view finer than the image, a pixel that a window bar partly covers reads the
        sky beside the bar, not the mean of the sky behind it."""
        c = self.view_camera
        eye = c.matrix_world[:3, 3]
        px, py = c.project(eye + np.asarray(directions, float))[:2]
        h, w = self.view.shape[:2]
        col = np.clip(np.floor(px), 0, w - 1).astype(np.int64)
        row = np.clip(np.floor(py), 0, h - 1).astype(np.int64)
        return self.view[row, col]

    def radiance_along(self, direction):
        """(2, 3): the radiance arriving travelling along +``direction`` (from the sky at
        ``-direction``) and along ``-direction`` (from ``+direction``), for a bundle of
        parallel lines (:mod:`raybundle.tracing.visibility`): one look-up per direction."""
        d = np.asarray(direction, float).reshape(3)
        return self.radiance(np.stack([-d, d]))

    def to_arrays(self):
        if self.stand_in:
            raise ValueError("the world is still being rendered: it has no image to save yet")
        d = {"world_image": self.image}
        if self.camera_image is not None:
            d["world_camera_image"] = self.camera_image
        if self.view is not None:
            d["world_view"] = self.view
            d.update(self.view_camera.to_arrays("world_view_camera_"))
        return d

    @classmethod
    def from_arrays(cls, d):
        """The world of a scene file: ``world_image`` (H, W, 3), or the older constant ``environment`` (3,)."""
        if d.get("world_image") is not None:
            view, camera = d.get("world_view"), None
            if view is not None:
                from .camera import Camera
                camera = Camera.from_arrays(d, "world_view_camera_")
            return cls(np.asarray(d["world_image"], float), d.get("world_camera_image"), view, camera)
        env = d.get("environment")
        return cls.constant(np.zeros(3) if env is None else env)


def _checked(image, what):
    a = np.asarray(image, float)
    if a.ndim == 1:
        a = np.broadcast_to(a, (3,)).reshape(1, 1, 3)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"the {what} must be (H, W, 3) radiance, got shape {a.shape}")
    if not np.isfinite(a).all() or (a < 0).any():
        raise ValueError(f"the {what}: the environment (world) radiance must be finite and non-negative")
    return np.ascontiguousarray(a)


def pixel_of(directions, h, w):
    """(row, column) index arrays of the pixels of an ``h`` x ``w`` equirectangular image
    (module docstring) that the unit ``directions`` (N, 3) fall in."""
    d = np.asarray(directions, float)
    u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * np.pi)
    v = np.arccos(np.clip(d[:, 2], -1.0, 1.0)) / np.pi
    col = np.floor(u * w).astype(np.int64) % w
    row = np.minimum(np.floor(v * h).astype(np.int64), h - 1)
    return row, col


def pixel_directions(h, w):
    """(h, w, 3) unit directions of the pixel centres of an equirectangular image."""
    v = (np.arange(h) + 0.5) / h * np.pi
    phi = np.pi * (1.0 - 2.0 * (np.arange(w) + 0.5) / w)
    st = np.sin(v)[:, None]
    return np.stack([st * np.cos(phi)[None], st * np.sin(phi)[None], np.broadcast_to(np.cos(v)[:, None], (h, w))],
                    axis=-1)


#: a sun is a region of pixels brighter than this many times the world's mean luminance ...
SUN_CONTRAST = 50.0
#: ... within this angle [rad] of the brightest pixel ...
SUN_RADIUS = np.radians(6.0)
#: ... that holds at least this share of the world's power on a plane facing it
SUN_SHARE = 0.1


def split_sun(world: World):
    """``(world, sun)``: a sun inside ``world``'s image taken out as a lamp, or ``(world, None)``.

    The sun is the region of pixels brighter than :data:`SUN_CONTRAST` times the mean
    luminance and within :data:`SUN_RADIUS` of the brightest pixel, when its excess over
    its surroundings carries at least :data:`SUN_SHARE` of the irradiance the whole world
    gives a plane facing it.  In the returned world's lighting image those pixels hold the
    mean radiance of the ring of pixels around the region, and ``sun`` is a dict of the
    lamp's ``direction`` (3,) (the light's travel direction, towards the scene),
    ``irradiance`` (3,) [W/m^2] ``= sum_p (L_p - L_ring) w_p`` over the region's pixels
    (``w_p`` their solid angles), and ``angle`` [rad], the angular diameter of a uniform disk
    with the region's radiance-weighted angular spread ``2 sqrt(2 <rho^2>)`` (a sun smaller
    than a pixel gets 0: a sharp shadow).  The world's power is unchanged: what leaves the
    image is the lamp's."""
    img = world.image
    h, w = img.shape[:2]
    if h < 4 or w < 8:
        return world, None
    omega = np.broadcast_to(world.pixel_solid_angles(), (h, w))
    lum = img @ LUMINANCE
    mean = float(np.sum(lum * omega) / (4.0 * np.pi))
    if mean <= 0:
        return world, None
    peak = np.unravel_index(np.argmax(lum), lum.shape)
    if lum[peak] < SUN_CONTRAST * mean:
        return world, None
    dirs = pixel_directions(h, w)
    toward = dirs[peak]
    near = dirs @ toward > np.cos(SUN_RADIUS)
    region = near & (lum > SUN_CONTRAST * mean)
    ring = near & ~region
    fill = (img[ring] * omega[ring, None]).sum(axis=0) / max(omega[ring].sum(), 1e-300) if ring.any() \
        else np.zeros(3)
    excess = np.maximum(img[region] - fill, 0.0) * omega[region, None]        # (R, 3) W/m^2 per pixel
    weight = excess @ LUMINANCE
    # the whole world's irradiance on a plane facing the sun
    cos = np.maximum(dirs @ toward, 0.0)
    facing = float(np.sum(lum * omega * cos))
    if weight.sum() < SUN_SHARE * facing:
        return world, None
    centre = (dirs[region] * weight[:, None]).sum(axis=0)
    centre /= np.linalg.norm(centre)
    rho2 = 2.0 * (1.0 - np.clip(dirs[region] @ centre, -1.0, 1.0))        # squared angle to the centre
    spread = float(np.sum(rho2 * weight) / weight.sum())
    irradiance = excess.sum(axis=0)
    light = img.copy()
    light[region] = fill
    sun = dict(direction=-centre, irradiance=irradiance, angle=2.0 * np.sqrt(2.0 * spread))
    return World(light, world.seen, world.view, world.view_camera), sun
