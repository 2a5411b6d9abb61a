"""The error's breakdown by component: RAYBUNDLE's Light Components passes against Cycles' light passes.

Both engines write their parts as passes of a multilayer EXR: RAYBUNDLE the view layer's
Light Components (``RB Emission``, ``RB Lamps``...; :mod:`raybundle.imaging.components`),
Cycles its light passes (Emission, Environment, Diffuse, Glossy and Transmission Direct,
Indirect and Color).  Each side's parts are summed into the components compared
(:data:`COMPONENTS`):

* ``emission``: what the eye sees emitting (Cycles: Emission + Environment);
* ``direct``: the lamps' and the world's direct light on the diffuse lobe (Cycles: Diffuse
  Direct x Diffuse Color);
* ``diffuse indirect``: the rest of the diffuse lobe (Cycles: Diffuse Indirect x Diffuse Color;
  RAYBUNDLE: its patches and caustics);
* ``glossy``: the glossy lobe (Cycles: (Glossy Direct + Indirect) x Glossy Color);
* ``transmission``: seen through glass (Cycles: (Transmission Direct + Indirect) x
  Transmission Color; RAYBUNDLE keeps what it sees through glass as the part of the surface
  behind, so the pixels where glass or a mirror turned its eye rays are left out of the
  comparison: :func:`glass_pixels`).

Where RAYBUNDLE's patches carry the world's direct light (``world_samples`` 0 beside lamps), its
``direct`` holds the lamps' alone: :func:`merged_diffuse` compares the diffuse lobe whole.  The
split is not the same on both sides where lamps shine through glass panes either: RAYBUNDLE's
lamp samples pass a pane (direct), Cycles' shadow rays do not (its light through glass is
indirect); the bench therefore also compares the diffuse lobe whole.
"""
from __future__ import annotations

import numpy as np

#: the components compared, in order
COMPONENTS = ("emission", "direct", "diffuse indirect", "glossy", "transmission")
#: Cycles' light passes the view layer turns on (``use_pass_<name>``)
CYCLES_PASS_SWITCHES = ("emit", "environment", "diffuse_direct", "diffuse_indirect", "diffuse_color",
                        "glossy_direct", "glossy_indirect", "glossy_color", "transmission_direct",
                        "transmission_indirect", "transmission_color")
#: Cycles' pass names as Blender 5 writes them, and as Blender 4 did
_CYCLES_NAMES = {"Emission": "Emit", "Environment": "Env", "Diffuse Direct": "DiffDir",
                 "Diffuse Indirect": "DiffInd", "Diffuse Color": "DiffCol", "Glossy Direct": "GlossDir",
                 "Glossy Indirect": "GlossInd", "Glossy Color": "GlossCol", "Transmission Direct": "TransDir",
                 "Transmission Indirect": "TransInd", "Transmission Color": "TransCol"}


def enable_passes(view_layer, engine):
    """Turn on ``view_layer``'s passes the breakdown reads: Cycles' light passes, or (engine
    ``RAYBUNDLE``) the Light Components."""
    if engine == "CYCLES":
        for name in CYCLES_PASS_SWITCHES:
            setattr(view_layer, "use_pass_" + name, True)
    else:
        view_layer.raybundle.use_pass_components = True


def multilayer_output(scene):
    """``scene`` saves a 32-bit multilayer EXR (every pass), in Blender 4 and 5."""
    s = scene.render.image_settings
    if hasattr(s, "media_type"):              # Blender 5: the file format follows the media type
        s.media_type = "MULTI_LAYER_IMAGE"
    else:
        s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "32"
    s.exr_codec = "ZIP"


def cycles_components(passes):
    """{component: (H, W, 3)} from Cycles' passes ({pass name: image}, :func:`raybundle.util.io.
    read_exr_passes`)."""
    p = {short: passes[long] if long in passes else passes[short] for long, short in _CYCLES_NAMES.items()}
    return {"emission": p["Emit"] + p["Env"], "direct": p["DiffDir"] * p["DiffCol"],
            "diffuse indirect": p["DiffInd"] * p["DiffCol"], "glossy": (p["GlossDir"] + p["GlossInd"]) * p["GlossCol"],
            "transmission": (p["TransDir"] + p["TransInd"]) * p["TransCol"]}


def save_components(path, components):
    """Write ``components`` ({name: (H, W, 3)}) as a half-float EXR of channels ``<name>.R``,
    ``.G``, ``.B`` (a tenth of the size of Cycles' own passes in full floats: what the
    repository keeps of a pass reference), atomically."""
    import OpenEXR

    from raybundle.util.io import atomic_path

    channels = {name: np.ascontiguousarray(np.asarray(img, np.float32).astype(np.float16))
                for name, img in components.items()}
    with atomic_path(path) as tmp:
        with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as f:
            f.write(tmp)


def load_components(path):
    """The components :func:`save_components` wrote, as float32 (H, W, 3) by name."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        return {name: np.array(c.pixels, np.float32) for name, c in f.channels().items()}


def raybundle_components(passes):
    """{component: (H, W, 3)} from RAYBUNDLE's Light Components passes."""
    p = {name[3:].lower(): image for name, image in passes.items() if name.startswith("RB ")}
    return {"emission": p["emission"], "direct": p["lamps"] + p["world"],
            "diffuse indirect": p["diffuse indirect"] + p["caustics"], "glossy": p["glossy"],
            "transmission": np.zeros_like(p["emission"])}


def glass_pixels(passes):
    """(H, W) bool: the pixels where glass or a mirror turned some of RAYBUNDLE's eye rays."""
    return np.asarray(passes["RB Glass"]) > 0


def merged_diffuse(components):
    """The same components with ``direct`` and ``diffuse indirect`` summed into ``diffuse``
    (where RAYBUNDLE's patches carry part of the direct light)."""
    out = {k: v for k, v in components.items() if k not in ("direct", "diffuse indirect")}
    out["diffuse"] = components["direct"] + components["diffuse indirect"]
    return out
