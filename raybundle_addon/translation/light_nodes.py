"""A light's own shader nodes (Light Properties > Nodes) -> the factor its emission takes.

Cycles multiplies a light's color and power by what its node tree's Light Output receives: an
Emission shader's ``Color x Strength`` (the default tree, Color white and Strength 1, is a
factor of 1).  The factor is read where it is the same at every point of the light:

- the Emission's Color and Strength as their sockets hold them, or from an RGB or Value node;
- a Light Falloff node on the Strength: its Quadratic output with Smooth 0 is its Strength
  (Cycles' sampling already gives the inverse-square fall-off); its Linear and Constant outputs,
  and a Smooth above 0, depend on the distance;
- Add and Mix Shaders of emissions: the sum, and the mix by a constant factor;
- an IES Texture's output (times its Strength) on the Strength of a point or spot lamp's
  Emission: its photometric profile (:mod:`raybundle.scene.ies`), looked up in the lamp's own
  frame as Cycles does with the Vector left unlinked; the file from the node's text block or
  from its file path.

A tree with anything else (a texture through the light's coordinates, a Blackbody or Math node,
a distance-dependent fall-off, an IES Texture on a sun or area lamp, or with its Vector linked) is
not evaluated: the light emits its own color and power, and the warning names the node.  A tree
whose Light Output receives nothing makes the light emit nothing, as in Cycles.
"""
from __future__ import annotations

import numpy as np

from .node_links import follow_reroutes


class _Unread(Exception):
    """A node the reader does not evaluate (the message names it)."""


def light_node_factor(ld, warn):
    """``(factor (3,), profile)`` of light ``ld``'s emission given by its node tree: the color
    factor (ones without a tree) and the :class:`~raybundle.scene.ies.Profile` of an IES Texture
    on it (None); ``warn(message)`` is told once for each light whose tree is not read in full."""
    import bpy

    nt = getattr(ld, "node_tree", None)
    if nt is None or (bpy.app.version < (5, 0, 0) and not ld.use_nodes):
        return np.ones(3), None
    out = nt.get_output_node("CYCLES") or nt.get_output_node("ALL")
    if out is None:
        return np.ones(3), None
    found = []
    try:
        factor = _shader(out.inputs["Surface"], 0, found)
        if len(found) > 1:
            raise _Unread("more than one IES Texture")
        if found and ld.type not in ("POINT", "SPOT"):
            raise _Unread(f"its IES texture {found[0].name!r} on a {ld.type.lower()} lamp")
        return factor, (_profile(found[0]) if found else None)
    except _Unread as e:
        warn(f"light {ld.name!r}: its node tree is not modeled ({e}): the light emits its own color and power")
        return np.ones(3), None


def _linked(sock):
    """The node feeding input ``sock`` (reroutes followed), or None (unlinked or muted link)."""
    if not sock.is_linked:
        return None
    link = sock.links[0]
    if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
        return None
    return follow_reroutes(link.from_node)


def _shader(sock, depth, ies):
    """(3,) what shader input ``sock`` delivers as a factor of the light's emission; IES Textures
    met go to ``ies``."""
    if depth > 32:
        raise _Unread("a shader chain too deep")
    node = _linked(sock)
    if node is None or node.mute:
        return np.zeros(3)
    if node.type == "EMISSION":
        return _color(node.inputs["Color"]) * max(_strength(node.inputs["Strength"], ies), 0.0)
    if node.type == "ADD_SHADER":
        return _shader(node.inputs[0], depth + 1, ies) + _shader(node.inputs[1], depth + 1, ies)
    if node.type == "MIX_SHADER":
        fac = float(np.clip(_value(node.inputs[0]), 0.0, 1.0))
        return (1.0 - fac) * _shader(node.inputs[1], depth + 1, ies) + fac * _shader(node.inputs[2], depth + 1, ies)
    raise _Unread(f"the {node.bl_label} node {node.name!r}")


def _color(sock):
    node = _linked(sock)
    if node is None:
        return np.array(sock.default_value[:3], float)
    if node.type == "RGB":
        return np.array(node.outputs[0].default_value[:3], float)
    if node.type == "VALUE":
        return np.full(3, float(node.outputs[0].default_value))
    raise _Unread(f"the {node.bl_label} node {node.name!r} on {sock.node.name!r}'s {sock.name}")


def _value(sock):
    node = _linked(sock)
    if node is None:
        return float(sock.default_value)
    if node.type == "VALUE":
        return float(node.outputs[0].default_value)
    raise _Unread(f"the {node.bl_label} node {node.name!r} on {sock.node.name!r}'s {sock.name}")


def _strength(sock, ies):
    """An Emission's Strength: a value, a Light Falloff's Quadratic output without Smooth, or an
    IES Texture's output (its Strength; the node goes to ``ies``)."""
    node = _linked(sock)
    if node is not None and node.type == "TEX_IES":
        if node.inputs["Vector"].is_linked:
            raise _Unread(f"the IES Texture {node.name!r} with its Vector linked")
        ies.append(node)
        return _value(node.inputs["Strength"])
    if node is not None and node.type == "LIGHT_FALLOFF":
        from_socket = sock.links[0].from_socket.name
        if from_socket != "Quadratic" or _value(node.inputs["Smooth"]) != 0.0:
            raise _Unread(f"the Light Falloff node {node.name!r}: only its Quadratic output with Smooth 0 is "
                          "modeled")
        return _value(node.inputs["Strength"])
    return _value(sock)


def _profile(node):
    """The :class:`~raybundle.scene.ies.Profile` of IES Texture ``node`` (its text block, or its
    file); :class:`_Unread` naming the node when it has none or it cannot be read."""
    import bpy

    from raybundle.scene.ies import IESError, parse_ies

    try:
        if node.mode == "INTERNAL":
            if node.ies is None:
                raise _Unread(f"the IES Texture {node.name!r} has no text block")
            text = node.ies.as_string()
        else:
            with open(bpy.path.abspath(node.filepath), encoding="utf-8", errors="replace") as f:
                text = f.read()
        return parse_ies(text)
    except (OSError, IESError) as e:
        raise _Unread(f"the IES Texture {node.name!r}: {e}") from None
