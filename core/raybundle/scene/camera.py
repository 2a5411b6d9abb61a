"""Pinhole (perspective) and orthographic cameras with Blender's conventions.

The camera looks down its local -Z axis with +Y up (Blender).  Intrinsics are
kept in pixels with the origin at the top-left corner of the image and +v
pointing down; pixel centres lie at (i + 0.5, j + 0.5).  Rays start at the
clip-start plane (``clip_start`` metres in front of the camera, as Blender
clips); the clip end is not modelled (everything beyond it is rendered).

Each image sample's position in its pixel follows the *pixel filter* (Cycles' film settings:
Box, Gaussian or Blackman-Harris of a width in pixels), as Cycles samples it: the offsets from
the pixel's centre along x and along y are drawn independently from the filter's 1D profile
(filter importance sampling), so the pixel's value is the image convolved with the separable
filter ``f(x) f(y)``, normalised (:meth:`Camera.subpixel`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

#: the pixel filters (Cycles' ``pixel_filter_type``), in the order of their codes in saved arrays
PIXEL_FILTERS = ("BOX", "GAUSSIAN", "BLACKMAN_HARRIS")


@dataclass
class Camera:
    """Pinhole camera.

    Attributes
    ----------
    width, height : int  resolution in pixels
    fx, fy : float  focal lengths [pixels] (orthographic: pixels per metre)
    cx, cy : float  principal point [pixels], origin top-left
    matrix_world : (4, 4) float  camera-to-world transform (Blender ``matrix_world``)
    orthographic : bool
    clip_start : float  [m] distance of the near clipping plane along the view axis
    pixel_filter : str  one of :data:`PIXEL_FILTERS`
    filter_width : float  [pixels] Cycles' filter width (a box is one pixel wide in Cycles)
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    matrix_world: np.ndarray
    orthographic: bool = False
    clip_start: float = 0.0
    pixel_filter: str = "BOX"
    filter_width: float = 1.0

    def __post_init__(self):
        """A camera that cannot form an image is a ValueError (one line), not a black image."""
        m = np.asarray(self.matrix_world, float)
        if not (1 <= int(self.width) <= 65536 and 1 <= int(self.height) <= 65536):
            raise ValueError(f"camera resolution {self.width} x {self.height}: both must lie in [1, 65536]")
        if not all(np.isfinite(x) for x in (self.fx, self.fy, self.cx, self.cy)) or self.fx <= 0 or self.fy <= 0:
            raise ValueError("camera: the focal length (or orthographic scale) must be finite and positive")
        if m.shape != (4, 4) or not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise ValueError("camera: its matrix_world must be a finite 4 x 4 transform of non-zero scale")
        if self.pixel_filter not in PIXEL_FILTERS:
            raise ValueError(f"camera: pixel filter {self.pixel_filter!r} is not one of {', '.join(PIXEL_FILTERS)}")
        if not 0.01 <= float(self.filter_width) <= 10.0:
            raise ValueError(f"camera: pixel filter width {self.filter_width} px must lie in [0.01, 10] (Cycles' range)")

    @classmethod
    def from_blender(cls, lens, sensor_width, sensor_height, sensor_fit, shift_x, shift_y,
                     resolution, matrix_world, pixel_aspect=(1.0, 1.0), ortho_scale=None, clip_start=0.0):
        """Intrinsics from Blender camera data (``lens``/``sensor_*`` in mm).

        Follows Blender's sensor-fit rule: AUTO fits the sensor width to the
        larger image side; HORIZONTAL/VERTICAL fit width/height.  With
        ``ortho_scale`` [m] the camera is orthographic: the fitted side spans
        ``ortho_scale`` metres (``lens``/``sensor`` are then unused).
        """
        w, h = int(resolution[0]), int(resolution[1])
        ax, ay = pixel_aspect
        fit = sensor_fit
        if fit == "AUTO":
            fit = "HORIZONTAL" if w * ax >= h * ay else "VERTICAL"
            sensor = sensor_width
        else:
            sensor = sensor_width if fit == "HORIZONTAL" else sensor_height
        par = ay / ax
        view = w if fit == "HORIZONTAL" else par * h
        fx = view / ortho_scale if ortho_scale else lens / sensor * view
        return cls(w, h, fx, fx / par, w / 2 - shift_x * view, h / 2 + shift_y * view / par,
                   np.asarray(matrix_world, float), bool(ortho_scale), float(clip_start))

    @classmethod
    def look_at(cls, position, target, up, lens, sensor_width, resolution, sensor_fit="AUTO"):
        """Camera at ``position`` looking at ``target`` (Blender units and lens in mm)."""
        p = np.asarray(position, float)
        back = p - np.asarray(target, float)
        back /= np.linalg.norm(back)
        right = np.cross(np.asarray(up, float), back)
        right /= np.linalg.norm(right)
        cam_up = np.cross(back, right)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, cam_up, back, p
        return cls.from_blender(lens, sensor_width, sensor_width, sensor_fit, 0.0, 0.0, resolution, m)

    @property
    def position(self):
        return self.matrix_world[:3, 3]

    def with_resolution(self, width, height):
        """The same view at another resolution (intrinsics scale with it)."""
        sx, sy = width / self.width, height / self.height
        return replace(self, width=int(width), height=int(height), fx=self.fx * sx, fy=self.fy * sy,
                       cx=self.cx * sx, cy=self.cy * sy)

    def subpixel(self, u):
        """Sample positions (N, 2) [pixels] from the pixel's top-left corner for uniforms ``u``
        (N, 2) in [0, 1)^2, drawn from the pixel filter as Cycles draws them: along x and along
        y independently, ``0.5 + F^-1(u)`` with ``F`` the cumulative distribution of the filter's
        1D profile over its support (Cycles' ``film.cpp``: a box of the width; a Gaussian
        ``exp(-8 x^2 / w^2)`` (standard deviation w / 4) over ``|x| <= 1.5 w``; Blackman-Harris
        ``0.35875 - 0.48829 cos t + 0.14128 cos 2t - 0.01168 cos 3t``, ``t = pi (x / w + 1)``, over
        ``|x| <= w``).  Samples leave the pixel wherever the filter is wider than it.  The
        default box one pixel wide is ``u`` itself."""
        u = np.asarray(u, float)
        if self.pixel_filter == "BOX":
            return u if self.filter_width == 1.0 else 0.5 + (u - 0.5) * float(self.filter_width)
        x, cdf, _ = _filter_cdf(self.pixel_filter, float(self.filter_width))
        return 0.5 + np.interp(u, cdf, x)

    def filter_weights(self, offsets):
        """The density (per pixel) of :meth:`subpixel`'s offsets along one axis, at ``offsets``
        [pixels] from a pixel's centre: the filter's 1D profile normalised to integrate to 1;
        0 beyond its support."""
        kind, width = self.pixel_filter, float(self.filter_width)
        return _filter_profile(kind, width, np.asarray(offsets, float)) / _filter_cdf(kind, width)[2]

    @property
    def filter_margin(self):
        """How far [pixels] beyond a pixel's edge its filter reaches (0 for the box one pixel wide)."""
        return max(0.0, float(_filter_cdf(self.pixel_filter, float(self.filter_width))[0][-1]) - 0.5)

    def footprint(self, px, py):
        """The pixels that light landing at image points ``px, py`` (M,) [pixels] reaches
        through the pixel filter, and with what weight: ``(sample (P,), pixel (P,), weight
        (P,))``, ``pixel`` a flat index ``y * width + x`` inside the image and ``weight`` the
        filter's density there, ``w(px - x - 1/2) w(py - y - 1/2)`` (:meth:`filter_weights`): a
        pixel's value is the mean of the image under its filter, so light splatted at a point
        counts in every pixel whose filter covers it.  A box one pixel wide: the pixel it lands
        in, weight 1."""
        px, py = np.asarray(px, float), np.asarray(py, float)
        col, row = np.floor(px).astype(np.int64), np.floor(py).astype(np.int64)
        if self.pixel_filter == "BOX" and self.filter_width == 1.0:
            inside = np.nonzero((col >= 0) & (col < self.width) & (row >= 0) & (row < self.height))[0]
            return inside, row[inside] * self.width + col[inside], np.ones(len(inside))
        reach = int(np.ceil(self.filter_margin + 0.5))
        k = np.arange(-reach, reach + 1)
        sample = np.repeat(np.arange(len(px)), len(k) ** 2)
        x = (col[:, None, None] + k[None, None, :]).repeat(len(k), axis=1).reshape(-1)
        y = (row[:, None, None] + k[None, :, None]).repeat(len(k), axis=2).reshape(-1)
        w = self.filter_weights(px[sample] - x - 0.5) * self.filter_weights(py[sample] - y - 0.5)
        keep = np.nonzero((w > 0) & (x >= 0) & (x < self.width) & (y >= 0) & (y < self.height))[0]
        return sample[keep], y[keep] * self.width + x[keep], w[keep]

    def ray_directions(self, px, py):
        """Unit world directions through image points (px, py) in pixels, (N, 3)."""
        return self.rays(px, py)[1]

    def rays(self, px, py):
        """Primary rays through image points (px, py) [pixels]: ``(origins (N, 3),
        unit directions (N, 3))``, origins on the clip-start plane."""
        x = (np.asarray(px, float) - self.cx) / self.fx
        y = -(np.asarray(py, float) - self.cy) / self.fy
        rot, pos = self.matrix_world[:3, :3], self.matrix_world[:3, 3]
        scale = np.linalg.norm(rot, axis=0)          # object scale does not change the view
        rot = rot / scale
        if self.orthographic:
            local = np.stack([x, y, np.full_like(x, -self.clip_start)], axis=-1)
            org = pos + local @ rot.T
            return org, np.broadcast_to(-rot[:, 2], org.shape)
        local = np.stack([x, y, -np.ones_like(x)], axis=-1)
        d = local @ rot.T
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        # the clip-start plane is clip_start along the view axis: clip_start / cos from the eye
        t = self.clip_start * np.sqrt(1.0 + x * x + y * y)
        return pos + t[..., None] * d, d

    def project(self, points):
        """Where world ``points`` (N, 3) land on the image, the inverse of :meth:`rays`.

        Returns ``(px, py, to_eye, reach, density)``: image coordinates [pixels] (N,) each;
        the unit direction (N, 3) from each point towards the eye; the distance [m] (N,)
        from the point to where the camera ray starts (the clip-start plane), 0 behind it;
        and the density [pixels^2 per m^2 of area facing the eye] (N,) with which the image
        plane covers surface, ``fx fy / (r^2 cos^3 theta)`` for a pinhole (r the distance
        from the eye, theta the angle from the view axis) and ``fx fy`` for an orthographic
        camera, so that a surface element dA at cosine ``cos_y`` to ``to_eye`` covers
        ``density cos_y dA`` pixels^2 (0 where the point is not in front of the clip plane).
        """
        p = np.asarray(points, float)
        rot, pos = self.matrix_world[:3, :3], self.matrix_world[:3, 3]
        rot = rot / np.linalg.norm(rot, axis=0)
        local = (p - pos) @ rot                       # camera coordinates; the view axis is -z
        depth = -local[:, 2]
        front = depth > self.clip_start
        if self.orthographic:
            px, py = self.cx + self.fx * local[:, 0], self.cy - self.fy * local[:, 1]
            to_eye = np.broadcast_to(rot[:, 2], p.shape).copy()
            reach = np.where(front, depth - self.clip_start, 0.0)
            density = np.where(front, self.fx * self.fy, 0.0)
            return px, py, to_eye, reach, density
        z = np.where(front, depth, 1.0)
        px, py = self.cx + self.fx * local[:, 0] / z, self.cy - self.fy * local[:, 1] / z
        r = np.linalg.norm(local, axis=1)
        to_eye = (pos - p) / np.maximum(r, 1e-300)[:, None]
        reach = np.where(front, r * (1.0 - self.clip_start / z), 0.0)
        density = np.where(front, self.fx * self.fy * r / z ** 3, 0.0)
        return px, py, to_eye, reach, density

    def to_arrays(self, prefix="camera_"):
        return {prefix + "intrinsics": np.array([self.width, self.height, self.fx, self.fy, self.cx, self.cy]),
                prefix + "matrix_world": self.matrix_world,
                prefix + "projection": np.array([float(self.orthographic), self.clip_start]),
                prefix + "filter": np.array([float(PIXEL_FILTERS.index(self.pixel_filter)), self.filter_width])}

    @classmethod
    def from_arrays(cls, d, prefix="camera_"):
        if prefix + "intrinsics" not in d:
            return None
        w, h, fx, fy, cx, cy = np.asarray(d[prefix + "intrinsics"], float)
        ortho, clip = np.asarray(d.get(prefix + "projection", (0.0, 0.0)), float)
        kind, width = np.asarray(d.get(prefix + "filter", (0.0, 1.0)), float)     # older files: a box
        return cls(int(w), int(h), fx, fy, cx, cy, np.asarray(d[prefix + "matrix_world"], float),
                   bool(ortho), float(clip), PIXEL_FILTERS[int(kind)], float(width))


def _filter_profile(kind, width, x):
    """:meth:`Camera.filter_weights`: Cycles' filter functions with its width conventions."""
    if kind == "BOX":
        return (np.abs(x) <= 0.5 * width).astype(float)
    if kind == "GAUSSIAN":
        return np.where(np.abs(x) <= 1.5 * width, np.exp(-8.0 * (x / width) ** 2), 0.0)
    t = np.pi * (x / width + 1.0)
    return np.where(np.abs(x) <= width,
                    0.35875 - 0.48829 * np.cos(t) + 0.14128 * np.cos(2 * t) - 0.01168 * np.cos(3 * t), 0.0)


@lru_cache(maxsize=8)
def _filter_cdf(kind, width, n=4097):
    """``(x (n,), F (n,), total)``: offsets over the filter's support [pixels], its cumulative
    distribution there, and the integral of its profile (trapezoids on n points: F is inverted
    by linear interpolation to about 1e-7 px)."""
    half = {"BOX": 0.5, "GAUSSIAN": 1.5}.get(kind, 1.0) * width
    x = np.linspace(-half, half, n)
    f = _filter_profile(kind, width, x)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(x))])
    return x, cdf / cdf[-1], float(cdf[-1])
