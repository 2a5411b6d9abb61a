"""The front door stays short and its links stay true: the README at most 250 lines, no paragraph
over 120 words, no table cell over 40 words, its first two commands ``make demo`` and ``make
test``; every relative link of the README and of ``docs/`` points at a file (and a heading) that
exists."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "CHANGELOG.md"]


def blocks(text):
    """The README's prose paragraphs and table rows (code blocks left out)."""
    prose, rows, para, code = [], [], [], False
    for line in text.split("\n") + [""]:
        if line.startswith("```"):
            code = not code
            continue
        if code:
            continue
        if line.startswith("|"):
            rows.append(line)
        elif line.strip() and not line.startswith("#"):
            para.append(line)
            continue
        if para:
            prose.append(" ".join(para))
            para = []
    return prose, rows


def slug(heading):
    """A heading's anchor as GitHub makes it."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_the_readme_is_short_and_starts_with_its_two_commands():
    text = (ROOT / "README.md").read_text()
    assert len(text.split("\n")) <= 250
    prose, rows = blocks(text)
    long_paragraphs = [p[:60] for p in prose if len(p.split()) > 120]
    long_cells = [c.strip()[:60] for r in rows for c in r.strip("|").split("|") if len(c.split()) > 40]
    assert not long_paragraphs and not long_cells, (long_paragraphs, long_cells)
    commands = re.findall(r"^make \w+", text.split("```sh", 1)[1], re.M)[:2]
    assert commands == ["make demo", "make test"]


def test_every_relative_link_of_the_readme_and_the_docs_exists():
    bad = []
    for page in PAGES:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            if "://" in target or target.startswith("mailto:"):
                continue
            path, _, anchor = target.partition("#")
            file = (page.parent / path).resolve() if path else page
            if not file.exists():
                bad.append((page.name, target))
            elif anchor and file.suffix == ".md":
                headings = {slug(h) for h in re.findall(r"^#+ (.+)$", file.read_text(), re.M)}
                if anchor not in headings:
                    bad.append((page.name, target))
    assert not bad, bad


def test_no_docstring_or_comment_quotes_a_before_and_after_figure_or_a_date():
    """Docstrings and comments in ``core/`` and ``raybundle_addon/`` state contracts and equations:
    before-and-after figures (``3.27% -> 2.92%``) and dates belong to docs/benchmarks.md and
    CHANGELOG.md."""
    figure = re.compile(r"\d(\.\d+)?\s*%\s*(->|→)|(->|→)\s*\d+(\.\d+)?\s*(/\s*\d+(\.\d+)?\s*)?%|\b20\d\d-\d\d-\d\d\b")
    found = [f"{path.relative_to(ROOT)}:{k}" for path in [*ROOT.glob("core/raybundle/**/*.py"),
                                                           *ROOT.glob("raybundle_addon/*.py")]
             for k, line in enumerate(path.read_text().split("\n"), 1) if figure.search(line)]
    assert not found, found
