"""Labeling-service throughput and latency on loopback, beside a plain one-row-insert FastAPI
endpoint measured in the same run (`make bench-service`).

Measured, each in its own server process (uvicorn, SQLite file in WAL mode):
- baseline: POST of one small JSON body → one INSERT with SQLAlchemy, paced like the labelers;
- collie, 1000 queries posted: the time for one POST of a 1000-segment session (Ant-sized: H=20,
  obs 29, qpos 15, qvel 14, a 201-point path) until all 1000 are claimable;
- collie, label submissions from 50 concurrent labelers (each its own token and keep-alive
  connection; claim, then label), paced at an offered total rate: achieved labels/s, p50/p99;
- collie, service start: import and app construction (migrations included), fresh interpreter;
- collie, label submitted → applied by a trainer-side reader of the run's stream (the long poll of
  trainer/feedback/http.py, in its own process): p50/p99;
- collie, a session body at the size limit (--big-mib, default the 128 MiB limit): the server's
  peak RSS growth over the body's size, and /api/health p99 (pinged every 10 ms) while it is parsed;
- collie, 1000 idle SSE streams: the server's CPU, as a share of one core.
Each is measured on SQLite with synchronous=FULL (the default: an acknowledged label survives a
power cut), on SQLite with NORMAL (the cost of FULL) and on a real PostgreSQL server (Debian's
postgresql 15, started by the bench; --no-postgres skips it).
Targets: ≥ 1000 labels/s with p99 ≤ 20 ms; stream p99 ≤ 50 ms; 1000 queries claimable ≤ 1 s; body at
the limit: RSS growth ≤ 2× its size, health p99 ≤ 100 ms; 1000 idle streams ≤ 5 % of a core.
Bounded: fixed durations and counts; everything runs on 127.0.0.1.
JSON (runs/bench/service.json): one object per configuration, under its name, with baseline_rps,
baseline_p50_ms, baseline_p99_ms, label_rps, label_p50_ms, label_p99_ms, claim_p99_ms,
stream_p50_ms, stream_p99_ms, post_1000_s, stream_missing, baseline_cpu_ms, label_cpu_ms,
big_body_mib, big_body_rss_growth_ratio, big_body_health_p99_ms, idle_streams,
idle_streams_core_share; and startup_s, the service start. Settings: rate, seconds, big_mib,
streams.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from fastapi import FastAPI
from pydantic import BaseModel
from record import record
from sqlalchemy import Float, Integer, String, create_engine, event
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column

from collie.client import CollieClient
from collie.schemas import EnvDims, LabelChangedEvent, RunCreate, SessionPost

LABELERS = 50
ANT = EnvDims(obs_dim=29, nq=15, nv=14, horizon=20, skill_dim=2)


# ---------------------------------------------------------------- a minimal HTTP/1.1 load client


class Connection:
    """One keep-alive HTTP/1.1 connection; far cheaper per request than a general client, so the
    load generator does not starve the server of the machine's two cores."""

    def __init__(self, host: str, port: int, token: str = "") -> None:
        self.host, self.port, self.token = host, port, token

    async def open(self) -> Connection:
        self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        return self

    async def request(self, method: str, path: str, body: bytes = b"") -> tuple[int, bytes]:
        return await asyncio.wait_for(self._request(method, path, body), 60)  # a stuck server fails the bench

    async def _request(self, method: str, path: str, body: bytes) -> tuple[int, bytes]:
        head = f"{method} {path} HTTP/1.1\r\nHost: {self.host}\r\nContent-Length: {len(body)}\r\n"
        if self.token:
            head += f"Authorization: Bearer {self.token}\r\n"
        if body:
            head += "Content-Type: application/json\r\n"
        self.writer.write(head.encode() + b"\r\n" + body)
        await self.writer.drain()
        header = await self.reader.readuntil(b"\r\n\r\n")
        status = int(header[9:12])
        length = 0
        for line in header.split(b"\r\n"):
            if line[:15].lower() == b"content-length:":
                length = int(line[15:])
        return status, await self.reader.readexactly(length) if length else b""

    def close(self) -> None:
        self.writer.close()


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values) * 1000.0, q)) if values else float("nan")


