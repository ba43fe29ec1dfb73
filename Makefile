# The two commands of the README. Each creates .venv on a fresh machine.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test install clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[test]"
	@# compile the numba kernels once into their cache (otherwise every test worker compiles them)
	$(BIN)/python -c "from problems.inverse.cases import CASES; from problems.inverse.forward import case_material; import numpy as np; [case_material(c, c.reference).update(np.full((2, 6), -1e-3), np.zeros((2, 6)), np.zeros((2, 7))) for c in CASES.values()]"
	$(BIN)/python -c "from problems.fe.mesh import box_mesh; from problems.fe.newton import discretise, run; from problems.materials import LinearElastic; run(discretise(box_mesh(1, 1, 2)), LinearElastic())"
	touch $(STAMP)

install: $(STAMP)

## make run: the default suite (coarse mesh; 6,6,12:g8:hex27 on model-error data), then its report, under results/
run: $(STAMP)
	$(BIN)/femubench run suites/default.toml --out results/default
	$(BIN)/femubench report results/default --format md,csv,tex

## make test: the linter (ruff), then the fast, deterministic test suite (slow checks: make test-slow)
test: $(STAMP)
	$(BIN)/ruff check .
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 $(BIN)/python -m pytest -n 2

test-slow: $(STAMP)
	$(BIN)/python -m pytest -m slow

clean:
	rm -rf $(VENV) build *.egg-info
