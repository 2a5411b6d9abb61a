# One-command set-up: `make demo` and `make test` create .venv and install everything on first use.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test bench bench-blender bench-boxes bench-bake bench-scale bench-invariance extension cycles-reference clean

$(STAMP): core/pyproject.toml requirements-dev.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-dev.txt -e ./core
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m raybundle render cornell --time 30 --out out/cornell.exr --stats out/cornell.json
	$(PY) -m raybundle_addon demo_scenes/cornell_box.blend --time 30 --out out/cornell_box_blend.exr

test: $(STAMP)
	$(PY) -m pytest -q tests

# Every method on the built-in scenes, 60 s each (12 minutes on 2 cores, plus 10 minutes per missing
# reference half of the Cornell boxes: `make cycles-reference` makes Cycles ones instead)
bench: $(STAMP)
	$(PY) -m raybundle bench --out out/bench

# The RAYBUNDLE engine against Cycles on the Cornell .blend (about 15 minutes on 2 cores)
bench-blender: $(STAMP)
	$(PY) tools/bench_blender.py demo_scenes/cornell_box.blend --out out/bench-blender

# The built-in boxes against Cycles on the same triangles, side by side (about 45 minutes on 2 cores)
bench-boxes: $(STAMP)
	$(PY) tools/bench_blender.py cornell --times 5 10 30 60 120 --out out/bench-cornell --max-cycles-seconds 260
	$(PY) tools/bench_blender.py cornell-glossy --times 5 10 30 60 120 --out out/bench-cornell-glossy --reference-samples 4096 --max-cycles-seconds 200

# The point-domain bake against Cycles' bake of the same 4,624 vertices, and a 1024^2 lightmap
# (about 25 minutes on 2 cores the first time: the Cycles reference is cached in out/bench-bake)
bench-bake: $(STAMP)
	$(PY) tools/bench_bake.py --out out/bench-bake

# The Cornell box meshed with 4k to 4M triangles: error, set-up time and memory against triangle count
# (about 15 minutes on 2 cores and 5 GB of memory; needs out/bench-cornell's Cycles reference from bench-boxes)
bench-scale: $(STAMP)
	$(PY) tools/bench_scale.py --out out/bench-scale --one-patch-per-triangle 4000 16000 64000

# The Cornell .blend described in a dozen ways a Blender user would (subdivided, triangulated, flipped,
# split, joined, instanced, transformed, scaled, reordered) against the file as it is, and the patch
# count as a convergence (about 10 minutes on 2 cores)
bench-invariance: $(STAMP)
	$(PY) tools/bench_invariance.py --out out/bench-invariance

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

clean:
	rm -rf $(VENV) out .pytest_cache dist build
