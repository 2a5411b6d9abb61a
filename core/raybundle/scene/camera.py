"""Pinhole (perspective) and orthographic cameras with Blender's conventions.

The camera looks down its local -Z axis with +Y up (Blender).  Intrinsics are
kept in pixels with the origin at the top-left corner of the image and +v
pointing down; pixel centres lie at (i + 0.5, j + 0.5).  Rays start at the
clip-start plane (``clip_start`` metres in front of the camera, as Blender
clips); the clip end is not modelled (everything beyond it is rendered).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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

    def __post_init__(self):
        """A camera that cannot form an image is a ValueError (one line), not a black image."""
        m = np.asarray(self.matrix_world, float)
        if not (1 <= int(self.width) <= 65536 and 1 <= int(self.height) <= 65536):
            raise ValueError(f"camera resolution {self.width} x {self.height}: both must lie in [1, 65536]")
        if not all(np.isfinite(x) for x in (self.fx, self.fy, self.cx, self.cy)) or self.fx <= 0 or self.fy <= 0:
            raise ValueError("camera: the focal length (or orthographic scale) must be finite and positive")
        if m.shape != (4, 4) or not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise ValueError("camera: its matrix_world must be a finite 4 x 4 transform of non-zero scale")

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
        return Camera(int(width), int(height), self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                      self.matrix_world, self.orthographic, self.clip_start)

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
                prefix + "projection": np.array([float(self.orthographic), self.clip_start])}

    @classmethod
    def from_arrays(cls, d, prefix="camera_"):
        if prefix + "intrinsics" not in d:
            return None
        w, h, fx, fy, cx, cy = np.asarray(d[prefix + "intrinsics"], float)
        ortho, clip = np.asarray(d.get(prefix + "projection", (0.0, 0.0)), float)
        return cls(int(w), int(h), fx, fy, cx, cy, np.asarray(d[prefix + "matrix_world"], float),
                   bool(ortho), float(clip))
