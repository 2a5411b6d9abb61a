"""The methods bench (``python -m raybundle bench``): its figures and its files."""
import csv
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from raybundle.app import bench

ROOT = pathlib.Path(__file__).resolve().parents[1]


def power_law(times, c=0.2, p=-0.5):
    return [{"seconds": t, "error": c * t ** p} for t in times]


def test_time_to_a_level_and_the_slope_are_exact_on_a_power_law():
    """Snapshots on e = 0.2 t^-0.5 (unbiased noise): the slope is -0.5 and the log-log
    interpolation between snapshots gives the exact crossing time t = (0.2 / level)^2."""
    rows = power_law([0.5, 1, 2, 4, 8, 16, 32])
    assert bench.slope(rows) == pytest.approx(-0.5, abs=1e-12)
    for level in (0.1, 0.05, 0.045):
        assert bench.time_to(rows, level) == pytest.approx((0.2 / level) ** 2, rel=1e-9)
    assert bench.time_to(rows, 0.01) is None                    # never reached in 32 s
    assert bench.time_to(rows, 0.5) == 0.5                      # already below at the first snapshot
    flat = [{"seconds": t, "error": max(0.2 * t ** -0.5, 0.03)} for t in (2, 4, 8, 16, 32, 64, 128)]
    assert bench.slope(flat) > -0.4                             # a floor flattens the curve


@pytest.fixture(scope="module")
def short_bench(tmp_path_factory):
    """One short bench shared by the tests below: the bundle iteration and Cycles on a furnace
    (analytic reference) and the Cornell box (reference halves path-traced once, then reused)."""
    tmp = tmp_path_factory.mktemp("bench")
    ref, out = tmp / "ref", tmp / "bench"
    (tmp / "docs").mkdir()
    (tmp / "docs" / "benchmarks.md").write_text(PAGE)
    cmd = [sys.executable, "-m", "raybundle", "bench", "--scenes", "furnace", "cornell", "--methods",
           "stochastic-iteration", "--time", "3", "--resolution", "24", "24", "--reference-time", "2",
           "--reference-dir", str(ref), "--out", str(out), "--cycles", str(ROOT / "tools" / "cycles_reference.py"),
           "--page", str(tmp / "docs" / "benchmarks.md")]
    return cmd, ref, out, subprocess.run(cmd, capture_output=True, text=True)


#: a benchmark page with another bench's section and an old one of this bench's
PAGE = """# Benchmarks

<!-- bench:lights -->
## Many lights
kept as it is
<!-- /bench:lights -->

<!-- bench:methods -->
## Methods, an old run
| furnace | an old run's figure |
<!-- /bench:methods -->
"""


def test_the_bench_writes_its_own_section_of_the_benchmark_page(short_bench):
    """``--page``: the bench's section is replaced by its summary table and charts (copied beside
    the page), stamped with the date, the commit and the machine; the other sections stay."""
    import datetime

    cmd, ref, out, p = short_bench
    assert p.returncode == 0, p.stderr
    page = pathlib.Path(cmd[-1])
    text = page.read_text()
    assert "## Many lights\nkept as it is" in text and "an old run's figure" not in text
    section = text.split("<!-- bench:methods -->", 1)[1].split("<!-- /bench:methods -->", 1)[0]
    assert f"on {datetime.date.today().isoformat()}, commit " in section and " cores, " in section
    assert "| furnace | stochastic-iteration |" in section and "| cornell | cycles |" in section
    for k in range(2):
        assert f"(images/bench-methods-{k}.png)" in section
        assert (page.parent / "images" / f"bench-methods-{k}.png").stat().st_size > 0


