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
import shlex
import shutil
import subprocess
import sys

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


def table(header, rows):
    """A Markdown table: ``header`` (column names) over ``rows`` (sequences of cells, already text)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def add_page_argument(parser, section):
    """``--page FILE.md`` (the benchmark page whose section this bench writes) and ``--section
    NAME`` (the section's name; None when not given, ``section`` says the bench's default) on a
    bench's argument ``parser``."""
    parser.add_argument("--page", help="write this bench's section of a benchmark page (Markdown), "
                        "e.g. docs/benchmarks.md")
    parser.add_argument("--section", help=f"the section's name on the page (default: {section})")


def command_line(tool, argv=None):
    """The shell command that ran ``tool`` with ``argv`` (default: this process's arguments)."""
    return shlex.join([tool, *(sys.argv[1:] if argv is None else argv)])


def checked_page(page, tool):
    """``page`` checked writable before any work (None passes); exits with one line and status 2
    if not."""
    if page:
        from ..util.io import OutputError, check_output

        try:
            check_output(page, "--page", suffix=".md")
        except OutputError as e:
            print(f"{tool}: {e}", file=sys.stderr)
            raise SystemExit(2) from None
    return page


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
