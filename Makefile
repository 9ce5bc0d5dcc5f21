# SPDX-License-Identifier: GPL-3.0-or-later
# The front door. Every target sets up what it needs (scripts/setup.sh is idempotent).
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out
PRESET ?= wavy

.PHONY: setup setup-blender demo test test-fast extension bench bench-quick clean

setup:
	@bash scripts/setup.sh

# The Blender test matrix beside .venv (Blender 5.0.1): 4.2 LTS (Python 3.11), 5.3 (Python 3.13).
setup-blender: setup
	@bash scripts/setup_blender.sh

# Generate a preset hairstyle on the bundled scalp, render it with the bundled head in the
# picture (the tracer's opaque meshes), export it.
demo: setup
	@mkdir -p $(OUT)
	$(PY) -m groom generate --preset $(PRESET) --out $(OUT)/$(PRESET).npz
	$(PY) -m groom head --out $(OUT)/head.obj
	$(PY) -m tracer render $(OUT)/$(PRESET).npz --mesh $(OUT)/head.obj --mesh-color 0.62,0.45,0.36 \
		--out $(OUT)/$(PRESET).png --size 512x512 --spp 4 --shadows
	$(PY) -m groom export $(OUT)/$(PRESET).npz --format tfx --out $(OUT)/$(PRESET).tfx
	$(PY) -m groom export $(OUT)/$(PRESET).npz --format hair --out $(OUT)/$(PRESET).hair
	@echo "demo: wrote $(OUT)/$(PRESET).npz, .png (with the head), .tfx, .hair"

# The whole suite: groom, hairio, tracer (headless EGL) and the extension under Blender 5.0;
# the tracer again through GLX on a virtual X server (the tests start Xvfb); the extension's
# tests under Blender 4.2 LTS and 5.3, each installing the real zip with Blender's installer.
BLENDER_TESTS := tests/blender tests/hairio/test_io_blender_export.py
test: setup-blender
	$(PY) -m pytest -q tests
	KEYSTRAND_GL_BACKEND=glx $(PY) -m pytest -q tests/tracer
	.venv-bpy42/bin/python -m pytest -q $(BLENDER_TESTS)
	.venv-bpy53/bin/python -m pytest -q $(BLENDER_TESTS)

extension: setup
	$(PY) scripts/build_extension.py --out dist

bench: setup
	$(PY) -m benchmarks --full

bench-quick: setup
	$(PY) -m benchmarks --quick

clean:
	rm -rf $(OUT) dist build .pytest_cache