def test_bench_writes_curves_charts_and_a_summary(short_bench, tmp_path):
    """One CSV and PNG per scene, summary.md with a row per scene and method, errors that fall
    with time on the furnace; the reference halves are reused by a second run."""
    cmd, ref, out, p = short_bench
    assert p.returncode == 0, p.stderr
    assert sorted(f.name for f in ref.iterdir()) == ["cornell-24x24-1.exr", "cornell-24x24-2.exr"]
    assert p.stderr.count("path tracing for") == 2
    for name in ("furnace", "cornell"):
        assert (out / f"{name}.png").stat().st_size > 0
        rows = list(csv.DictReader((out / f"{name}.csv").read_text().splitlines()))
        assert {r["method"] for r in rows} == {"stochastic-iteration", "cycles"}
        err = [float(r["error"]) for r in rows if r["method"] == "stochastic-iteration"]
        t = [float(r["seconds"]) for r in rows if r["method"] == "stochastic-iteration"]
        assert len(err) >= 2 and t == sorted(t) and np.isfinite(err).all()
        if name == "furnace":
            assert err[-1] < err[0]                              # no noise in the analytic reference
    md = (out / "summary.md").read_text()
    for name in ("furnace", "cornell"):
        for method in ("stochastic-iteration", "cycles"):
            assert f"| {name} | {method} |" in md
    # the halves are reused: no path tracing the second time
    again = [sys.executable, "-m", "raybundle", "bench", "--scenes", "cornell", "--methods", "stochastic-iteration",
             "--time", "3", "--resolution", "24", "24", "--reference-time", "2", "--reference-dir", str(ref),
             "--out", str(tmp_path / "again")]
    p = subprocess.run(again, capture_output=True, text=True)
    assert p.returncode == 0 and "path tracing for" not in p.stderr, p.stderr
    p = subprocess.run([sys.executable, "-m", "raybundle", "bench", "--methods", "no-such-method", "--out", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "unknown method" in p.stderr


def test_cycles_is_one_more_curve_where_it_can_build_the_scene(short_bench, tmp_path):
    """``--cycles``: Cycles (through ``bpy`` in a subprocess, CPU, no denoising or clamping) at
    1, 2, 4, ... samples per pixel, each render timed from loading the scene to the EXR
    written, scored by the same error function: its error falls as samples double; a scene
    it cannot build (emission that depends on the albedo) is refused with the reason, which
    the bench writes as an n/a row."""
    _, _, out, p = short_bench
    assert p.returncode == 0, p.stderr
    for name in ("furnace", "cornell"):
        rows = [r for r in csv.DictReader((out / f"{name}.csv").read_text().splitlines()) if r["method"] == "cycles"]
        spp = [int(r["iterations"]) for r in rows]
        err = [float(r["error"]) for r in rows]
        assert len(rows) >= 2 and spp == [2 ** k for k in range(len(rows))], spp
        assert np.isfinite(err).all() and err[-1] < err[0], err
        assert f"| {name} | cycles |" in (out / "summary.md").read_text()
    with pytest.raises(ValueError, match="emission that depends on the albedo"):
        bench.run_cycles("furnace-glossy", 1.0, None, None, str(ROOT / "tools" / "cycles_reference.py"), (16, 16))
    summary = bench.summary_table({"cornell": {}}, {"cornell": {"cycles": "emission that depends on the albedo"}})
    assert "| cornell | cycles | n/a" in summary and "emission that depends on the albedo" in summary


def test_bench_refuses_empty_pairs_and_references_without_time(tmp_path):
    """A scene/method pair where nothing applies, and a missing reference half with
    ``--reference-time 0``: one line, exit 2, nothing cached."""
    base = [sys.executable, "-m", "raybundle", "bench", "--time", "1", "--resolution", "16", "16",
            "--reference-dir", str(tmp_path / "ref"), "--out", str(tmp_path / "b")]
    p = subprocess.run(base + ["--scenes", "furnace-glossy", "--methods", "radiosity"], capture_output=True, text=True)
    assert p.returncode == 2 and "no method applies" in p.stderr and "Traceback" not in p.stderr, p.stderr
    p = subprocess.run(base + ["--scenes", "cornell", "--methods", "path-tracing", "--reference-time", "0"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "--reference-time" in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert not (tmp_path / "ref").exists() or not any((tmp_path / "ref").iterdir())


def test_ctrl_c_stops_the_whole_bench_and_caches_no_cut_reference(tmp_path):
    """Ctrl-C while a reference half is being path-traced: the bench ends (exit 130), the
    half is not cached, so the next run does not reuse a reference cut short."""
    import signal
    import time

    ref = tmp_path / "ref"
    proc = subprocess.Popen([sys.executable, "-m", "raybundle", "bench", "--scenes", "cornell", "--methods",
                             "path-tracing", "--time", "1", "--resolution", "16", "16", "--reference-time", "60",
                             "--reference-dir", str(ref), "--out", str(tmp_path / "b")],
                            stderr=subprocess.PIPE, text=True)
    buf, t0 = "", time.time()
    while "path tracing for" not in buf and time.time() - t0 < 60:
        buf += proc.stderr.readline()
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 130, err
    assert "cut short: not cached" in err and "Traceback" not in err
    assert not list(ref.glob("*.exr"))
