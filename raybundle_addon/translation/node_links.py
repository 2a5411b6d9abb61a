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
