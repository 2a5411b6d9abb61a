"""Image and file output: linear EXR (OpenEXR package), sRGB PNG previews, JSON.

Every writer is atomic: it writes a temporary file beside the target and
renames it over the target only when the write succeeded, so an interrupted
render never leaves a truncated image behind.
"""
from __future__ import annotations

import contextlib
import json
import os
import struct
import tempfile
import zlib

import numpy as np


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path in the target's folder; rename it to ``path`` on success."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    suffix = os.path.splitext(path)[1]
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=suffix, dir=folder)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())     # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


class OutputError(ValueError):
    """An output path that cannot be written; the message says which and why, in one line."""


def check_output(path, what="output", suffix=None, folder=False):
    """Make sure ``path`` can be written before any work is done: its folder is created
    (or ``path`` itself, a folder, with ``folder``) and a file is created and removed in it;
    ``suffix`` (e.g. ``".exr"``) is the extension it must have.  Raises :class:`OutputError`."""
    path = os.fspath(path)
    if suffix is not None and not path.lower().endswith(suffix):
        raise OutputError(f"{what} {path}: the output must end in {suffix}")
    if not folder and (os.path.isdir(path) or path.endswith(os.sep)):
        raise OutputError(f"{what} {path}: is a folder; give a file name")
    target = os.path.abspath(path) if folder else os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(target, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-check-", dir=target)
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise OutputError(f"{what} {path}: cannot write there ({e.strerror or e})") from None


def write_exr(path, rgb, header=None):
    """Write an (H, W, 3) linear radiance image [W m^-2 sr^-1] as a FLOAT RGB EXR.

    Row 0 is the top of the image.  ``header`` adds string attributes.
    Non-finite pixels raise ValueError (never write a silent NaN image).
    """
    import OpenEXR

    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) image, got {rgb.shape}")
    if not np.isfinite(rgb).all():
        raise ValueError(f"refusing to write {path}: the image has {int((~np.isfinite(rgb)).sum())} "
                         "non-finite values")
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in (header or {}).items():
        hdr[k] = str(v)
    with atomic_path(path) as tmp:
        with OpenEXR.File(hdr, {"RGB": rgb}) as f:
            f.write(tmp)


def write_layers_exr(path, layers, header=None):
    """Write view layers as a multilayer FLOAT EXR as Blender names them: each ``name -> (H, W, 3
    or 4)`` linear image of ``layers`` as channels ``<name>.Combined.R``, ``.G``, ``.B``, ``.A``
    (alpha 1 where an image has none).  Row 0 is the top; ``header`` adds string attributes.
    Non-finite pixels raise ValueError."""
    import OpenEXR

    channels = {}
    for name, img in layers.items():
        img = np.asarray(img, dtype=np.float32)
        if img.ndim != 3 or img.shape[2] not in (3, 4):
            raise ValueError(f"view layer {name!r}: expected an (H, W, 3 or 4) image, got {img.shape}")
        if not np.isfinite(img).all():
            raise ValueError(f"refusing to write {path}: view layer {name!r} has "
                             f"{int((~np.isfinite(img)).sum())} non-finite values")
        for k, c in enumerate("RGBA"):
            channels[f"{name}.Combined.{c}"] = np.ascontiguousarray(img[..., k] if k < img.shape[2] else
                                                                    np.ones(img.shape[:2], np.float32))
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for k, v in (header or {}).items():
        hdr[k] = str(v)
    with atomic_path(path) as tmp:
        with OpenEXR.File(hdr, channels) as f:
            f.write(tmp)


def _exr_channels(f):
    """Every channel of an open EXR ``f`` over all its parts (Blender 5 writes a view layer a part)."""
    parts = getattr(f, "parts", None) or []
    if len(parts) <= 1:
        return f.channels()
    out = {}
    for part in parts:
        out.update(part.channels)
    return out


def exr_layers(path):
    """The view layers of a multilayer EXR (:func:`write_layers_exr`, Blender's own, in one part or
    a part each), by name; empty for a plain RGB(A) EXR."""
    import OpenEXR

    with OpenEXR.File(os.fspath(path)) as f:
        return sorted(k[:-len(".Combined")] for k in _exr_channels(f) if k.endswith(".Combined"))


def read_exr(path, layer=None):
    """Read an EXR's RGB as (H, W, 3) float32, row 0 at the top: a plain RGB(A) file's, or a
    multilayer file's view layer ``layer`` (its ``<layer>.Combined`` pass); ``layer`` may be left
    out when the file has one.  A file without such channels raises ValueError."""
    import OpenEXR

    with OpenEXR.File(os.fspath(path)) as f:
        ch = _exr_channels(f)
        if layer is None:
            for key in ("RGB", "RGBA"):
                if key in ch:
                    return np.array(ch[key].pixels[..., :3], dtype=np.float32)
            found = sorted(k[:-len(".Combined")] for k in ch if k.endswith(".Combined"))
            if len(found) != 1:
                raise ValueError(f"{path}: " + (f"{len(found)} view layers ({', '.join(found)}): say which" if found
                                                else "no RGB channels and no view layer's Combined pass"))
            layer = found[0]
        key = f"{layer}.Combined"
        if key not in ch:
            raise ValueError(f"{path}: no view layer {layer!r} (it has {[k for k in ch if k.endswith('.Combined')]})")
        return np.array(ch[key].pixels[..., :3], dtype=np.float32)


def read_exr_passes(path, layer=None):
    """The passes of a multilayer EXR's view layer ``layer`` (may be left out when the file has
    one), by pass name: (H, W, 3) float32 for colour passes (RGB of RGBA), (H, W) for one
    channel (``X``, ``Z``...); row 0 at the top."""
    import OpenEXR

    with OpenEXR.File(os.fspath(path)) as f:          # its channels live while the file is open
        ch = _exr_channels(f)
        layers = sorted({k.split(".", 1)[0] for k in ch if "." in k})
        if layer is None:
            if len(layers) != 1:
                raise ValueError(f"{path}: {len(layers)} view layers ({', '.join(layers)}): say which")
            layer = layers[0]
        out = {}
        for key, c in ch.items():
            if key.startswith(layer + "."):
                name, px = key[len(layer) + 1:], np.array(c.pixels, np.float32)
                if px.ndim == 3:
                    px = px[..., :3]
                out[name.rsplit(".", 1)[0] if px.ndim == 2 and "." in name else name] = px
        if not out:
            raise ValueError(f"{path}: no view layer {layer!r} (it has {layers})")
        return out


def read_exr_header(path):
    import OpenEXR

    with OpenEXR.File(os.fspath(path), header_only=True) as f:
        return dict(f.header())


def linear_to_srgb(x):
    """sRGB transfer function (IEC 61966-2-1) of linear values clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def write_png(path, rgb, exposure=0.0):
    """Write an (H, W, 3) linear image as an 8-bit sRGB PNG preview (clipped, no tone map)."""
    img = np.asarray(rgb, float) * (2.0 ** exposure)
    img = np.nan_to_num(img, nan=0.0, posinf=1.0, neginf=0.0)
    data = np.round(linear_to_srgb(img) * 255).astype(np.uint8)
    h, w, _ = data.shape
    raw = b"".join(b"\x00" + data[y].tobytes() for y in range(h))

    def chunk(tag, body):
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(png)


def write_json(path, obj):
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            json.dump(obj, f, indent=2, sort_keys=True)
            f.write("\n")
