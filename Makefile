# Two commands on a fresh machine: `make demo` and `make test`. Both (re)create .venv from the pins.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= out
PYTEST_ARGS ?=

.PHONY: venv demo test test-core addon clean

venv: $(STAMP)

$(STAMP): requirements.txt pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gg demo --out $(OUT)/demo

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 $(PYTEST_ARGS) tests

test-core: $(STAMP)
	$(BIN)/python -m pytest -n 2 -m "not bpy and not extension" $(PYTEST_ARGS) tests

addon: $(STAMP)
	$(BIN)/python tools/build_addon.py --out $(OUT)/addon

clean:
	rm -rf $(OUT) build *.egg-info
