# The two commands of the README: `make demo` and `make test`. Both create .venv on first use.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install demo test bench clean

install: $(STAMP)

# torch comes first and pinned: on our machines torch==2.13.0 is a CPU build on local disk,
# while a plain `torch` (or any range that admits a newer release) pulls a multi-GB CUDA build.
# The rest at the versions of constraints.txt, the same on every machine (labels move with them).
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet "torch==2.13.0"
	$(PY) -m pip install --quiet -e ".[dev]" -c constraints.txt
	# best effort: Debian's chromium for the browser tests of `hollowtree view` (they skip without it)
	-command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
		{ DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium || { apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; }; } >/dev/null 2>&1; } || true
	touch $(STAMP)

# The bundled default: workflows/local.yaml makes a labelled 1 M-point scan of the Wazir Khan
# mosque on first use and runs every stage on it on a local Dask cluster; a rerun resumes
# (or says there is nothing to do).
demo: $(STAMP)
	mkdir -p out
	$(VENV)/bin/hollowtree run workflows/local.yaml

# Two pytest workers, one per core, each taking whole files (a file's module fixtures are
# built once): 604 s against 820 s one after another, measured side by side.
test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile --durations=15

bench: $(STAMP)
	$(PY) benchmarks/bench_synth.py
	$(PY) benchmarks/bench_ingest.py

clean:
	rm -rf $(VENV) out .pytest_cache
