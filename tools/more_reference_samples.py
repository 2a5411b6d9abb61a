"""Bring the committed Cycles reference halves of an interior to more samples per pixel.

    python tools/more_reference_samples.py demo_scenes/interiors/dining-room.blend --to 4096

Each half ``<file>-clay-<seed>.exr`` (seeds 1, 2) in ``--references`` that holds fewer than
``--to`` samples (its header's ``cycles.ViewLayer.samples``) gets a Cycles render of the
missing samples with seed 10 + its seed, rendered as ``tools/bench_blender.py --clay
--resolution 320 180`` renders, and becomes the samples-weighted mean of the two: the halves
stay independent (their seeds differ) and each is a plain Monte Carlo mean of ``--to``
samples.  The header records the count and how the half was made.  Takes as long as the
missing samples take Cycles (about 20 minutes per 2,048 on 2 cores for the dining room).
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path[:0] = [os.path.dirname(os.path.abspath(__file__)),
                os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "core")]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("blend")
    p.add_argument("--to", type=int, default=4096, help="samples per pixel of each half afterwards")
    p.add_argument("--references", default="demo_scenes/interiors/references")
    p.add_argument("--resolution", type=int, nargs=2, default=(320, 180))
    a = p.parse_args(argv)
    import numpy as np

    import bench_blender as bb
    from raybundle.util.io import read_exr, read_exr_header, write_exr

    bb.OPEN_SETTINGS.update(clay=True, resolution=tuple(a.resolution))
    stem = os.path.splitext(os.path.basename(a.blend))[0]
    for half in (1, 2):
        path = os.path.join(a.references, f"{stem}-clay-{half}.exr")
        have = int(read_exr_header(path)["cycles.ViewLayer.samples"])
        if have >= a.to:
            print(f"{path}: {have} samples already")
            continue
        extra, seed = a.to - have, 10 + half
        more = path + f".seed{seed}.exr"
        img, wall = bb.render(a.blend, more, "CYCLES", samples=extra, seed=seed)
        mean = (have * read_exr(path) + extra * img) / a.to
        write_exr(path, mean.astype(np.float32),
                  {"cycles.ViewLayer.samples": str(a.to),
                   "raybundle_reference": f"Cycles, clay, {a.resolution[0]} x {a.resolution[1]}: the mean of {have} "
                                          f"samples (seed {half}) and {extra} samples (seed {seed}), weighted by "
                                          "samples"})
        os.remove(more)
        print(f"{path}: {have} + {extra} samples (seed {seed}, {wall:.0f} s)")


if __name__ == "__main__":
    main()
