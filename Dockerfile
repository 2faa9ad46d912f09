# collie images. Two targets from one context:
#   service — the labeling service alone (FastAPI + SQLAlchemy; no torch, no MuJoCo): small, starts in ~1 s;
#   full    — trainer, oracle teacher and labeling UI (extras trainer, service, ui: torch CPU wheel, viser, MuJoCo with EGL/OSMesa).
# Built by docker-compose.yml; by hand: docker build --target service -t collie-service .
FROM python:3.11-slim AS source
ENV PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
WORKDIR /app
COPY pyproject.toml README.md ./
COPY collie ./collie
COPY backend ./backend
COPY teacher ./teacher
COPY trainer ./trainer
COPY labeling_ui ./labeling_ui
COPY web ./web
RUN useradd --create-home --uid 10001 collie && mkdir -p /data /runs && chown collie /data /runs

FROM source AS service
# psycopg: for COLLIE_DATABASE_URL=postgresql+psycopg://… (the compose `postgres` profile).
RUN pip install ".[service]" "psycopg[binary]>=3.1"
USER collie
ENV COLLIE_DATABASE_URL=sqlite:////data/collie.db COLLIE_WEB_DIR=/app/web
EXPOSE 8000
HEALTHCHECK --interval=5s --timeout=3s --retries=12 \
  CMD python -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/api/health', timeout=2)"
# Inside the container the service must listen on all interfaces; compose publishes it on 127.0.0.1 only.
CMD ["collie", "serve", "--host", "0.0.0.0", "--port", "8000", "--tokens-json", "/data/tokens.json"]

FROM source AS full
# Mesa's EGL and its software driver (a Recommends, left out by --no-install-recommends): MUJOCO_GL=egl
# renders the pixel robots offscreen with them, as the Makefile's packages do on a host.
RUN apt-get update \
 && apt-get install -y --no-install-recommends libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libosmesa6 libglib2.0-0 \
 && rm -rf /var/lib/apt/lists/*
# The CPU wheel: an unpinned torch pulls gigabytes of CUDA packages.
RUN pip install --index-url https://download.pytorch.org/whl/cpu "torch==2.13.0" \
 && pip install ".[trainer,service,ui]"
USER collie
# The trainer's --fast-ops measurement (trainer/fast_ops.py) kept on the runs volume, not measured per container.
ENV MUJOCO_GL=egl COLLIE_CACHE_DIR=/runs/.cache
CMD ["collie", "--help"]
