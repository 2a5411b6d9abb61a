"""Light and shadow linking: which surfaces a lamp lights directly, and which block its light.

Blender (and Cycles) lets a lamp name a *receiver collection* (the objects it lights) and a
*blocker collection* (the objects that cast its shadows).  Here the objects are grouped by how
every lamp treats them: each input face belongs to a *link group* (``face_group``, indexed by
:attr:`~raybundle.scene.model.PatchScene.triangle_source`), and each lamp to a *link set* (the
``link`` column of :class:`~raybundle.scene.model.PointLights`, :class:`SunLights` and
:class:`AreaLights`, and ``face_emitter`` for the faces of an emitting mesh; set 0, a lamp
without linking, lights everything and is blocked by everything).  ``receives[s, g]``: set s lights the faces of group g directly; ``blocks[s, g]``:
the faces of group g block set s's light.

Only direct light is linked: what a lit surface reflects reaches every other surface (the
bundles carry it), as in Cycles.  An emitting mesh is linked where the first shot takes it (a
small emitter, :func:`~raybundle.lights.sources.small_emitters`); the bundles carry a large
one's light to everything.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class LightLinking:
    """``face_group`` (F,) int, ``receives`` and ``blocks`` (S, G) bool (module docstring); row 0
    of both is all True; ``face_emitter`` (F,) int or None: the link set of each emitting face
    (0 for the rest)."""

    face_group: np.ndarray
    receives: np.ndarray
    blocks: np.ndarray
    face_emitter: np.ndarray | None = None

    def __post_init__(self):
        self.face_group = np.asarray(self.face_group, np.int64).reshape(-1)
        self.face_emitter = (np.zeros(len(self.face_group), np.int64) if self.face_emitter is None else
                             np.asarray(self.face_emitter, np.int64).reshape(-1))
        self.receives = np.atleast_2d(np.asarray(self.receives, bool))
        self.blocks = np.atleast_2d(np.asarray(self.blocks, bool))
        g = int(self.face_group.max()) + 1 if len(self.face_group) else 1
        if self.receives.shape != self.blocks.shape or self.receives.shape[1] < g:
            raise ValueError(f"light linking: receives {self.receives.shape} and blocks {self.blocks.shape} need one "
                             f"column per link group ({g})")
        if len(self.face_emitter) != len(self.face_group) or (len(self.face_emitter) and (
                self.face_emitter.min() < 0 or self.face_emitter.max() >= len(self.receives))):
            raise ValueError("light linking: face_emitter needs one link set in [0, sets) per face")
        if not (self.receives[0].all() and self.blocks[0].all()):
            raise ValueError("light linking: link set 0 (no linking) must light and be blocked by every group")

    @property
    def n_sets(self):
        return len(self.receives)

    def to_arrays(self):
        return {"link_face_group": self.face_group, "link_receives": self.receives, "link_blocks": self.blocks,
                "link_face_emitter": self.face_emitter}

    @classmethod
    def from_arrays(cls, d):
        """The linking of :meth:`to_arrays`' arrays in ``d``, or None without them."""
        if "link_face_group" not in d:
            return None
        return cls(d["link_face_group"], d["link_receives"], d["link_blocks"], d.get("link_face_emitter"))