# ---------------------------------------------------------------- servers


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_up(url: str, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if httpx.get(url, timeout=1).status_code < 500:
                return
        except httpx.TransportError:
            time.sleep(0.05)
    raise RuntimeError(f"{url} did not come up")


class BaselineBase(DeclarativeBase):
    pass


class BaselineRow(BaselineBase):
    __tablename__ = "rows"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    query_id: Mapped[str] = mapped_column(String(64))
    value: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[float] = mapped_column(Float)


class BaselineBody(BaseModel):
    query_id: str
    value: int


def baseline_app(db: str) -> FastAPI:
    """The plain one-row-insert endpoint the figures are compared with (sync handler, ORM session,
    SQLite in WAL mode: the textbook FastAPI + SQLAlchemy setup)."""
    engine = create_engine(f"sqlite:///{db}", connect_args={"check_same_thread": False})

    @event.listens_for(engine, "connect")
    def _wal(dbapi_connection: Any, _: Any) -> None:
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.close()

    BaselineBase.metadata.create_all(engine)
    app = FastAPI()

    @app.post("/insert")
    def insert(body: BaselineBody) -> dict[str, bool]:
        with Session(engine) as session:
            session.add(BaselineRow(query_id=body.query_id, value=body.value, created_at=time.time()))
            session.commit()
        return {"ok": True}

    @app.get("/health")
    def health() -> dict[str, bool]:
        return {"ok": True}

    return app


def serve_baseline(port: int, db: str) -> None:
    import uvicorn

    uvicorn.run(baseline_app(db), host="127.0.0.1", port=port, log_level="warning", access_log=False)


# ---------------------------------------------------------------- workloads


async def paced(workers: list[object], rate: float, seconds: float) -> None:
    """Run each worker's `step()` on an open-loop schedule: rate/len(workers) per second each."""
    gap = len(workers) / rate
    start = time.perf_counter() + 0.05

    async def loop(i: int, worker: object) -> None:
        t = start + gap * i / len(workers)
        end = start + seconds
        while t < end:
            delay = t - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)
            await worker.step()  # type: ignore[attr-defined]
            t += gap

    await asyncio.gather(*(loop(i, w) for i, w in enumerate(workers)))


class Inserter:
    def __init__(self, conn: Connection, name: str) -> None:
        self.conn, self.name, self.n = conn, name, 0
        self.latency: list[float] = []

    async def step(self) -> None:
        body = json.dumps({"query_id": f"{self.name}-{self.n}", "value": 1}).encode()
        t = time.perf_counter()
        status, _ = await self.conn.request("POST", "/insert", body)
        self.latency.append(time.perf_counter() - t)
        assert status == 200, status
        self.n += 1


class Labeler:
    """Label what is held and get the next query in the same round trip (?next=true), as the
    labeling UI does; a claim only when nothing is held. The label round trip is what is timed."""

    def __init__(self, conn: Connection, run_id: int) -> None:
        self.conn, self.run_id, self.n = conn, run_id, 0
        self.held: str | None = None
        self.latency: list[float] = []
        self.claim_latency: list[float] = []
        self.sent: dict[str, float] = {}

    async def step(self) -> None:
        if self.held is None:
            t = time.perf_counter()
            status, body = await self.conn.request("POST", f"/api/runs/{self.run_id}/claim")
            self.claim_latency.append(time.perf_counter() - t)
            assert status in (200, 204), (status, body[:200])
            self.held = json.loads(body)["query"]["query_id"] if status == 200 else None
            return
        label = {"query_id": self.held, "value": self.n % 3, "client_request_id": f"{id(self)}-{self.n}"}
        self.n += 1
        self.sent[self.held] = time.monotonic()
        t = time.perf_counter()
        path = f"/api/runs/{self.run_id}/labels?next=true"
        status, body = await self.conn.request("POST", path, json.dumps(label).encode())
        self.latency.append(time.perf_counter() - t)
        assert status == 201, (status, body[:200])
        following = json.loads(body).get("next")
        self.held = following["query"]["query_id"] if following else None


