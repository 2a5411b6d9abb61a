# One-command set-up: `make demo` and `make test` create the environments and install everything on first use.
#
# Two environments, one per end of the Blender versions the extension supports:
#   .venv         the newest: Python 3.13 with bpy 5.3 and NumPy 2 (requirements-dev.txt); everything
#                 runs here: the full suite, `make demo`, the benches, `make extension`
#   .venv-oldest  the oldest: Python 3.11 with bpy 4.2 LTS and NumPy 1.26 (requirements-oldest.txt)
#                 and nothing of ours: tests/test_extension.py installs the extension zip into it
# Each Python is found by running it (tools/find_python: a `python3.13` on PATH can be a pyenv stub
# that fails). Without Python 3.13, .venv is made with 3.11 (bpy 5.0.1, NumPy 1.26) and `make test`
# says what it skipped; under CI=true a missing Python is an error.
PY_NEWEST := $(shell tools/find_python 3.13)
PY_OLDEST := $(shell tools/find_python 3.11)
PYTHON    := $(or $(PY_NEWEST),$(PY_OLDEST))
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OLDEST := .venv-oldest
NO_NEWEST := the newest Blender's environment (no working Python 3.13: the suite ran on Python 3.11, bpy 5.0.1, NumPy 1.26)
NO_OLDEST := the oldest Blender's environment (no working Python 3.11: the zip was not installed into bpy 4.2, NumPy 1.26)
SKIPPED := $(if $(PY_NEWEST),,$(NO_NEWEST))$(if $(PY_OLDEST),,$(NO_OLDEST))

.PHONY: demo test test-newest test-suite test-chains test-oldest bench bench-blender bench-boxes bench-lights bench-interiors bench-interiors-quick bench-bake bench-scale \
        bench-invariance docs-images extension cycles-reference demo-scenes test-blender-versions golden golden-check clean FORCE

