# collie — `make demo` and `make test` set up .venv themselves on a fresh machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# CPU Linux: the pinned CPU wheel (an unpinned torch pulls GBs of CUDA). On a GPU host: make TORCH_SPEC=torch==2.13.0 PIP_TORCH_INDEX=
TORCH_SPEC ?= torch==2.13.0
STAMP := $(VENV)/.stamp-install
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: setup demo test lint bench-guidance bench-update bench-service clean

$(STAMP): pyproject.toml Makefile
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "$(TORCH_SPEC)" mujoco==3.17.0
	$(PY) -m pip install -q -e ".[trainer,service,dev]"
	@touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/collie train --env point --task north --method collie --preset cpu --out runs/demo
	@echo "plots: runs/demo/skills_latest.png runs/demo/curves.png · metrics: runs/demo/metrics.jsonl"

lint: $(STAMP)
	$(VENV)/bin/ruff check .

test: $(STAMP) lint
	$(VENV)/bin/pytest -q

bench-guidance: $(STAMP)
	$(PY) benchmarks/bench_guidance.py

bench-update: $(STAMP)
	$(PY) benchmarks/bench_update.py

clean:
	rm -rf runs .pytest_cache .ruff_cache
