# Two commands do all the set-up on a fresh machine (pip only, no sudo):
#   make demo   -> creates .venv, installs asmteach, runs the demo
#   make test   -> creates .venv, installs asmteach with test tools, runs ruff and pytest
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= out/demo
# pytest processes; the slow end-to-end tests take minutes each, so two cores halve the suite's time
TEST_WORKERS ?= 2

.PHONY: demo test lint install clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Reinstall whenever packaging metadata changes (entry points live there).
$(STAMP): $(BIN)/python pyproject.toml setup.py
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/asmteach run configs/demo.yaml --out $(OUT) || echo "the parts did not end assembled: the report says where and why"

lint: $(STAMP)
	$(BIN)/ruff check .

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS)

clean:
	rm -rf $(VENV) out build *.egg-info
