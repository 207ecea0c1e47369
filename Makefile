# Two commands do all the set-up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(PY) -m zmap.demo out

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadgroup -q --durations=20

bench: $(STAMP)
	$(PY) bench/interpolate.py

clean:
	rm -rf out .pytest_cache
