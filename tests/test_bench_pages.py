"""Every bench writes its own section of the benchmark page, and ``make docs-images`` its pictures:
a tiny run of each, on a page that holds another bench's section and an old one of its own."""
import datetime
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
TOOLS = ROOT / "tools"

#: another bench's section, which must stay as it is
OTHER = "<!-- bench:other -->\n## Another bench\nkept as it is\n<!-- /bench:other -->"


def run_tool(tmp_path, tool, section, *args):
    """Run ``tools/<tool>.py`` with ``args`` and ``--page`` on a page holding :data:`OTHER` and an
    old ``section``; returns (process, the page's text, the section's text)."""
    page = tmp_path / "docs" / "benchmarks.md"
    page.parent.mkdir(parents=True)
    page.write_text(f"# Benchmarks\n\n{OTHER}\n\n<!-- bench:{section} -->\n## An old run\n| an old run's figure |\n"
                    f"<!-- /bench:{section} -->\n")
    p = subprocess.run([sys.executable, str(TOOLS / f"{tool}.py"), *map(str, args), "--out", str(tmp_path / "out"),
                        "--page", str(page)], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-3000:]
    text = page.read_text()
    assert OTHER in text and "an old run's figure" not in text   # a figure could read 9.99%
    body = text.split(f"<!-- bench:{section} -->", 1)[1].split(f"<!-- /bench:{section} -->", 1)[0]
    assert f"on {datetime.date.today().isoformat()}, commit " in body and " cores, " in body
    assert f"`tools/{tool}.py " in body
    return p, text, body


def charts(page_dir, section, n):
    for k in range(n):
        assert (page_dir / "images" / f"bench-{section}-{k}.png").stat().st_size > 1000


def test_the_blender_bench_writes_its_section(tmp_path):
    _, _, body = run_tool(tmp_path, "bench_blender", "blender-cornell_box", "demo_scenes/cornell_box.blend",
                          "--resolution", 24, 16, "--reference-samples", 4, "--times", 0.5,
                          "--max-cycles-seconds", 1, "--twin", "--breakdown", "--breakdown-samples", 4)
    assert "`demo_scenes/cornell_box.blend`, its own materials, 24 × 16 px" in body
    # set-up, mean, bias, noise, error
    assert re.search(r"\| 0\.5 s \| [\d.]+ \| [\d.]+ s \| ×[\d.]+ \| [\d.]+% \| [\d.]+% \| [\d.]+% \|", body), body
    assert re.search(r"\| bottom \| ×[\d.]+, \d+% \| ×[\d.]+, \d+% \| ×[\d.]+, \d+% \|", body), body
    assert "| Cycles spp | 1 | 2 |" in body and "| time to an error of | 5% |" in body
    # the error by component: raybundle's, its bias and noise and mean, Cycles'
    assert re.search(r"\| direct \| [\d.]+% \| [\d.]+% \| [\d.]+% \| [\d.]+% \| ×[\d.]+ \| [\d.]+% \|", body), body
    assert "That run's seconds by part" in body and re.search(r"Its phases: (compiling the kernels [\d.]+ s, )?"
                                                                r"exporting the scene", body), body
    charts(tmp_path / "docs", "blender-cornell_box", 1)
    # the rooms side by side, from the bench's summary.json
    p = subprocess.run([sys.executable, str(TOOLS / "interiors_table.py"), str(tmp_path)], capture_output=True,
                       text=True, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-3000:]
    assert re.search(r"\| cornell_box \| own materials \| [\d.]+ s \| [\d.]+ s \| \d+ \|", p.stdout), p.stdout
    assert re.search(r"\| cornell_box \| own materials \| [\d.]+% / [\d.]+% \(\d+%\) \|", p.stdout), p.stdout


def test_the_bake_bench_writes_its_section(tmp_path):
    _, _, body = run_tool(tmp_path, "bench_bake", "bake", "--reference-samples", 4, "--times", 0.5,
                          "--max-cycles-seconds", 1, "--lightmap-size", 32, "--lightmap-seconds", 0.5,
                          "--lightmap-error-size", 16, "--lightmap-reference-samples", 4)
    assert "4,624 vertices" in body and "| 0.5 s |" in body and "A 32² lightmap of the floor" in body
    assert "The floor's 16² lightmap against Cycles' bake" in body
    charts(tmp_path / "docs", "bake", 2)


