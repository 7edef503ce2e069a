# Two commands on a fresh machine: `make demo` and `make test`. Both (re)create .venv from the pins.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= out
PYTEST_ARGS ?=
# tiny: ~1 min capture (6 cameras); demo: the 12-camera 256 px capture (~17 min to synthesize on 2 cores)
DEMO_PRESET ?= tiny

.PHONY: venv demo test test-core addon clean

venv: $(STAMP)

$(STAMP): requirements.txt pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gg demo --preset $(DEMO_PRESET) --out $(OUT)/demo
	zip=$$($(BIN)/python tools/build_addon.py --out $(OUT)/addon) && \
	$(BIN)/python tools/blender_batch.py --addon "$$zip" --capture $(OUT)/demo/capture --save $(OUT)/demo/blender/capture.blend --user-resources $(OUT)/blender_user

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadgroup $(PYTEST_ARGS) tests

test-core: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadgroup -m "not bpy and not extension" $(PYTEST_ARGS) tests

addon: $(STAMP)
	$(BIN)/python tools/build_addon.py --out $(OUT)/addon

clean:
	rm -rf $(OUT) build *.egg-info