async def run_inserts(port: int, rate: float, seconds: float) -> dict[str, float]:
    conns = [await Connection("127.0.0.1", port).open() for _ in range(LABELERS)]
    workers = [Inserter(c, f"w{i}") for i, c in enumerate(conns)]
    started = time.perf_counter()
    await paced(workers, rate, seconds)
    elapsed = time.perf_counter() - started
    latency = [x for w in workers for x in w.latency]
    for c in conns:
        c.close()
    return {
        "n": len(latency),
        "rps": len(latency) / elapsed,
        "p50": percentile(latency, 50),
        "p99": percentile(latency, 99),
    }


async def run_labels(port: int, run_id: int, tokens: list[str], rate: float, seconds: float) -> tuple[dict, dict]:
    conns = [await Connection("127.0.0.1", port, t).open() for t in tokens]
    workers = [Labeler(c, run_id) for c in conns]
    started = time.perf_counter()
    await paced(workers, rate, seconds)
    elapsed = time.perf_counter() - started
    for c in conns:
        c.close()
    latency = [x for w in workers for x in w.latency]
    claims = [x for w in workers for x in w.claim_latency]
    figures = {
        "rps": len(latency) / elapsed,
        "p50": percentile(latency, 50),
        "p99": percentile(latency, 99),
        "claim_p99": percentile(claims, 99),
    }
    return figures, {q: t for w in workers for q, t in w.sent.items()}


def stream_reader(api: str, token: str, run_id: int, after: int, done: Any, out: mp.Queue) -> None:
    """The trainer's side, in its own process: the feedback source's long poll, timestamping when
    each label is applied (time.monotonic is one clock for every process on Linux). Runs until
    `done` is set, then drains what is left."""
    from trainer.feedback.http import HttpFeedback

    seen: dict[str, float] = {}

    class Timed(HttpFeedback):
        def _apply(self, events: list) -> None:
            super()._apply(events)
            now = time.monotonic()
            for e in events:
                if isinstance(e, LabelChangedEvent):
                    seen.setdefault(e.data.query_id, now)

    source = Timed(api, token, run_id, wait_chunk_s=1.0)
    source._after = after
    out.put("ready")
    while not done.is_set():
        source._pump(1.0)
    source._pump(0.0)
    source.close()
    out.put(seen)


def session(session_index: int, n: int, dims: EnvDims, rng: np.random.Generator) -> dict[str, Any]:
    """A session body as plain JSON-ready data (random frames: full-precision floats, the worst case)."""
    h = dims.horizon

    def rows(*shape: int) -> list[Any]:
        return rng.normal(size=shape).tolist()

    queries = [
        {
            "query_id": f"s{session_index}-q{j}",
            "start": j,
            "score": float(rng.random()),
            "skill": rows(dims.skill_dim),
            "obs": rows(h, dims.obs_dim),
            "xy": rows(h, 2),
            "pitch": rows(h),
            "qpos": rows(h, dims.nq),
            "qvel": rows(h, dims.nv),
            "path_xy": rows(201, 2),
        }
        for j in range(n)
    ]
    return {"session": session_index, "epoch": session_index, "queries": queries}


