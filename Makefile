# The two commands a newcomer needs: `make demo` and `make test`. Both build .venv from nothing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: venv demo test lab bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/workbench demo --out build/demo

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider --nbmake tests notebooks

lab: $(STAMP)
	$(BIN)/jupyter lab notebooks/

bench: $(STAMP)
	$(BIN)/workbench bench grasps
	$(BIN)/workbench bench placements
	$(BIN)/workbench bench ik
	$(BIN)/workbench bench regrasp
	$(BIN)/workbench bench motion
	$(BIN)/workbench bench fingers

clean:
	rm -rf build .pytest_cache
