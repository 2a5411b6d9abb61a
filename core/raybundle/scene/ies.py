"""Photometric profiles (IES LM-63 files): a lamp's intensity by direction, as Cycles reads them.

An IES file lists candela values on a grid of vertical angles (0 straight down, along the lamp's
local -Z, to 180 up) and horizontal angles (about the lamp's Z axis).  :func:`parse_ies` reads one
the way Cycles' IES Texture node does: the values times the candela multiplier, the ballast factor
and the ballast-lamp photometric factor, times ``4 pi / 177.83`` (candela to Cycles' lamp
strength, with the luminous efficacy of D65: Blender's convention), photometric types B and C,
a quarter or a half of the horizontal range mirrored to the full circle, and :class:`Profile.at`
looks a direction up with Cycles' cubic (Catmull-Rom) interpolation along both angles, 0 outside
the vertical range (the neighbours at the ends of the ranges as Cycles takes them: :meth:`Profile.at`).  A lamp whose Emission Strength is an IES Texture's output (times its
Strength) emits its intensity times that factor in each direction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: candela to Cycles' lamp strength: 4 pi / 177.83 (D65's luminous efficacy, lm/W)
CANDELA_TO_STRENGTH = 4.0 * np.pi / 177.83


class IESError(ValueError):
    """A photometric file that cannot be read (the message says why)."""


@dataclass
class Profile:
    """``h_angles`` (H,) and ``v_angles`` (V,) ascending [rad], ``values`` (H, V): the factor of
    the lamp's emission in each direction (:meth:`at`)."""

    h_angles: np.ndarray
    v_angles: np.ndarray
    values: np.ndarray

    def __post_init__(self):
        self.h_angles = np.asarray(self.h_angles, float).reshape(-1)
        self.v_angles = np.asarray(self.v_angles, float).reshape(-1)
        self.values = np.asarray(self.values, float).reshape(len(self.h_angles), len(self.v_angles))

    @property
    def peak(self):
        """An upper bound of :meth:`at`: the grid's largest value times 1.25^2 (the absolute
        Catmull-Rom weights sum to at most 1.25 along each angle)."""
        return float(max(self.values.max(), 0.0)) * 1.5625

    def at(self, local):
        """(N,) the factor along unit directions ``local`` (N, 3) from the lamp, in its own frame
        (Cycles: ``v = acos(-z)``, ``h = atan2(x, y) + pi``)."""
        local = np.asarray(local, float)
        v = np.arccos(np.clip(-local[:, 2], -1.0, 1.0))
        h = np.arctan2(local[:, 0], local[:, 1]) + np.pi
        ha, va, val = self.h_angles, self.v_angles, self.values
        out = np.zeros(len(local))
        ok = (v >= va[0]) & (v < va[-1]) & (h >= ha[0]) & (h < ha[-1])
        if not ok.any():
            return out
        v, h = v[ok], h[ok]
        wrap_lo, wrap_hi = va[0] < 1e-7, va[-1] > np.pi - 1e-7
        hi = np.clip(np.searchsorted(ha, h, side="left") - 1, 0, len(ha) - 2)
        vi = np.clip(np.searchsorted(va, v, side="left") - 1, 0, len(va) - 2)
        hf = (h - ha[hi]) / np.maximum(ha[hi + 1] - ha[hi], 1e-30)
        vf = (v - va[vi]) / np.maximum(va[vi + 1] - va[vi], 1e-30)
        n_h, n_v = len(ha), len(va)

        def column(hk):
            """The vertical interpolation in columns ``hk`` (N,)."""
            a = np.where(vi > 0, val[hk, np.maximum(vi - 1, 0)], val[hk, min(1, n_v - 1)] if wrap_lo else 0.0)
            b, c = val[hk, vi], val[hk, vi + 1]
            d = np.where(vi + 2 < n_v, val[hk, np.minimum(vi + 2, n_v - 1)],
                         val[hk, max(n_v - 2, 0)] if wrap_hi else 0.0)
            return _cubic(a, b, c, d, vf)

        # the outer neighbours at the ends of the horizontal range as Cycles (5.3) takes them,
        # measured against its renders: the first interval repeats its first column, the last
        # one takes the column before its last
        prev = np.maximum(hi - 1, 0)
        after = np.where(hi + 2 < n_h, hi + 2, n_h - 2)
        out[ok] = np.maximum(_cubic(column(prev), column(hi), column(hi + 1), column(after), hf), 0.0)
        return out