# ---------------------------------------------------------------- main


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rate", type=float, default=1000.0, help="offered labels (and inserts) per second")
    parser.add_argument("--seconds", type=float, default=4.0, help="length of each paced phase")
    parser.add_argument("--big-mib", type=float, default=128.0, help="size of the large session body (MiB)")
    parser.add_argument("--streams", type=int, default=1000, help="idle SSE streams to hold open")
    parser.add_argument("--no-postgres", action="store_true", help="SQLite only")
    parser.add_argument("--baseline-server", nargs=2, metavar=("PORT", "DB"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.baseline_server:
        serve_baseline(int(args.baseline_server[0]), args.baseline_server[1])
        return 0

    tmp = Path(tempfile.mkdtemp(prefix="collie-bench-"))
    base_port = free_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    baseline = subprocess.Popen(
        [sys.executable, __file__, "--baseline-server", str(base_port), str(tmp / "base.db")], env=env
    )
    postgres = None
    configurations = [
        ("SQLite, synchronous=FULL", {"COLLIE_DATABASE_URL": f"sqlite:///{tmp / 'full.db'}"}),
        (
            "SQLite, synchronous=NORMAL",
            {"COLLIE_DATABASE_URL": f"sqlite:///{tmp / 'normal.db'}", "COLLIE_SQLITE_SYNCHRONOUS": "NORMAL"},
        ),
    ]
    try:
        if not args.no_postgres:
            sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
            from tests.service.postgres import PostgresServer

            postgres = PostgresServer().start()
            configurations.append(("PostgreSQL 15", {"COLLIE_DATABASE_URL": postgres.new_database()}))
        wait_up(f"http://127.0.0.1:{base_port}/health")
        results = {}
        for name, extra in configurations:
            say(f"--- {name}")
            results[name] = with_service(args, tmp / name.split(",")[0], {**env, **extra}, base_port, baseline.pid)
            print_figures(name, results[name], args)
        compare(results)
        start_s = startup_seconds(tmp / "start.db")
        print(f"service start (import + migrations, fresh interpreter): {start_s:.2f} s")
        settings = {"rate": args.rate, "seconds": args.seconds, "big_mib": args.big_mib, "streams": args.streams}
        figures = {name: figures_of(f) for name, f in results.items()} | {"startup_s": start_s}
        record("service", figures, settings)  # label_rps follows the offered rate
        return 0
    finally:
        baseline.terminate()
        baseline.wait(10)
        if postgres is not None:
            postgres.stop()


def with_service(args: argparse.Namespace, tmp: Path, env: dict[str, str], base_port: int, base_pid: int) -> dict:
    """Start `collie serve` with `env` (its database), measure everything against it, stop it."""
    tmp.mkdir(parents=True, exist_ok=True)
    tokens_file = tmp / "tokens.json"
    tokens_file.unlink(missing_ok=True)
    command = [sys.executable, "-m", "collie.cli", "serve", "--port", "0", "--tokens-json", str(tokens_file)]
    service = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120  # a busy machine can take a while to start a server
        while not tokens_file.exists() and time.monotonic() < deadline and service.poll() is None:
            time.sleep(0.05)
        info = json.loads(tokens_file.read_text())
        api, tokens = info["api"], info["tokens"]
        wait_up(f"{api}/api/health")
        big = big_body(api, tokens, service.pid, args.big_mib)  # first: a fresh process has no freed memory to reuse
        figures = measure(
            args, api, int(api.rsplit(":", 1)[1]), tokens, base_port, {"collie": service.pid, "baseline": base_pid}
        )
        figures["big"] = big
        figures["streams"] = idle_streams(api, tokens, service.pid, args.streams)
        return figures
    finally:
        service.terminate()
        service.wait(10)


def startup_seconds(db: Path) -> float:
    """Import the service and build the app (migrations included) in a fresh interpreter."""
    code = (
        "import time; t = time.perf_counter(); from backend.main import create_app; "
        f"from backend.settings import Settings; create_app(Settings(database_url='sqlite:///{db}')); "
        "print(time.perf_counter() - t)"
    )
    return float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)


def say(message: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux /proc): unlike wall-clock latency, it does
    not grow when other work shares the machine."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(
    args: argparse.Namespace, api: str, port: int, tokens: dict[str, str], base_port: int, pids: dict[str, int]
) -> dict[str, Any]:
    say("posting sessions")
    rng = np.random.default_rng(0)
    n_labels = int(args.rate * args.seconds * 1.2) + LABELERS
    trainer = CollieClient(api, tokens["trainer"], timeout_s=120)
    operator = CollieClient(api, tokens["operator"])
    run = trainer.create_run(RunCreate(env="ant", task="north", method="collie", dims=ANT))
    labelers = [operator.create_labeler(f"bench-{i}").token for i in range(LABELERS)]

    # Timed: the trainer's own path (wire models built and checked client-side, then one POST).
    first = SessionPost.model_validate(session(0, 1000, ANT, rng))
    started = time.perf_counter()
    trainer.post_session(run.id, first)
    post_s = time.perf_counter() - started
    assert trainer.run(run.id).queue.pending == 1000
    for s in range(1, (n_labels + 999) // 1000):  # more queries to label, posted untimed
        headers = {"Authorization": f"Bearer {tokens['trainer']}", "Content-Type": "application/json"}
        body = json.dumps(session(s, 1000, ANT, rng))
        httpx.post(f"{api}/api/runs/{run.id}/sessions", content=body, headers=headers, timeout=300).raise_for_status()

    say("baseline inserts")
    asyncio.run(run_inserts(base_port, args.rate, 1.0))  # warm-up
    cpu = cpu_seconds(pids["baseline"])
    base = asyncio.run(run_inserts(base_port, args.rate, args.seconds))
    base["cpu_ms"] = 1000 * (cpu_seconds(pids["baseline"]) - cpu) / base["n"]

    queue: mp.Queue = mp.Queue()
    after = trainer.run(run.id).last_event_id
    done = mp.Event()
    reader = mp.Process(target=stream_reader, args=(api, tokens["trainer"], run.id, after, done, queue))
    reader.start()
    assert queue.get(timeout=30) == "ready"
    time.sleep(0.5)
    say("labels")
    cpu = cpu_seconds(pids["collie"])
    labels, sent = asyncio.run(run_labels(port, run.id, labelers, args.rate, args.seconds))
    labels["cpu_ms"] = 1000 * (cpu_seconds(pids["collie"]) - cpu) / len(sent)
    done.set()
    applied: dict[str, float] = queue.get(timeout=120)
    reader.join(10)
    stream = [applied[q] - t for q, t in sent.items() if q in applied]
    missing = len(sent) - len(stream)

    trainer.close()
    operator.close()
    return {
        "base": base,
        "labels": labels,
        "stream": stream,
        "missing": missing,
        "post_s": post_s,
        "post_mb": len(first.model_dump_json()) / 1e6,
    }


def figures_of(f: dict) -> dict[str, Any]:
    """One configuration's figures, flat, for runs/bench/service.json."""
    base, labels, stream = f["base"], f["labels"], f["stream"]
    return {
        "baseline_rps": base["rps"],
        "baseline_p50_ms": base["p50"],
        "baseline_p99_ms": base["p99"],
        "label_rps": labels["rps"],
        "label_p50_ms": labels["p50"],
        "label_p99_ms": labels["p99"],
        "claim_p99_ms": labels["claim_p99"],
        "stream_p50_ms": percentile(stream, 50),
        "stream_p99_ms": percentile(stream, 99),
        "post_1000_s": f["post_s"],
        "stream_missing": f["missing"],
        "baseline_cpu_ms": base["cpu_ms"],
        "label_cpu_ms": labels["cpu_ms"],
        "big_body_mib": f["big"]["mib"],
        "big_body_rss_growth_ratio": f["big"]["growth_ratio"],
        "big_body_health_p99_ms": f["big"]["health_p99"],
        "idle_streams": f["streams"]["n"],
        "idle_streams_core_share": f["streams"]["core_share"],
    }


def print_figures(name: str, f: dict, args: argparse.Namespace) -> None:
    base, labels, stream, missing, post_s = f["base"], f["labels"], f["stream"], f["missing"], f["post_s"]
    rows = [
        ("baseline one-row insert", f"{base['rps']:.0f}/s", f"{base['p50']:.1f} ms", f"{base['p99']:.1f} ms"),
        ("collie label (+ next query)", f"{labels['rps']:.0f}/s", f"{labels['p50']:.1f} ms", f"{labels['p99']:.1f} ms"),
        ("collie first claim per labeler", "", "", f"{labels['claim_p99']:.1f} ms"),
        ("label → applied from the stream", "", f"{percentile(stream, 50):.1f} ms", f"{percentile(stream, 99):.1f} ms"),
    ]
    print(f"\n=== {name}")
    print(f"loopback, {LABELERS} concurrent clients, offered {args.rate:.0f}/s for {args.seconds:.0f} s each")
    print(f"{'':36s}{'rate':>10s}{'p50':>12s}{'p99':>12s}")
    for row_name, *cells in rows:
        print(f"{row_name:36s}" + "".join(f"{c:>12s}" if i else f"{c:>10s}" for i, c in enumerate(cells)))
    print(f"\n1000 queries posted → all claimable: {post_s:.2f} s ({f['post_mb']:.0f} MB of JSON)")
    print(f"labels not seen on the stream: {missing}")
    print(f"ratios vs baseline: rate {labels['rps'] / base['rps']:.2f}×, p99 {labels['p99'] / base['p99']:.2f}×")
    print(
        f"server CPU per request: baseline insert {base['cpu_ms']:.2f} ms, collie label + next query"
        f" {labels['cpu_ms']:.2f} ms ({labels['cpu_ms'] / base['cpu_ms']:.2f}×; one core serves"
        f" ≈ {1000 / labels['cpu_ms']:.0f} labels/s)"
    )
    big, streams = f["big"], f["streams"]
    print(
        f"session body of {big['mib']:.0f} MiB ({big['status']}): peak RSS growth {big['growth_ratio']:.2f}× its size,"
        f" parsed in {big['seconds']:.1f} s; /api/health meanwhile p99 {big['health_p99']:.0f} ms"
        f" (max {big['health_max']:.0f} ms, {big['health_n']} pings)"
    )
    print(f"{streams['n']} idle SSE streams: {100 * streams['core_share']:.1f} % of a core")
    ok = (
        labels["rps"] >= 0.95 * args.rate
        and labels["p99"] <= 20
        and percentile(stream, 99) <= 50
        and post_s <= 1.0
        and missing == 0
        and big["growth_ratio"] <= 2.0
        and big["health_p99"] <= 100
        and streams["core_share"] <= 0.05
    )
    print(
        "targets (≥1000/s, p99 ≤ 20 ms, stream p99 ≤ 50 ms, post ≤ 1 s, body RSS ≤ 2×, health p99 ≤ 100 ms,"
        " idle streams ≤ 5 %):",
        "met" if ok else "NOT met",
    )


def compare(results: dict[str, dict]) -> None:
    """The cost of synchronous=FULL, and PostgreSQL beside SQLite."""
    print("\n=== side by side (label + next query: rate, p50, p99, server CPU per label)")
    for name, f in results.items():
        lab = f["labels"]
        print(f"{name:28s}{lab['rps']:>8.0f}/s{lab['p50']:>9.1f} ms{lab['p99']:>9.1f} ms{lab['cpu_ms']:>9.2f} ms")
    full, normal = results.get("SQLite, synchronous=FULL"), results.get("SQLite, synchronous=NORMAL")
    if full and normal:
        print(
            f"cost of synchronous=FULL vs NORMAL: p99 {full['labels']['p99'] / normal['labels']['p99']:.2f}×,"
            f" CPU per label {full['labels']['cpu_ms'] / normal['labels']['cpu_ms']:.2f}×"
        )


# ---------------------------------------------------------------- limits: a body at the limit, idle streams


def rss_kib(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"no {field} for {pid}")


def big_body(api: str, tokens: dict[str, str], pid: int, mib: float) -> dict[str, Any]:
    """POST one session of about `mib` MiB (random full-precision Ant segments) while /api/health is
    pinged every 10 ms; the server's peak RSS growth (VmHWM, reset first) over the body's size."""
    rng = np.random.default_rng(1)
    trainer = CollieClient(api, tokens["trainer"], timeout_s=600)
    run = trainer.create_run(RunCreate(env="ant", task="north", method="collie", dims=ANT))
    one = len(json.dumps(session(0, 1, ANT, rng)["queries"][0])) + 2
    n = max(1, min(4096, int(mib * 2**20 / one)))
    body = json.dumps(session(0, n, ANT, rng)).encode()
    del rng
    Path(f"/proc/{pid}/clear_refs").write_text("5")  # reset the peak RSS to the current one
    before = rss_kib(pid, "VmRSS")
    pings: list[float] = []
    stop = asyncio.Event()

    async def ping() -> None:
        async with httpx.AsyncClient(timeout=120) as client:
            while not stop.is_set():
                t = time.perf_counter()
                await client.get(f"{api}/api/health")
                pings.append(time.perf_counter() - t)
                await asyncio.sleep(0.01)

    async def post() -> tuple[int, float]:
        headers = {"Authorization": f"Bearer {tokens['trainer']}", "Content-Type": "application/json"}
        async with httpx.AsyncClient(timeout=600) as client:
            t = time.perf_counter()
            response = await client.post(f"{api}/api/runs/{run.id}/sessions", content=body, headers=headers)
            return response.status_code, time.perf_counter() - t

    async def both() -> tuple[int, float]:
        pinger = asyncio.create_task(ping())
        await asyncio.sleep(0.2)
        result = await post()
        stop.set()
        await pinger
        return result

    status, seconds = asyncio.run(both())
    peak = rss_kib(pid, "VmHWM")
    trainer.close()
    return {
        "mib": len(body) / 2**20,
        "status": status,
        "seconds": seconds,
        "growth_ratio": (peak - before) * 1024 / len(body),
        "health_p99": percentile(pings, 99),
        "health_max": max(pings) * 1000 if pings else float("nan"),
        "health_n": len(pings),
    }


def idle_streams(api: str, tokens: dict[str, str], pid: int, n: int, seconds: float = 10.0) -> dict[str, Any]:
    """Hold `n` SSE streams open on one run (tokens of their own: a token may hold only a few),
    then measure the server's CPU over `seconds` of quiet."""
    operator = CollieClient(api, tokens["operator"])
    trainer = CollieClient(api, tokens["trainer"])
    run = trainer.create_run(RunCreate(env="ant", task="north", method="collie", dims=ANT))
    per_token = 25
    labelers = [operator.create_labeler(f"streams-{pid}-{i}").token for i in range((n + per_token - 1) // per_token)]
    host, port = "127.0.0.1", int(api.rsplit(":", 1)[1])

    async def hold() -> float:
        writers = []
        for i in range(n):
            reader, writer = await asyncio.open_connection(host, port)
            head = f"GET /api/runs/{run.id}/stream HTTP/1.1\r\nHost: {host}\r\n"
            head += f"Authorization: Bearer {labelers[i // per_token]}\r\n\r\n"
            writer.write(head.encode())
            status = await reader.readuntil(b"\r\n\r\n")
            assert status.startswith(b"HTTP/1.1 200"), status[:100]
            writers.append(writer)
        await asyncio.sleep(2.0)  # every stream has read its backlog
        cpu = cpu_seconds(pid)
        await asyncio.sleep(seconds)
        used = cpu_seconds(pid) - cpu
        for writer in writers:
            writer.close()
        return used / seconds

    share = asyncio.run(hold())
    operator.close()
    trainer.close()
    return {"n": n, "core_share": share}


if __name__ == "__main__":
    sys.exit(main())
