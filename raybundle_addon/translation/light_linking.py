"""Blender's light and shadow linking on lamps -> :class:`raybundle.scene.linking.LightLinking`.

A lamp's Light Linking panel names a receiver collection (the objects it lights) and a blocker
collection (the objects that cast its shadows).  As Blender's depsgraph reads them (Cycles
renders what it computes):

- an object directly in the collection takes its own entry's state, Include or Exclude; an
  object inside a child collection, at any depth, takes the state of that first-level child's
  entry (where both apply, the object's own entry);
- a lamp lights (or is blocked by) an object whose state is Include, and, when no object of its
  collection is included, every object not excluded.

Lamps (and emitting meshes) with the same two collections share a link set.  Objects are
grouped by how every link set treats them; a collection instance's objects take the
instancer's state where it has one.  An emitting mesh's linking applies to the first shot of
its light (:mod:`raybundle.scene.linking`).
"""
from __future__ import annotations

import numpy as np


def collection_states(collection):
    """``{object name: "INCLUDE" or "EXCLUDE"}`` for the objects of ``collection`` (module docstring)."""
    states = {}

    def inner(coll, state):
        for child in coll.children:
            inner(child, state)
        for ob in coll.objects:
            states[ob.name] = state

    for entry, child in zip(collection.collection_children, collection.children):
        inner(child, entry.light_linking.link_state)
    for entry, ob in zip(collection.collection_objects, collection.objects):
        states[ob.name] = entry.light_linking.link_state
    return states


class _Rule:
    """Whether a link set reaches an object: Include, or not Exclude when nothing is included."""

    def __init__(self, collection):
        self.states = {} if collection is None else collection_states(collection)
        self.any_include = "INCLUDE" in self.states.values()

    def __call__(self, name):
        state = self.states.get(name)
        return state == "INCLUDE" or (state is None and not self.any_include)


class LinkSets:
    """The link sets of a scene's emitters, made as they are met (:meth:`set_of`)."""

    def __init__(self):
        self._sets = {}             # (receiver name, blocker name) -> (index, receives rule, blocks rule)

    def set_of(self, ob):
        """The link set of emitter ``ob`` (an original lamp or mesh object): 0 without linking."""
        link = getattr(ob, "light_linking", None)
        receivers = getattr(link, "receiver_collection", None)
        blockers = getattr(link, "blocker_collection", None)
        if receivers is None and blockers is None:
            return 0
        key = (None if receivers is None else receivers.name_full, None if blockers is None else blockers.name_full)
        if key not in self._sets:
            self._sets[key] = (len(self._sets) + 1, _Rule(receivers), _Rule(blockers))
        return self._sets[key][0]

    def linking(self, objects, triangle_object, emitters=None):
        """The :class:`~raybundle.scene.linking.LightLinking` of ``objects`` ((original name,
        instancer name or None) each) whose triangles are ``triangle_object`` (T,) (indices into
        ``objects``), with ``emitters`` (len(objects),) the link set of each object's own emission
        (:meth:`set_of`; None: none), or None when nothing is linked."""
        from raybundle.scene.linking import LightLinking

        if not self._sets:
            return None
        rows = sorted(self._sets.values(), key=lambda r: r[0])
        named = {n for _, r, b in rows for n in (*r.states, *b.states)}
        names = [inst if inst is not None and inst in named else name for name, inst in objects]
        table = np.array([[rule(name) for _, r, b in rows for rule in (r, b)] for name in names], bool)
        table = table.reshape(len(names), -1)
        combos, group = np.unique(table, axis=0, return_inverse=True)
        ones = np.ones((1, len(combos)), bool)
        receives = np.vstack([ones, combos[:, 0::2].T])
        blocks = np.vstack([ones, combos[:, 1::2].T])
        emitter = None if emitters is None else np.asarray(emitters, np.int64)[triangle_object]
        return LightLinking(np.asarray(group).reshape(-1)[triangle_object], receives, blocks, emitter)
