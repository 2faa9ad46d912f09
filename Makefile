# collie — `make demo` and `make test` set up .venv themselves on a fresh machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# CPU Linux: the pinned CPU wheel (an unpinned torch pulls GBs of CUDA). On a GPU host: make TORCH_SPEC=torch==2.13.0 PIP_TORCH_INDEX=
TORCH_SPEC ?= torch==2.13.0
STAMP := $(VENV)/.stamp-install
# Debian packages: Chromium for the browser tests, EGL (Mesa) for MuJoCo's offscreen rendering.
SYSTEM_PACKAGES := chromium libegl1 libegl-mesa0 libgl1 libgles2 libosmesa6 fonts-liberation postgresql
SYS_STAMP := $(VENV)/.stamp-system
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: setup demo demo-oracle test lint bench-guidance bench-update bench-service bench-pixels bench-encoders bench-labeling bench-dashboard bench-baselines clean

$(SYS_STAMP):
	@mkdir -p $(VENV)
	@if command -v dpkg >/dev/null && ! dpkg -s $(SYSTEM_PACKAGES) >/dev/null 2>&1; then \
	  echo "installing Debian packages: $(SYSTEM_PACKAGES)"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $(SYSTEM_PACKAGES) >/dev/null; \
	fi
	@touch $(SYS_STAMP)

$(STAMP): pyproject.toml Makefile $(SYS_STAMP)
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "$(TORCH_SPEC)" mujoco==3.17.0
	$(PY) -m pip install -q -e ".[trainer,service,ui,dev]"
	@touch $(STAMP)

setup: $(STAMP)

# The main job: service + trainer + labeling UI on the embedded SQLite; you label in the browser.
demo: $(STAMP)
	$(VENV)/bin/collie up --env point --task north --method collie --preset cpu --out runs/demo
	@echo "plots: runs/demo/trainer/skills_latest.png · metrics: runs/demo/trainer/metrics.jsonl"

# The same loop, unattended: the scripted oracle labels through the same API.
demo-oracle: $(STAMP)
	$(VENV)/bin/collie up --env point --task north --method collie --preset cpu --teacher oracle \
	  --out runs/demo-oracle --exit-when-done
	@echo "plots: runs/demo-oracle/trainer/skills_latest.png · metrics: runs/demo-oracle/trainer/metrics.jsonl"

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

test: $(STAMP) lint
	$(VENV)/bin/pytest -q

bench-guidance: $(STAMP)
	$(PY) benchmarks/bench_guidance.py

bench-update: $(STAMP)
	$(PY) benchmarks/bench_update.py

bench-service: $(STAMP)
	$(PY) benchmarks/bench_service.py

bench-dashboard: $(STAMP)
	$(PY) benchmarks/bench_dashboard.py

bench-labeling: $(STAMP)
	$(PY) benchmarks/bench_labeling.py

bench-pixels: $(STAMP)
	$(PY) benchmarks/bench_pixels.py

bench-encoders: $(STAMP)
	$(PY) benchmarks/bench_encoders.py

# Issue 7's comparison: every method on the point tasks, 3 seeds, then the paper-format report
# (hours on 2 cores; resumable: rerun it to continue). docs/results.md says what it measured.
BASELINE_RUNS ?= runs/baselines
bench-baselines: $(STAMP)
	$(VENV)/bin/collie sweep --env point --tasks north,range,hole_north,hole,range_north \
	  --methods oracle,collie,dodont,ddg,metra,lsd,diayn --seeds 3 --preset cpu --jobs 2 --downstream --out $(BASELINE_RUNS)
	$(VENV)/bin/collie sweep --env point --tasks north,range,hole_north --methods dodont --variant paper_protocol \
	  --seeds 1 --preset cpu --jobs 2 --out $(BASELINE_RUNS) -- --segment-length 201 --queries-per-session 2 --query-strategy uniform
	$(VENV)/bin/collie sweep --env half_cheetah --tasks right,not_flip --methods oracle,collie,metra \
	  --seeds 1 --preset cpu --jobs 2 --downstream --out $(BASELINE_RUNS)-cheetah -- --epochs 300
	$(VENV)/bin/collie report $(BASELINE_RUNS) $(BASELINE_RUNS)-cheetah --out $(BASELINE_RUNS)/report

clean:
	rm -rf runs .pytest_cache .ruff_cache
