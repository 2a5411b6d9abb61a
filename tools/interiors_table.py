"""The interior bench's rooms side by side: one table from each room's ``summary.json``.

Usage (after ``make bench-interiors``, which runs it)::

    python tools/interiors_table.py out/bench-interiors --page docs/benchmarks.md

Reads ``<folder>/<room>-<full|clay>/summary.json`` (:mod:`bench_blender`) and prints, and
with ``--page`` writes as the page's ``interiors`` section: per room and mode raybundle's error
at its longest time beside Cycles' at the same time, its set-up, iterations and mean, and with
a breakdown (``--breakdown``) each component's error beside Cycles'.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys

_TOOLS = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [_TOOLS]

from raybundle.app.bench_page import add_page_argument, checked_page, command_line, table, write_section  # noqa: E402
from bench_blender import percent  # noqa: E402


def rows_of(folder):
    """(room, mode, summary) for every ``<room>-<mode>/summary.json`` under ``folder``, own
    materials before clay."""
    found = []
    for path in sorted(glob.glob(os.path.join(folder, "*", "summary.json"))):
        with open(path) as f:
            s = json.load(f)
        room = os.path.splitext(os.path.basename(s["blend"]))[0]
        found.append((room, "clay" if s["clay"] else "own materials", s))
    return sorted(found, key=lambda r: (r[1] == "clay", r[0]))


def overview(found):
    """Markdown: raybundle against Cycles, one row per room and mode."""
    out = []
    for room, mode, s in found:
        ours = [r for r in s["rows"] if r["engine"] == "raybundle"][-1]
        same = s["summary"][-1]["cycles_error_same_time"]
        out.append([room, mode, f"{ours['seconds']:.1f} s",
                    "–" if ours.get("setup_seconds") is None else f"{ours['setup_seconds']:.1f} s",
                    str(ours.get("iterations") or "–"), f"×{ours['mean_ratio']:.3f}", percent(ours["error"]),
                    percent(ours.get("bias")), percent(ours.get("noise")), percent(same),
                    "–" if not same else f"{ours['error'] / same:.2f}"])
    return table(["room", "mode", "raybundle's run", "set-up", "iterations", "its mean", "raybundle", "its bias",
                  "its noise", "Cycles, same time", "ratio"], out)


def components(found):
    """Markdown: each room's error by component (raybundle / Cycles at the same time), and the
    component's share of the image."""
    seen = {k for _, _, s in found for k in (s.get("breakdown") or {}).get("components", {})}
    names = [k for k in ("emission", "diffuse", "direct", "diffuse indirect", "glossy", "transmission") if k in seen]
    out = []
    for room, mode, s in found:
        comp = (s.get("breakdown") or {}).get("components")
        if not comp:
            continue
        out.append([room, mode] + ["–" if k not in comp else
                                   f"{percent(comp[k]['error'])} / {percent(comp[k]['cycles_error'])} "
                                   f"({100 * comp[k]['share']:.0f}%)" for k in names])
    return table(["room", "mode"] + names, out) if out else ""


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("folder", help="the interior bench's output folder (out/bench-interiors)")
    add_page_argument(p, "interiors")
    a = p.parse_args(argv)
    checked_page(a.page, "interiors_table")
    found = rows_of(a.folder)
    if not found:
        print(f"no summary.json under {a.folder}", file=sys.stderr)
        return 2
    body = ["Each room's raybundle run at its longest Time Limit beside Cycles at the same time, both timed "
            "from opening the file to the EXR written in the same run (each room's section below has the rest).",
            "", overview(found)]
    parts = components(found)
    if parts:
        body += ["The error by component, raybundle / Cycles at the same time (the component's share of the "
                 "image), relative to the whole reference's mean (`tools/breakdown.py`); `diffuse` is the diffuse "
                 "lobe whole (direct and indirect: the split differs between the engines where the patches "
                 "carry the world's direct light, or lamps shine through glass panes).", "", parts]
    text = "\n".join(body)
    print(text)
    if a.page:
        write_section(a.page, a.section or "interiors", "The interior bench: every room", text,
                      command=command_line("tools/interiors_table.py", argv))
        print(f"wrote its section of {a.page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
