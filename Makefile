# collie — `make demo` and `make test` set up .venv themselves on a fresh machine.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
# torch is pinned; PyPI's Linux wheel carries GBs of CUDA packages. On a machine without nvidia-smi whose
# network reaches PyTorch's CPU index, pip also looks there and takes the CPU wheel (2.13.0+cpu ranks
# above 2.13.0); otherwise pip's own configuration decides (here: a local CPU wheel). A GPU host gets
# PyPI's CUDA build; `make setup TORCH_INDEX=` skips the CPU index anywhere, TORCH_INDEX=URL names another.
TORCH_SPEC ?= torch==2.13.0
TORCH_CPU_INDEX := https://download.pytorch.org/whl/cpu
TORCH_INDEX ?= $(shell command -v nvidia-smi >/dev/null || { $(PYTHON) -c "import urllib.request as u; u.urlopen('$(TORCH_CPU_INDEX)/torch/', timeout=5)" >/dev/null 2>&1 && echo $(TORCH_CPU_INDEX); })
STAMP := $(VENV)/.stamp-install
# Debian packages: Chromium for the browser tests, EGL (Mesa) for MuJoCo's offscreen rendering.
SYSTEM_PACKAGES := chromium libegl1 libegl-mesa0 libgl1 libgles2 libosmesa6 fonts-liberation postgresql
SYS_STAMP := $(VENV)/.stamp-system
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: setup demo demo-oracle test test-compile lint bench-guidance bench-update profile-update bench-contention bench-first-segment bench-gpu bench-exit bench-service bench-pixels bench-encoders probe-quadruped-gait probe-car bench-labeling bench-browser-ceiling bench-dashboard bench-baselines bench-robots bench-chaos clean

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
	$(PY) -m pip install -q $(if $(TORCH_INDEX),--extra-index-url $(TORCH_INDEX)) "$(TORCH_SPEC)"
	$(PY) -m pip install -q mujoco==3.17.0
	$(PY) -m pip install -q -e ".[trainer,service,ui,dev,sweep]"
	@touch $(STAMP)

setup: $(STAMP)

# The main job: service + trainer + labeling UI on the embedded SQLite; you label in the browser.
demo: $(STAMP)
	@echo "results go to runs/demo/trainer/ (skills_latest.png, metrics.jsonl); Ctrl-C stops the stack, the same command resumes it"
	$(VENV)/bin/collie up --env point --task north --method collie --preset cpu --out runs/demo

# The same loop, unattended: the scripted oracle labels through the same API.
demo-oracle: $(STAMP)
	$(VENV)/bin/collie up --env point --task north --method collie --preset cpu --teacher oracle \
	  --out runs/demo-oracle --exit-when-done
	@echo "plots: runs/demo-oracle/trainer/skills_latest.png · metrics: runs/demo-oracle/trainer/metrics.jsonl"

# ruff (rules and one format), mypy (pyproject's [tool.mypy]) and the import contracts / type-ignore reasons.
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy
	$(VENV)/bin/pytest -q -p no:cacheprovider tests/lint

# Two workers, one file each at a time (module fixtures stay in one process), one OpenMP thread
# each: the suite waits on subprocesses and browsers as much as it computes.
TEST_WORKERS ?= 2
test: $(STAMP) lint
	OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OMP_WAIT_POLICY=PASSIVE \
	  $(VENV)/bin/pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=15

# `--compile`'s networks equal the eager ones (pyproject's `compile` marker; inductor takes minutes here).
test-compile: $(STAMP)
	$(VENV)/bin/pytest -q -m compile tests/core/test_update_paths.py

# The settings docs/results.md's point-mass numbers were measured with, before the reference's
# initialisation, policy log-std floor and DIAYN variant became the defaults (docs/algorithm.md),
# before rollouts acted through trainer/acting.py's Actor (`--acting torch`: the same seeds), and
# before the step's fused Adam and fast tanh / one-output Q layer (`--fused-adam false --fast-ops false`).
# `make bench-guidance FIRST_VERSION_FLAGS=` measures today's defaults instead.
FIRST_VERSION_FLAGS ?= --init torch --log-std-min=-5 --diayn sphere --acting torch --fused-adam false --fast-ops false --flush-denormal false

# Every bench-* but bench-baselines and bench-robots (collie report tables) also writes its figures to
# runs/bench/<name>.json (benchmarks/record.py).
bench-guidance: $(STAMP)
	$(PY) benchmarks/bench_guidance.py -- $(FIRST_VERSION_FLAGS)

bench-update: $(STAMP)
	$(PY) benchmarks/bench_update.py

# Where a 2×256 update's CPU time goes (torch.profiler): matmul and Adam shares.
profile-update: $(STAMP)
	$(PY) benchmarks/profile_update.py

# A point run alone and beside one busy process (trainer/threads.py's defaults hold their share).
bench-contention: $(STAMP)
	$(PY) benchmarks/bench_contention.py

# Seconds from `collie up` to the first labelable segment, split by part;
# e.g. FIRST_SEGMENT_ARGS="--env ant --runs quiet" (issue 12's Ant stack), "--browser" (the segment on screen)
FIRST_SEGMENT_ARGS ?=
bench-first-segment: $(STAMP)
	$(PY) benchmarks/bench_first_segment.py $(FIRST_SEGMENT_ARGS)

# The paper preset on Ant and pixel Quadruped on a CUDA GPU; prints `no CUDA device` without one.
bench-gpu: $(STAMP)
	$(PY) benchmarks/bench_gpu.py

# The end of a `collie train`: with collie.cli.entry's gc.freeze() and without it (main alone).
bench-exit: $(STAMP)
	$(PY) benchmarks/bench_exit.py

