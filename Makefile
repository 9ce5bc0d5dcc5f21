# SPDX-License-Identifier: GPL-3.0-or-later
# The front door. Every target sets up what it needs (scripts/setup.sh is idempotent).
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out
PRESET ?= wavy

.PHONY: setup demo test test-fast extension bench bench-quick clean

setup:
	@bash scripts/setup.sh

# Generate a preset hairstyle on the bundled scalp, render it with the tracer, export it.
demo: setup
	@mkdir -p $(OUT)
	$(PY) -m groom generate --preset $(PRESET) --out $(OUT)/$(PRESET).npz
	$(PY) -m tracer render $(OUT)/$(PRESET).npz --out $(OUT)/$(PRESET).png --size 512x512 --spp 4 --shadows
	$(PY) -m groom export $(OUT)/$(PRESET).npz --format tfx --out $(OUT)/$(PRESET).tfx
	$(PY) -m groom export $(OUT)/$(PRESET).npz --format hair --out $(OUT)/$(PRESET).hair
	@echo "demo: wrote $(OUT)/$(PRESET).npz, .png, .tfx, .hair"

# The whole suite: groom, hairio, tracer (headless EGL), and the extension under bpy.
test: setup
	$(PY) -m pytest -q tests

extension: setup
	$(PY) scripts/build_extension.py --out dist

bench: setup
	$(PY) -m benchmarks --full

bench-quick: setup
	$(PY) -m benchmarks --quick

clean:
	rm -rf $(OUT) dist build .pytest_cache
