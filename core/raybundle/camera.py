"""Pinhole camera with Blender's conventions.

The camera looks down its local -Z axis with +Y up (Blender).  Intrinsics are
kept in pixels with the origin at the top-left corner of the image and +v
pointing down; pixel centres lie at (i + 0.5, j + 0.5).
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
    fx, fy : float  focal lengths [pixels]
    cx, cy : float  principal point [pixels], origin top-left
    matrix_world : (4, 4) float  camera-to-world transform (Blender ``matrix_world``)
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    matrix_world: np.ndarray

    @classmethod
    def from_blender(cls, lens, sensor_width, sensor_height, sensor_fit, shift_x, shift_y,
                     resolution, matrix_world, pixel_aspect=(1.0, 1.0)):
        """Intrinsics from Blender camera data (``lens``/``sensor_*`` in mm).

        Follows Blender's sensor-fit rule: AUTO fits the sensor width to the
        larger image side; HORIZONTAL/VERTICAL fit width/height.
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
        fx = lens / sensor * view
        return cls(w, h, fx, fx / par, w / 2 - shift_x * view, h / 2 + shift_y * view / par,
                   np.asarray(matrix_world, float))

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
                      self.matrix_world)

    def ray_directions(self, px, py):
        """Unit world directions through image points (px, py) in pixels, (N, 3)."""
        x = (np.asarray(px, float) - self.cx) / self.fx
        y = -(np.asarray(py, float) - self.cy) / self.fy
        local = np.stack([x, y, -np.ones_like(x)], axis=-1)
        d = local @ self.matrix_world[:3, :3].T
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def to_arrays(self, prefix="camera_"):
        return {prefix + "intrinsics": np.array([self.width, self.height, self.fx, self.fy, self.cx, self.cy]),
                prefix + "matrix_world": self.matrix_world}

    @classmethod
    def from_arrays(cls, d, prefix="camera_"):
        if prefix + "intrinsics" not in d:
            return None
        w, h, fx, fy, cx, cy = np.asarray(d[prefix + "intrinsics"], float)
        return cls(int(w), int(h), fx, fy, cx, cy, np.asarray(d[prefix + "matrix_world"], float))
