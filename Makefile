# Two commands do all the set-up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast bench docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[all,dev]'
	touch $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(PY) -m zmap.demo out

test: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadgroup -q --durations=20

# the quick check while editing: everything but the cases marked slow (real parts end to end,
# notebooks, anything over about a second)
test-fast: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadgroup -q -m "not slow"

bench: $(STAMP)
	$(PY) bench/interpolate.py

# the API reference from the docstrings (docs/api/), warnings are errors; open docs/api/_build/html/index.html
docs: $(STAMP)
	$(PY) -m sphinx -W --keep-going -b html docs/api docs/api/_build/html -q

clean:
	rm -rf out .pytest_cache