bench-service: $(STAMP)
	$(PY) benchmarks/bench_service.py

bench-dashboard: $(STAMP)
	$(PY) benchmarks/bench_dashboard.py

bench-labeling: $(STAMP)
	$(PY) benchmarks/bench_labeling.py

# The browser's own limit: viser pages with nothing of ours, still and with one node moved at 30 Hz.
bench-browser-ceiling: $(STAMP)
	$(PY) benchmarks/bench_browser_ceiling.py

bench-pixels: $(STAMP)
	$(PY) benchmarks/bench_pixels.py

bench-encoders: $(STAMP)
	$(PY) benchmarks/bench_encoders.py

# How far open-loop gaits carry the pixel Quadruped (seconds; docs/results.md's gait figures).
probe-quadruped-gait: $(STAMP)
	$(PY) benchmarks/probe_quadruped_gait.py --seeds 4

# How the car moves: distance and top speed at full throttle, spin rate, veer with and without elliptic cones.
probe-car: $(STAMP)
	$(PY) benchmarks/probe_car.py --seeds 8

# kill -9 ×100 over service, trainer, teacher and labeling UI during a 1000-label oracle run under collie up.
bench-chaos: $(STAMP)
	$(PY) benchmarks/bench_chaos.py

# Issue 7's comparison: every method on the point tasks, 3 seeds, then the paper-format report
# (hours on 2 cores; resumable: rerun it to continue). docs/results.md says what it measured.
# (Its HalfCheetah line moved to bench-robots, at the robots' own budget.)
BASELINE_RUNS ?= runs/baselines
bench-baselines: $(STAMP)
	$(VENV)/bin/collie sweep --env point --tasks north,range,hole_north,hole,range_north \
	  --methods oracle,collie,dodont,ddg,metra,lsd,diayn --seeds 3 --preset cpu --jobs 2 --downstream --out $(BASELINE_RUNS) \
	  --no-report -- $(FIRST_VERSION_FLAGS)
	$(VENV)/bin/collie sweep --env point --tasks north,range,hole_north --methods dodont --variant paper_protocol \
	  --seeds 1 --preset cpu --jobs 2 --out $(BASELINE_RUNS) --bin-rule visited \
	  -- --segment-length 201 --queries-per-session 2 --query-strategy uniform $(FIRST_VERSION_FLAGS)
	# OUT/report by the visited rule, as docs/results.md's point-mass tables

# Issue 12: the real robots at the `cpu` preset's robot budget (trainer/config.py ROBOT_CPU: about an
# hour per run, two at a time on 2 cores), then one report with the paper's Tables 1-3 beside ours.
# METRA never reads its task while it trains, so it is trained on one task per env and judged by the
# others' rules with `collie rescore` (same skills, no extra training; docs/baselines.md).
# Ant (2000 epochs, 53-59 min per run): 33 trained runs + 9 rescored, zero-shot motion on each; HalfCheetah: 15 trained + 3 rescored and
# the hierarchical Goal task; pixel Quadruped North, 1 seed, at a budget measured to finish in <= 3 h
# (PIXEL_ROBOT_FLAGS: 109 and 172 min here; its skills still do not move, docs/results.md). About a day of wall time on 2 cores (Ant ≈ 15 h); resumable: rerun it to continue.
# docs/results.md says what it measured; results/robots keeps each finished run's results (collie archive).
ROBOT_RUNS ?= runs/robots
PIXEL_ROBOT_FLAGS ?= --epochs 400 --grad-steps 16 --batch-size 32 --warmup 80 --feedback-every 40 --total-queries 40 \
  --replay-capacity 50000 --eval-every 50 --checkpoint-every 50
bench-robots: $(STAMP)
	$(VENV)/bin/collie sweep --env ant --tasks north,range,hole,hole_north --methods oracle,collie \
	  --seeds 3 --preset cpu --jobs 2 --downstream --no-report --out $(ROBOT_RUNS)/ant
	$(VENV)/bin/collie sweep --env ant --tasks north --methods metra,dodont,ddg \
	  --seeds 3 --preset cpu --jobs 2 --downstream --no-report --out $(ROBOT_RUNS)/ant
	for task in range hole hole_north; do \
	  $(VENV)/bin/collie rescore $(ROBOT_RUNS)/ant/ant-north-metra-s{0,1,2} --task $$task --keep-existing --downstream || exit 1; \
	done
	$(VENV)/bin/collie sweep --env half_cheetah --tasks right,not_flip --methods oracle,collie \
	  --seeds 3 --preset cpu --jobs 2 --downstream --no-report --out $(ROBOT_RUNS)/half_cheetah
	$(VENV)/bin/collie sweep --env half_cheetah --tasks right --methods metra \
	  --seeds 3 --preset cpu --jobs 2 --downstream --no-report --out $(ROBOT_RUNS)/half_cheetah
	$(VENV)/bin/collie rescore $(ROBOT_RUNS)/half_cheetah/half_cheetah-right-metra-s{0,1,2} --task not_flip \
	  --keep-existing --downstream
	$(VENV)/bin/collie sweep --env quadruped --tasks north --methods metra,collie \
	  --seeds 1 --preset cpu --jobs 2 --no-report --out $(ROBOT_RUNS)/quadruped -- $(PIXEL_ROBOT_FLAGS)
	$(VENV)/bin/collie report $(ROBOT_RUNS) --out $(ROBOT_RUNS)/report
	$(VENV)/bin/collie archive $(ROBOT_RUNS) --out results/robots

clean:
	rm -rf runs .pytest_cache .ruff_cache
