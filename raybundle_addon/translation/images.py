"""Blender images' pixels as arrays: linear RGB and alpha, row 0 at the bottom, and the encoded
values of byte sRGB images, which Cycles keeps encoded and decodes after interpolating."""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from raybundle.scene.textures import srgb_to_linear


@contextmanager
def loaded_while_read():
    """Within it, the images Blender had not loaded before (``Image.has_data`` False: a file's
    pixels are decoded on first access) and that were read are unloaded again at its end
    (``Image.buffers_free``; Blender reloads an image's pixels when it next needs them).  Their
    pixels are read into arrays once, and Blender's own copy would otherwise stay in memory for
    the whole render: a room's photographs, tens of megabytes each.  The Render Result and the
    Viewer Node's image (source ``VIEWER``) are never touched."""
    import bpy

    unloaded = [im for im in bpy.data.images if not im.has_data and im.source != "VIEWER"]
    try:
        yield
    finally:
        for im in unloaded:
            if im.has_data:
                im.buffers_free()


def srgb_bytes(image):
    """Whether ``image`` (a bpy Image) holds bytes in the sRGB color space, which Cycles keeps
    encoded and decodes after interpolating."""
    return (not getattr(image, "is_float", True) and
            getattr(getattr(image, "colorspace_settings", None), "name", "") == "sRGB")


def image_bytes(image):
    """``(bytes (H, W, 3) uint8, values (256,) float32)`` of a byte sRGB image (row 0 at the
    bottom): its texels and the encoded value each byte stands for as Blender holds it; or
    None without pixel data."""
    px = _pixels(image)
    return None if px is None else _byte_table(_rgb(px))


def linear_pixels(image):
    """(H, W, 3) linear RGB of an image's pixels (None without data), row 0 at the bottom."""
    px = image_rgba(image)
    return None if px is None else np.ascontiguousarray(px[..., :3])


def byte_mean(k, values):
    """(3,) the mean linear color of a byte sRGB image's texels ``k`` (H, W, 3) uint8 standing
    for the encoded ``values`` (256,) (:func:`image_bytes`), each decoded as
    :func:`decode_srgb_bytes` decodes it: from a count of each byte per channel."""
    linear = srgb_to_linear(values).astype(np.float32).astype(float)
    flat = k.reshape(-1, 3)
    return np.array([np.bincount(flat[:, c], minlength=256) @ linear for c in range(3)]) / max(len(flat), 1)


def decode_srgb_bytes(rgb):
    """:func:`~raybundle.scene.textures.srgb_to_linear` of a byte image's values (each one of 256,
    k / 255), through a table of the values it holds: the same numbers, without the power per texel."""
    k, held = _byte_table(rgb)
    return srgb_to_linear(held).astype(np.float32)[k]


def _byte_table(rgb):
    """``(bytes, values (256,) float32)`` of a byte image's values ``rgb`` (each k / 255): its
    bytes (uint8) and the value each byte stands for as the image holds it (k / 255 where none does)."""
    k = np.clip(rgb, 0.0, 1.0)
    k *= 255
    k = np.rint(k, out=k).astype(np.uint8)
    values = np.arange(256, dtype=np.float32) / np.float32(255)
    values[k] = rgb
    return k, values


def _rgb(px):
    """The RGB channels of pixels (H, W, channels), a gray channel repeated."""
    return px[..., :3] if px.shape[2] >= 3 else np.repeat(px[..., :1], 3, axis=2)


def image_rgba(image):
    """(H, W, 4) float32 linear RGB and alpha of an image's pixels (None without data), row 0
    at the bottom.  Byte images in an sRGB color space hold encoded values in
    ``Image.pixels``: their colors are decoded first."""
    px = _pixels(image)
    if px is None:
        return None
    h, w, ch = px.shape
    rgb = _rgb(px)
    if srgb_bytes(image):
        rgb = decode_srgb_bytes(rgb)
    alpha = px[..., 3:4] if ch in (2, 4) else np.ones((h, w, 1), np.float32)
    if ch == 2:
        alpha = px[..., 1:2]
    return np.concatenate([rgb, alpha], axis=2).astype(np.float32)


def _pixels(image):
    """(H, W, channels) float32 ``Image.pixels`` as Blender holds them (row 0 at the bottom), or
    None without data."""
    try:
        w, h = image.size
        ch = image.channels
        if w * h == 0 or not image.has_data and (image.packed_file is None and not image.filepath):
            return None
        px = np.empty(w * h * ch, np.float32)
        image.pixels.foreach_get(px)
    except (RuntimeError, ValueError, AttributeError):
        return None
    return None if px.size == 0 else px.reshape(h, w, ch)