def test_the_scale_bench_writes_its_section(tmp_path):
    from raybundle.app.bench import reference
    from raybundle.util.io import write_exr

    _, halves = reference("cornell", (24, 24), str(tmp_path / "halves"), 1.0, log=lambda _: None)
    (tmp_path / "ref").mkdir()
    for k, half in enumerate(halves, 1):
        write_exr(str(tmp_path / "ref" / f"reference-{k}.exr"), half)
    _, _, body = run_tool(tmp_path, "bench_scale", "scale", "--triangles", 4000, "--time", 1, "--reference",
                          tmp_path / "ref", "--resolution", 24, 24)
    assert re.search(r"\| 3,936 \| clusters \| [\d,]+ \| [\d.]+ s \|", body), body
    charts(tmp_path / "docs", "scale", 1)


def test_the_stress_bench_writes_its_section(tmp_path):
    """A stress scene built, rendered through the add-on, its set-up per phase and its memory reported."""
    p, _, body = run_tool(tmp_path, "bench_scale", "stress", "--stress", "transmission-chain", "--time", 2)
    assert re.search(r"\| transmission-chain \| [\d,]+ \| 11 \| 2 \|( [\d.]+ \|){9} [\d.]+ s \| \d+ \| [\d.]+ s \| "
                     r"-?[\d.]+ GB \| met \|", body), body
    assert "first shot" in p.stdout and (tmp_path / "out" / "stress.json").exists()


def test_the_invariance_bench_writes_its_section(tmp_path):
    _, _, body = run_tool(tmp_path, "bench_invariance", "invariance", "--batches", 2, "--per-batch", 2,
                          "--patches", 300, "--convergence", 300, 600, "--cases", "subdivide 2x")
    assert "`--cases 'subdivide 2x'`" not in body and "'subdivide 2x'" in body     # the command, quoted
    assert "| subdivide 2x | 128 |" in body and "| 600 | +0.00% |" in body


def test_the_pictures_of_the_readme_and_the_manual_are_made_by_a_command(tmp_path):
    """``tools/docs_images.py``: the room in clay and in its own materials by both engines, each
    labelled with its time and error, and the render and bake of the demo box."""
    out = tmp_path / "images"
    p = subprocess.run([sys.executable, str(TOOLS / "docs_images.py"), "--out", str(out), "--seconds", "1",
                        "--room", str(ROOT / "demo_scenes" / "room.blend"), "--references", str(tmp_path / "ref"),
                        "--reference-samples", "4", "--manual-seconds", "1", "--manual-resolution", "48", "48"],
                       capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-3000:]
    labels = re.findall(r"^(raybundle|Cycles), (clay|own materials): \d+ s, error [\d.]+%$", p.stdout, re.M)
    assert sorted(labels) == sorted([(e, k) for e in ("raybundle", "Cycles") for k in ("clay", "own materials")])
    for name in ("readme-room.png", "manual-render-and-bake.png"):
        assert (out / name).stat().st_size > 10_000
    assert sorted(x.name for x in out.iterdir()) == ["manual-render-and-bake.png", "readme-room.png"]


#: the Makefile's commands, continuation lines joined
COMMANDS = [t.strip() for t in (ROOT / "Makefile").read_text().replace("\\\n", " ").split("\n") if t.startswith("\t")]


@pytest.mark.parametrize("command", [c for c in COMMANDS if "tools/bench_" in c or "raybundle bench" in c])
def test_every_bench_command_of_the_makefile_writes_the_page(command):
    assert "--page $(PAGE)" in command


def test_every_section_of_the_benchmark_page_is_stamped_or_says_it_is_not_yet_rewritten():
    text = (ROOT / "docs" / "benchmarks.md").read_text()
    sections = re.findall(r"<!-- bench:([\w-]+) -->(.*?)<!-- /bench:\1 -->", text, re.S)
    assert len(sections) >= 9
    for name, body in sections:
        stamped = re.search(r"\*Written by `.+` on \d{4}-\d\d-\d\d, commit \w+", body)
        kept = re.search(r"\*Not yet rewritten by `make [\w-]+`: written by hand, kept from the README at commit "
                         r"[0-9a-f]{7}", body)
        assert stamped or kept, name


def test_the_breakdown_gives_each_pass_parts_cost_per_pixel_beside_cycles_per_path():
    """Issue 62's figure: the run's seconds per part over its passes and pixels, in µs, and
    Cycles' seconds over its samples and pixels; nothing where the run gave no parts."""
    import bench_blender

    split = dict(part_seconds={"eye rays": 2.0, "lamps": 5.0, "iterations": 9.0}, image_passes=10, pixels=100_000,
                 cycles_seconds=12.8, cycles_samples=32)
    line = bench_blender.per_pixel_costs(split)
    assert line == ("µs per pixel and image pass: eye rays 2.00, lamps 5.00; Cycles 4.00 µs per path (its whole "
                    "path, its scene set-up included).")
    assert bench_blender.per_pixel_costs(dict(split, part_seconds=None)) is None
