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
                                                           *ROOT.glob("raybundle_addon/**/*.py")]
             for k, line in enumerate(path.read_text().split("\n"), 1) if figure.search(line)]
    assert not found, found


def table_rows(text):
    """The first cells of every Markdown table row in ``text``."""
    return {m.group(1).strip() for m in re.finditer(r"^\| ([^|]+) \|", text, re.M)}


def test_the_manual_describes_every_panel_setting_and_every_headless_option():
    """Each setting of the Ray Bundle GI panels (the property group's properties, the last
    render's read-only fields aside) has a row under its panel name in the manual's settings
    tables, and each option of ``raybundle-blender`` appears in the manual."""
    import bpy

    import raybundle_addon
    from raybundle_addon.__main__ import build_parser

    if not hasattr(bpy.types.Scene, "raybundle"):
        raybundle_addon.register()

    manual = (ROOT / "docs" / "manual.md").read_text()
    render = manual.split("### Settings (Render Properties › Ray Bundle GI)", 1)[1].split("\n## ", 1)[0]
    bake = manual.split("### Settings (Render Properties › Ray Bundle GI › Bake)", 1)[1].split("\n### ", 1)[0]
    rows = table_rows(render) | table_rows(bake)
    settings = bpy.types.Scene.bl_rna.properties["raybundle"].fixed_type.properties
    missing = [p.identifier for p in settings
               if p.identifier not in ("rna_type", "name") and not p.identifier.startswith("last_")
               and p.name not in rows]
    assert not missing, f"panel settings without a row in the manual: {missing}"
    options = [o for action in build_parser()._actions for o in action.option_strings if o.startswith("--")]
    assert [o for o in options if f"`{o}" not in manual and o != "--help"] == []
