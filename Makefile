# The two commands of the README: `make demo` and `make test`. Both create .venv on first use.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install demo test bench clean

install: $(STAMP)

# torch comes first and pinned: on our machines torch==2.13.0 is a CPU build on local disk,
# while a plain `torch` (or any range that admits a newer release) pulls a multi-GB CUDA build.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet "torch==2.13.0"
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

# The bundled default: a labelled 1 M-point scan of the Wazir Khan mosque, ingested into a
# run store and coarse-segmented (the later stages join as they land).
demo: $(STAMP)
	mkdir -p out
	$(VENV)/bin/hollowtree synth wazir_khan --points 1000000 --out out/wazir_khan.laz --overwrite
	rm -rf out/wazir_khan.zarr
	$(VENV)/bin/hollowtree ingest out/wazir_khan.laz --store out/wazir_khan.zarr
	$(VENV)/bin/hollowtree coarse out/wazir_khan.zarr

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) benchmarks/bench_synth.py
	$(PY) benchmarks/bench_ingest.py

clean:
	rm -rf $(VENV) out .pytest_cache
