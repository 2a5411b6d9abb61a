"""Triangles' areas and unit normals from their corners: ``c`` the cross product of a triangle's
edges from corner 0, its area ``|c| / 2`` and its normal ``c / (2 area)``.  Compiled
(:mod:`raybundle.util.compiled`), one pass over the triangles; the NumPy path does the same
operations in the same order, so both give the same bits."""
from __future__ import annotations

import numpy as np

from ..util.compiled import helper, kernel, use


def cross(vertices, triangles):
    """(T, 3) ``c`` of triangles ``triangles`` (T, 3) over ``vertices`` (V, 3)."""
    a = vertices[triangles[:, 0]]
    return np.cross(vertices[triangles[:, 1]] - a, vertices[triangles[:, 2]] - a)


def areas(vertices, triangles):
    """(T,) the triangles' areas [m^2]."""
    if _compiled(vertices, triangles):
        out = np.empty(len(triangles))
        _area_normal(np.ascontiguousarray(vertices), np.ascontiguousarray(triangles), out, np.empty((0, 3)))
        return out
    return 0.5 * np.linalg.norm(cross(vertices, triangles), axis=1)


def normals(vertices, triangles, area):
    """(T, 3) the triangles' unit normals, given their ``area`` (T,) (:func:`areas`); NaN or
    infinite where the area is 0, as NumPy divides."""
    if _compiled(vertices, triangles):
        out = np.empty((len(triangles), 3))
        _area_normal(np.ascontiguousarray(vertices), np.ascontiguousarray(triangles), np.ascontiguousarray(area),
                     out)
        return out
    return cross(vertices, triangles) / (2.0 * area[:, None])


def _compiled(vertices, triangles):
    """Whether the kernel takes these arrays (the types it is compiled for)."""
    return use() and vertices.dtype == np.float64 and triangles.dtype == np.int64


@helper
def _quotient(x, d):
    """``x / d`` as NumPy divides (``x / 0`` is +-inf, ``0 / 0`` NaN, where Numba would raise)."""
    if d != 0.0:
        return x / d
    return np.inf if x > 0.0 else (-np.inf if x < 0.0 else np.nan)


def _area_normal_sample():
    return np.eye(3), np.array([[0, 1, 2]], np.int64), np.empty(1), np.empty((1, 3))


@kernel(_area_normal_sample)
def _area_normal(vertices, triangles, area, normal):
    """Each triangle's area into ``area`` (T,), or, where ``normal`` has T rows, its unit normal
    into ``normal`` from the ``area`` given (module docstring)."""
    with_normal = normal.shape[0] == triangles.shape[0]
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        u0, u1, u2 = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        v0, v1, v2 = vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1], vertices[c, 2] - vertices[a, 2]
        x, y, z = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
        if with_normal:
            d = 2.0 * area[t]
            normal[t, 0], normal[t, 1], normal[t, 2] = _quotient(x, d), _quotient(y, d), _quotient(z, d)
        else:
            area[t] = 0.5 * np.sqrt(x * x + y * y + z * z)
