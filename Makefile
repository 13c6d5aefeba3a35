# One place that knows how to install: a virtual environment in .venv,
# created on demand. FMUs are built on demand by the code itself.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: reproduce test fmu benchmark clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

reproduce: $(VENV)/.installed
	$(BIN)/fnn-cosim reproduce

# Two processes (pytest-xdist): the tests are independent and share only the
# FMU cache, whose files are written beside their name and renamed into place.
# Bytecode is written even where PYTHONDONTWRITEBYTECODE is set: else every
# process the suite starts (Dask workers, the command line in a fresh
# interpreter) compiles the package again, and pytest rewrites every test
# module on every run (measured: 121.6 s against 133-141 s warm). It goes to
# the usual __pycache__ folders (ignored by git), not to a prefix folder: with
# PYTHONPYCACHEPREFIX Python ignores the bytecode pip wrote for every installed
# package and compiles SciPy, CasADi, Dask, ... again in each process that
# first imports them (a fresh clone's collection: 23.0 against 14.5 CPU-s).
test: $(VENV)/.installed
	PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest -q -n 2 --dist worksteal

fmu: $(VENV)/.installed
	$(BIN)/fnn-cosim build-fmu --out build/fmus

benchmark: $(VENV)/.installed
	$(BIN)/python benchmarks/cli_startup.py
	$(BIN)/python benchmarks/controller_speed.py
	$(BIN)/python benchmarks/cosim_speed.py
	$(BIN)/python benchmarks/loop_speed.py
	$(BIN)/python benchmarks/model_exchange.py
	$(BIN)/python benchmarks/study_efficiency.py
	$(BIN)/python benchmarks/ssp_importers.py
	$(BIN)/python benchmarks/table_replay.py
	$(BIN)/python benchmarks/stability_speed.py

clean:
	rm -rf build results
