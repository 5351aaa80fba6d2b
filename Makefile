# The two commands a newcomer needs: `make demo` and `make test`. Both build .venv from nothing.
# `make docs` builds the documentation site (MkDocs Material) into build/site.
# `make demo` installs only the runtime dependencies; `make test` adds the test extras (pytest, nbmake, MuJoCo,
# playwright, nbstripout, pytest-xdist) on top, each behind its own stamp so one never reinstalls the other.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
RUNTIME := $(VENV)/.installed-runtime
TESTDEPS := $(VENV)/.installed-test
DOCSDEPS := $(VENV)/.installed-docs
# JupyterLab refuses to start as root without --allow-root; a user never needs it.
LAB_ROOT := $(if $(filter 0,$(shell id -u)),--allow-root,)

.PHONY: venv dev demo test docs lab bench clean

$(RUNTIME): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e .
	touch $(RUNTIME)

$(TESTDEPS): $(RUNTIME) pyproject.toml
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(TESTDEPS)

$(DOCSDEPS): $(RUNTIME) pyproject.toml
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	touch $(DOCSDEPS)

venv: $(RUNTIME)

# the venv with the test tools (pytest, nbmake, nbstripout), without running the suite
dev: $(TESTDEPS)

demo: $(RUNTIME)
	$(BIN)/workbench demo --out build/demo

test: $(TESTDEPS)
	$(BIN)/python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile --durations=25 --nbmake tests notebooks

# The documentation site, into build/site; --strict turns a broken link or a public function without a docstring
# into a failure.
docs: $(DOCSDEPS)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

lab: $(RUNTIME)
	$(BIN)/jupyter lab $(LAB_ROOT) --ContentsManager.pre_save_hook=workbench.widgets.saving.strip_widget_views notebooks/

bench: $(RUNTIME)
	$(BIN)/workbench bench grasps
	$(BIN)/workbench bench placements
	$(BIN)/workbench bench ik
	$(BIN)/workbench bench regrasp
	$(BIN)/workbench bench motion
	$(BIN)/workbench bench fingers
	$(BIN)/workbench bench gptable
	$(BIN)/workbench bench catalog

clean:
	rm -rf build .pytest_cache
