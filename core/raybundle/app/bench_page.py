"""A bench's own section of the benchmark page (``docs/benchmarks.md``), written by the bench itself.

Each bench command owns the part of the page between ``<!-- bench:NAME -->`` and
``<!-- /bench:NAME -->``: :func:`write_section` replaces it (or appends it) with the bench's
table and charts, stamped with the date, the commit and the machine, so that no figure on the
page is typed by hand.  The charts are copied beside the page (``images/bench-NAME-*.png``).
The page is written atomically.
"""
from __future__ import annotations

import datetime
import os
import platform
import re
import shutil
import subprocess

from ..util.io import atomic_path


def _commit(folder):
    """The short commit of the checkout holding ``folder`` (with ``+dirty`` for local changes), or
    'unknown' outside a git checkout."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=folder, capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=folder,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return head.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def machine():
    """One line naming this machine: processor count, system and Python."""
    return f"{os.cpu_count()} cores, {platform.system()} {platform.machine()}, Python {platform.python_version()}"


def write_section(page, name, title, body, charts=(), command=None):
    """Write bench ``name``'s section of ``page`` (a Markdown file, made if missing): a heading
    ``title``, a line with the date, commit, machine and ``command`` that wrote it, the Markdown
    ``body`` and the PNG ``charts`` (paths; copied to ``images/`` beside the page).  Replaces the
    section's previous text, keeps the rest of the page.  Returns the section's text."""
    page = os.path.abspath(page)
    folder = os.path.dirname(page)
    links = []
    for k, chart in enumerate(charts):
        target = os.path.join(folder, "images", f"bench-{name}-{k}.png")
        os.makedirs(os.path.dirname(target), exist_ok=True)
        shutil.copyfile(chart, target)
        links.append(f"![{os.path.splitext(os.path.basename(chart))[0]}](images/{os.path.basename(target)})")
    stamp = (f"*Written by `{command or name}` on {datetime.date.today().isoformat()}, commit "
             f"{_commit(os.path.dirname(os.path.abspath(__file__)))}, on {machine()}.*")
    section = "\n\n".join([f"<!-- bench:{name} -->", f"## {title}", stamp, body.strip(), *links,
                           f"<!-- /bench:{name} -->"])
    old = open(page, encoding="utf-8").read() if os.path.exists(page) else "# Benchmarks\n"
    pattern = re.compile(rf"<!-- bench:{re.escape(name)} -->.*?<!-- /bench:{re.escape(name)} -->", re.S)
    text = pattern.sub(lambda _: section, old) if pattern.search(old) else old.rstrip("\n") + "\n\n" + section
    with atomic_path(page) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text.rstrip("\n") + "\n")
    return section
