# Two commands do everything on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# The CPU build of PyTorch; an unpinned torch would pull the multi-GB CUDA build.
TORCH_PIN := torch==2.13.0

.PHONY: demo test docs setup clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# setup.py builds torchgrade/lut/lookup.c into the package (an editable install builds it in place).
$(VENV)/.installed: pyproject.toml setup.py torchgrade/lut/lookup.c | $(BIN)/python
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(TORCH_PIN)
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $@

setup: $(VENV)/.installed

demo: setup
	$(BIN)/torchgrade demo --output demo.png

# One worker per core (at most 4), each test's name and outcome as it ends, the 20 slowest at the end.
test: setup
	$(BIN)/python -m pytest -n auto --maxprocesses 4 --dist loadgroup -v --durations 20

# The documentation site (docs/, mkdocs.yml) into build/site; `$(BIN)/mkdocs serve` shows it while editing.
docs: setup
	$(BIN)/mkdocs build --strict --site-dir build/site

clean:
	rm -rf $(VENV) demo.png build/site