def _cubic(a, b, c, d, x):
    """Catmull-Rom through b (x = 0) and c (x = 1), with neighbours a and d."""
    return 0.5 * (((d + 3.0 * (b - c) - a) * x + (2.0 * a - 5.0 * b + 4.0 * c - d)) * x + (c - a)) * x + b


def parse_ies(text):
    """The :class:`Profile` of an IES file's ``text`` (raises :class:`IESError`)."""
    text = text.replace(",", " ")
    at = text.find("\nTILT=")
    if at < 0:
        raise IESError("no TILT= line: not an IES file")
    rest = text[at + 1:]
    line, _, rest = rest.partition("\n")
    words = rest.split()
    pos = 0

    def take(n=1):
        nonlocal pos
        if pos + n > len(words):
            raise IESError("the file ends early")
        try:
            got = [float(w) for w in words[pos:pos + n]]
        except ValueError as e:
            raise IESError(f"not a number: {e}") from None
        pos += n
        return got

    if line.strip().upper().startswith("TILT=INCLUDE"):
        take()                                   # lamp-to-luminaire geometry
        n_tilt = int(take()[0])
        take(2 * n_tilt)
    _, _, multiplier, n_v, n_h, kind = take(6)
    n_v, n_h, kind = int(n_v), int(n_h), int(kind)
    if kind not in (1, 2):
        raise IESError(f"photometric type {kind} (A) is not read, as in Cycles: only types B and C")
    take(4)                                      # units, width, length, height
    ballast, photometric, _watts = take(3)
    factor = multiplier * ballast * photometric * CANDELA_TO_STRENGTH
    v = np.array(take(n_v))
    h = np.array(take(n_h))
    values = factor * np.array(take(n_h * n_v)).reshape(n_h, n_v)
    h, v, values = (_type_c if kind == 1 else _type_b)(h, v, values)
    return Profile(np.radians(h), np.radians(v), values)


def _type_c(h, v, values):
    """Cycles' type C ranges: horizontal 0-360 (a quarter or a half mirrored), vertical from 0 or 90."""
    h, values = list(h), list(values)
    if h[0] == 90.0:
        h = [x - 90.0 for x in h]
    if h[0] != 0.0:
        raise IESError(f"horizontal angles start at {h[0]:g}, not 0 or 90")
    if len(h) == 1:
        h, values = h + [360.0], values + [values[0]]
    if h[-1] == 90.0:
        n = len(h)
        for i in range(n - 2, -1, -1):
            h.append(180.0 - h[i])
            values.append(values[i])
    if h[-1] == 180.0:
        n = len(h)
        for i in range(n - 2, -1, -1):
            h.append(360.0 - h[i])
            values.append(values[i])
    if h[-1] != 360.0:
        step_last, step_first, gap = h[-1] - h[-2], h[1] - h[0], 360.0 - h[-1]
        if gap not in (step_last, step_first):
            raise IESError("horizontal angles do not cover a quarter, a half or the whole circle")
        h, values = h + [360.0], values + [values[0]]
    if not (v[0] == 0.0 or (v[0] == 90.0 and v[-1] == 180.0)):
        raise IESError(f"vertical angles from {v[0]:g} to {v[-1]:g}: type C needs 0-... or 90-180")
    return np.array(h), np.asarray(v, float), np.array(values)


def _type_b(h, v, values):
    """Cycles' type B: the roles of the angles swapped, mirrored to 0-360 and 0-180."""
    values = np.asarray(values).T                   # (V, H) -> rows are the new horizontal angles
    h, v = np.asarray(v, float), np.asarray(h, float)
    if h[-1] != 90.0:
        raise IESError("type B: vertical angles must end at 90")
    if h[0] == 0.0:
        h = np.concatenate([90.0 - h[:0:-1], 90.0 + h])
        values = np.concatenate([values[:0:-1], values])
    elif h[0] == -90.0:
        h = h + 90.0
    h = np.append(h, 360.0)
    values = np.concatenate([values, values[:1]])
    if v[-1] != 90.0:
        raise IESError("type B: horizontal angles must end at 90")
    if v[0] == 0.0:
        v = np.concatenate([90.0 - v[:0:-1], 90.0 + v])
        values = np.concatenate([values[:, :0:-1], values], axis=1)
    elif v[0] == -90.0:
        v = v + 90.0
    return h, v, values