ifeq ($(PYTHON),)
ifneq ($(MAKECMDGOALS),clean)
$(error neither Python 3.13 nor 3.11 works here (tools/find_python): install one, e.g. `pyenv install 3.13`)
endif
endif
# under CI=true, `make test` needs both ends, and says so before any work
ifeq ($(CI),true)
ifneq ($(filter test test-newest test-suite test-chains test-oldest,$(MAKECMDGOALS)),)
$(if $(PY_NEWEST),,$(error CI=true: no working Python 3.13 for the newest Blender's environment (tools/find_python 3.13)))
$(if $(PY_OLDEST),,$(error CI=true: no working Python 3.11 for the oldest Blender's environment (tools/find_python 3.11)))
endif
endif

# every module byte-compiled once, in parallel (pip's own compile, one file at a time, was slow):
# a process then never compiles what it imports, where Python writes no bytecode itself
# (PYTHONDONTWRITEBYTECODE): bpy's start-up scripts, numpy and numba cost each process seconds
BYTECODE = $(1) -m compileall -q -j 0 $$($(1) -c 'import sysconfig; print(sysconfig.get_path("purelib"))')

# .venv is remade when the Python it should have changes (3.13 appeared, or went away)
ifneq ($(shell cat $(VENV)/.python 2>/dev/null),$(PYTHON))
$(STAMP): FORCE
endif
$(STAMP): core/pyproject.toml pyproject.toml requirements-dev.txt
	$(PYTHON) -m venv --clear $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -r requirements-dev.txt -e ./core -e .
	$(call BYTECODE,$(PY)) core/raybundle raybundle_addon
	echo "$(PYTHON)" > $(VENV)/.python
	touch $(STAMP)

$(OLDEST)/.installed: requirements-oldest.txt
	$(if $(PY_OLDEST),,$(error no working Python 3.11 for the oldest Blender's environment (tools/find_python 3.11)))
	$(PY_OLDEST) -m venv --clear $(OLDEST)
	$(OLDEST)/bin/python -m pip install --quiet --upgrade pip
	$(OLDEST)/bin/python -m pip install --quiet --no-compile -r requirements-oldest.txt
	$(call BYTECODE,$(OLDEST)/bin/python)
	touch $@

demo: $(STAMP)
	$(PY) -m raybundle render cornell --time 30 --out out/cornell.exr --stats out/cornell.json
	$(VENV)/bin/raybundle-blender demo_scenes/cornell_box.blend --time 30 --out out/cornell_box_blend.exr

# The full suite on the newest Blender; then, side by side, its chains' file and the extension zip
# in the oldest (73 s where one after the other took 98 s); the last line names an
# environment that could not run (an error under CI=true)
test: test-suite
	@$(MAKE) --no-print-directory --output-sync=target -j2 test-chains test-oldest
	@$(if $(SKIPPED),echo "make test: skipped $(SKIPPED)")

test-newest: test-suite test-chains

# two processes, a file each at a time (the machines have 2 cores), the slowest files first so that both
# end together (tests/conftest.py); a process that crashes ends the run at once, naming its test: xdist's
# replacement worker can wait forever under --dist loadfile (pytest-xdist#784; a CI run
# hung 75 min so)
test-suite: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder --max-worker-restart=0 --ignore=tests/test_chains.py --ignore=tests/test_golden.py tests

# the chains' file apart from the suite: its Dask cluster's two workers beside a second test process
# of the suite once lost their scattered scene (beside the oldest Blender's one process they did not);
# the golden hashes too, whose cases include chains
test-chains: $(STAMP)
	$(PY) -m pytest -q tests/test_chains.py tests/test_golden.py

test-oldest:
ifneq ($(PY_OLDEST),)
	$(MAKE) --no-print-directory $(OLDEST)/.installed
	$(OLDEST)/bin/python -m pytest -q tests/test_extension.py tests/test_blender_walk.py
endif

# Each bench rewrites its own section of this page (raybundle.app.bench_page)
PAGE = docs/benchmarks.md

# Every method on the built-in scenes, 60 s each (12 minutes on 2 cores, plus 10 minutes per missing
# reference half of the Cornell boxes: `make cycles-reference` makes Cycles ones instead)
bench: $(STAMP)
	$(PY) -m raybundle bench --out out/bench --page $(PAGE)

# The RAYBUNDLE engine against Cycles on the Cornell .blend (about 15 minutes on 2 cores)
bench-blender: $(STAMP)
	$(PY) tools/bench_blender.py demo_scenes/cornell_box.blend --out out/bench-blender --page $(PAGE)

# The built-in boxes against Cycles on the same triangles, side by side (about 45 minutes on 2 cores)
bench-boxes: $(STAMP)
	$(PY) tools/bench_blender.py cornell --times 5 10 30 60 120 --out out/bench-cornell --max-cycles-seconds 260 \
	    --page $(PAGE)
	$(PY) tools/bench_blender.py cornell-glossy --times 5 10 30 60 120 --out out/bench-cornell-glossy --reference-samples 4096 \
	    --max-cycles-seconds 200 --page $(PAGE)

# Many lights: Veach's multiple-importance test scene (demo_scenes/lights) against Cycles from the same
# file at 30 and 90 s, references committed (about 10 minutes on 2 cores)
bench-lights: $(STAMP)
	$(PY) tools/bench_blender.py demo_scenes/lights/veach-mis.blend --references demo_scenes/lights/references \
	    --times 30 90 --max-cycles-seconds 200 --out out/bench-lights --page $(PAGE)

# Real rooms (demo_scenes/interiors), RAYBUNDLE against Cycles from the same file at 320 x 180, references
# committed: each room in its own materials and in clay (the view layer's Material Override) at 60 s, twice
# (seeds 3 and 4: the error's bias and noise), Cycles' ladder up to 120 s, and the error by component
# against Cycles' light passes (tools/breakdown.py; pass references of 2 x 256 samples, committed beside
# the others) (about 20 minutes a room on 2 cores); `make bench-interiors-quick` runs one room
INTERIORS = living-room dining-room modern-hall bathroom bathroom2
bench-interiors: $(STAMP)
	for room in $(INTERIORS); do \
	  for mode in full clay; do \
	    $(PY) tools/bench_blender.py demo_scenes/interiors/$$room.blend $$([ $$mode = clay ] && echo --clay) \
	      --resolution 320 180 --references demo_scenes/interiors/references --times 60 --twin --breakdown \
	      --max-cycles-seconds 120 --out out/bench-interiors/$$room-$$mode --page $(PAGE) || exit 1; \
	  done; \
	done
	$(PY) tools/interiors_table.py out/bench-interiors --page $(PAGE)

bench-interiors-quick:
	@$(MAKE) --no-print-directory bench-interiors INTERIORS=bathroom2

# The point-domain bake against Cycles' bake of the same 4,624 vertices, the time of a 1024^2 lightmap
# and the floor's 256^2 lightmap against Cycles' bake of it, and the vertices of the box subdivided in
# Edit Mode (about 80 minutes on 2 cores the first time, 35 after: the Cycles references are cached in
# out/bench-bake)
bench-bake: $(STAMP)
	$(PY) tools/bench_bake.py --out out/bench-bake --page $(PAGE)
	$(PY) tools/bench_bake.py --out out/bench-bake --blend demo_scenes/cornell_subdivided.blend --lightmap-size 0 \
	    --page $(PAGE)

# The Cornell box meshed with 4k to 4M triangles: error, set-up time and memory against triangle count
# (about 15 minutes on 2 cores and 5 GB of memory; needs out/bench-cornell's Cycles reference from bench-boxes);
# then the stress scenes (tools/stress_scenes.py: many objects, node-graph materials, touching planes, glass,
# glossy clusters, 1M and 4M triangles), each phase's seconds and the peak memory (about 8 minutes, 8 GB),
# and the same for the five bench rooms in clay and in their own materials (about 8 minutes)
bench-scale: $(STAMP)
	$(PY) tools/bench_scale.py --out out/bench-scale --one-patch-per-triangle 4000 16000 64000 --page $(PAGE)
	$(PY) tools/bench_scale.py --out out/bench-scale --stress --time 30 --page $(PAGE)
	$(PY) tools/bench_scale.py --out out/bench-scale --rooms --time 30 --page $(PAGE)

# The Cornell .blend described in a dozen ways a Blender user would (subdivided, triangulated, flipped,
# split, joined, instanced, transformed, scaled, reordered) against the file as it is, and the patch
# count as a convergence (about 10 minutes on 2 cores)
bench-invariance: $(STAMP)
	$(PY) tools/bench_invariance.py --out out/bench-invariance --page $(PAGE)

# The pictures of the README and the manual (docs/images), made from the code as it is: a real room by
# raybundle and by Cycles at the same time, in clay and in its own materials, with both errors; a render
# and a bake of the demo box (about 10 minutes on 2 cores)
docs-images: $(STAMP)
	$(PY) tools/docs_images.py --out docs/images

# The installable Blender extension: dist/raybundle-<version>-<platform>.zip for every platform in
# blender_manifest.toml, built without a Blender binary (Blender's blender_ext.py from the bpy module).
# Wheel downloads are cached in wheels/, so later builds are offline.
extension: $(STAMP)
	$(PY) tools/build_extension.py --out dist

# Cycles references for the bench: two independent halves per box (about 3 minutes each on 2 cores)
cycles-reference: $(STAMP)
	mkdir -p out/reference
	for scene in cornell cornell-glossy; do for k in 1 2; do \
	  $(PY) tools/cycles_reference.py $$scene --samples 1024 --seed $$k --out out/reference/$$scene-256x256-$$k.exr; \
	done; done

# The extension zip installed into each Blender release line from 4.2 to 5.3 (tests/test_extension.py
# in a venv per bpy version; make test runs the two ends; about 4 minutes on 2 cores)
test-blender-versions: $(STAMP)
	$(PY) tools/blender_versions.py --out out/blender-versions

# Issue 28's refactoring check: the built-in scenes, every method, a fixed final gather and chains,
# rendered by the command line and hashed; `make golden` (re)records this environment's hashes in
# tests/golden_hashes.json, `make golden-check` compares (tests/test_golden.py does too)
golden: $(STAMP)
	$(PY) tools/golden.py --record

golden-check: $(STAMP)
	$(PY) tools/golden.py

# The demo .blend files, saved by the oldest supported Blender (4.2 cannot read what 5.0 writes; every
# later Blender opens 4.2's files): the oldest env with this checkout's core and add-on on the path
demo-scenes: $(OLDEST)/.installed
	PYTHONPATH=core:. $(OLDEST)/bin/python demo_scenes/make_demo_scenes.py --out demo_scenes

clean:
	rm -rf $(VENV) $(OLDEST) out .pytest_cache dist build
