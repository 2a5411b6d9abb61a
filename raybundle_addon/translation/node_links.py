"""Following a node tree's links as Cycles does: through reroutes, and to the UV map an image reads."""
from __future__ import annotations


def follow_reroutes(node):
    """The node a link from ``node`` really comes from: past any reroutes; None where a reroute
    is unlinked (or a chain of them does not end)."""
    for _ in range(256):
        if node is None or node.type != "REROUTE":
            return node
        sock = node.inputs[0]
        if not sock.is_linked:
            return None
        node = sock.links[0].from_node
    return None


def uv_source(tex_node):
    """The UV map an Image Texture node reads: a UV Map node's map, "" for the active
    render UV map (Vector unlinked, or Texture Coordinate's UV), None for other coordinates."""
    vec = tex_node.inputs.get("Vector")
    if vec is None or not vec.is_linked:
        return ""
    link = vec.links[0]
    node = follow_reroutes(link.from_node)
    if node is not None and node.type == "UVMAP":
        return node.uv_map
    if node is not None and node.type == "TEX_COORD" and link.from_socket.name == "UV":
        return ""
    return None


#: nodes that make a vector of their inputs alone: an image read through them from a UV map reads a
#: function of that UV map (a tiled, offset or swizzled UV)
VECTOR_NODES = frozenset(("MAPPING", "VECT_MATH", "SEPXYZ", "COMBXYZ", "MATH", "VALUE", "REROUTE"))


def uv_through(tex_node):
    """``(uv map, tiling)`` when the Vector an Image Texture node reads is a function of one UV
    map through :data:`VECTOR_NODES` alone (Mapping, Vector Math, Separate and Combine XYZ, Math,
    constants): the map as :func:`uv_source` names it, and how many times, at most, the image
    repeats across the map's unit square (the product of the Mappings' largest scale in x and y,
    at least 1); None otherwise (other coordinates, two maps, a Mapping whose scale is linked)."""
    vec = tex_node.inputs.get("Vector")
    if vec is None or not vec.is_linked:
        return None
    uvs, tiling, seen, stack = set(), 1.0, set(), [vec.links[0]]
    while stack:
        link = stack.pop()
        if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
            continue
        node = follow_reroutes(link.from_node)
        if node is None:
            return None
        if node.type == "UVMAP" or node.type == "TEX_COORD" and link.from_socket.name == "UV":
            uvs.add(node.uv_map if node.type == "UVMAP" else "")
            continue
        if node.type not in VECTOR_NODES:
            return None
        if node.name in seen:
            continue
        seen.add(node.name)
        if node.type == "MAPPING" and "Scale" in node.inputs:
            if node.inputs["Scale"].is_linked:
                return None
            s = [abs(float(x)) for x in node.inputs["Scale"].default_value[:2]]
            s = [1.0 / x if node.vector_type == "TEXTURE" and x > 0 else x for x in s]
            tiling *= max(1.0, *s)
        stack += [lk for sock in node.inputs for lk in sock.links]
    return (uvs.pop(), tiling) if len(uvs) == 1 else None
