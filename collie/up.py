"""`collie up`: the whole loop on one machine — service, trainer and (optionally) the oracle teacher,
on the embedded SQLite default. Each part is its own process talking HTTP, as in production;
Ctrl-C stops them all cleanly, and running the same command again resumes the run."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

from collie.client import CollieClient
from collie.schemas import RunRead

PROCESS_ORDER = ("trainer", "teacher", "labeling_ui", "service")  # stop order: producers first


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--env", default="point")
    p.add_argument("--task", default=None, help="a built-in task (default north), or one a --task-file registers")
    p.add_argument("--task-file", type=Path, default=None, help="a task rule from a TOML/JSON/Python file")
    p.add_argument("--instruction", default=None, help="no rule: people label by this intent in words")
    p.add_argument("--method", default="collie")
    p.add_argument("--preset", default="cpu")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--teacher",
        choices=("none", "oracle"),
        default="none",
        help="oracle: a scripted labeler labels through the API (default: people label)",
    )
    p.add_argument("--teacher-rate", type=float, default=None, help="oracle labels per second (like a person)")
    p.add_argument("--noise-band", type=float, default=0.0, help="oracle R_error noise band")
    p.add_argument("--db", type=Path, default=None, help="SQLite file (default OUT/collie.db)")
    p.add_argument("--out", type=Path, default=None, help="folder for everything (default runs/up-ENV-TASK)")
    p.add_argument("--port", type=int, default=8000, help="service port (0 = any free port)")
    p.add_argument("--info-json", type=Path, default=None, help="write URLs, run id and tokens here")
    p.add_argument("--exit-when-done", action="store_true", help="exit 0 when the run finishes")
    p.add_argument("--no-label-ui", action="store_true", help="do not start the labeling UI")
    p.add_argument("--ui-port", type=int, default=8080, help="labeling UI port (0 = any free port)")
    p.add_argument("--train-args", default="", help='extra `collie train` flags, e.g. "--epochs 50"')


class Stack:
    """The child processes of one `collie up`, with their logs in OUT/logs/."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        (out / "logs").mkdir(parents=True, exist_ok=True)

    def start(self, name: str, args: list[str], env_extra: dict[str, str] | None = None) -> subprocess.Popen:
        log = open(self.out / "logs" / f"{name}.log", "ab")  # noqa: SIM115 - lives as long as the child
        env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env_extra or {})}
        proc = subprocess.Popen(
            [sys.executable, "-m", "collie.cli", *args],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )  # our Ctrl-C is handled here, not by children
        self.procs[name] = proc
        return proc

    def stop(self, timeout_s: float = 15.0) -> None:
        for name in PROCESS_ORDER:
            proc = self.procs.get(name)
            if proc is None or proc.poll() is not None:
                continue
            proc.send_signal(signal.SIGINT if name == "trainer" else signal.SIGTERM)
            try:
                proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()

    def dead(self) -> list[str]:
        return [n for n, p in self.procs.items() if p.poll() is not None]


def wait_for(path: Path, proc: subprocess.Popen, what: str, timeout_s: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.exists():
            try:
                return json.loads(path.read_text())
            except json.JSONDecodeError:
                pass  # being written
        if proc.poll() is not None:
            raise RuntimeError(f"{what} exited with code {proc.returncode} before it was ready")
        time.sleep(0.1)
    raise TimeoutError(f"{what} was not ready after {timeout_s:.0f} s")


def task_flags(args: argparse.Namespace) -> list[str]:
    """The trainer's rule flags; refuses what cannot run (ValueError)."""
    if args.instruction is not None:
        if args.task is not None or args.task_file is not None:
            raise ValueError("--instruction is for a run without a rule: drop --task and --task-file")
        if args.teacher == "oracle":
            raise ValueError("--teacher oracle labels by a task rule, and an --instruction run has none")
        return ["--instruction", args.instruction]
    flags = ["--task", args.task] if args.task is not None else []
    if args.task_file is not None:
        from collie.tasks.task_file import load_task_file

        load_task_file(args.task_file, args.task, args.env, args.seed)  # a bad file fails here, before anything starts
        return [*flags, "--task-file", str(args.task_file.resolve())]
    return flags or ["--task", "north"]


def run_name(args: argparse.Namespace) -> str:
    if args.instruction is not None:
        return "instruction"
    return args.task or (args.task_file.stem if args.task_file is not None else "north")


def run(args: argparse.Namespace) -> int:
    try:
        args.task_flags = task_flags(args)
    except ValueError as exc:
        print(f"collie up: error: {exc}", file=sys.stderr)
        return 2
    out = args.out or Path(f"runs/up-{args.env}-{run_name(args)}")
    out.mkdir(parents=True, exist_ok=True)
    db = args.db or out / "collie.db"
    stack = Stack(out)
    stopping = {"flag": False}

    def on_signal(signum: int, _frame: object) -> None:
        stopping["flag"] = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        return supervise(args, out, db, stack, stopping)
    except (RuntimeError, TimeoutError) as exc:
        print(f"collie up: error: {exc} (logs in {out / 'logs'})", file=sys.stderr)
        return 1
    finally:
        stack.stop()


def supervise(args: argparse.Namespace, out: Path, db: Path, stack: Stack, stopping: dict) -> int:
    tokens_file = out / "tokens.json"
    keep: dict[str, str] = {}  # a resumed stack keeps its tokens, so links already handed out stay valid
    if tokens_file.exists():
        saved = json.loads(tokens_file.read_text())["tokens"]
        keep = {f"COLLIE_{role.upper()}_TOKEN": tok for role, tok in saved.items()}
        tokens_file.unlink()
    service = stack.start(
        "service",
        ["serve", "--host", "127.0.0.1", "--port", str(args.port), "--db", str(db), "--tokens-json", str(tokens_file)],
        env_extra=keep,
    )
    info = wait_for(tokens_file, service, "the service")
    api, tokens = info["api"], info["tokens"]
    with CollieClient(api, tokens["operator"]) as client:
        wait_healthy(client, service)
    trainer_out = out / "trainer"
    memo = trainer_out / "service_run.json"
    resume = (trainer_out / "checkpoint.pt").exists() and memo.exists()
    if not resume:
        memo.unlink(missing_ok=True)
    train = [
        "train",
        "--env",
        args.env,
        *args.task_flags,
        "--method",
        args.method,
        "--preset",
        args.preset,
        "--seed",
        str(args.seed),
        "--out",
        str(trainer_out),
        "--api",
        api,
        "--token",
        tokens["trainer"],
        "--no-progress",
        "--noise-band",
        str(args.noise_band),
        *args.train_args.split(),
    ]
    # OpenMP threads that sleep while idle (trainer/threads.py); `collie train` picks the thread count
    trainer = stack.start("trainer", [*train, "--resume"] if resume else train, {"OMP_WAIT_POLICY": "PASSIVE"})
    run_id = wait_for(memo, trainer, "the trainer")["run_id"] if not resume else json.loads(memo.read_text())["run_id"]
    if args.teacher == "oracle":
        teach = [
            "teacher",
            "--api",
            api,
            "--token",
            tokens["labeler"],
            "--run",
            str(run_id),
            "--until-done",
            "--noise-band",
            str(args.noise_band),
            "--seed",
            str(args.seed),
        ]
        if args.teacher_rate:
            teach += ["--rate", str(args.teacher_rate)]
        stack.start("teacher", teach)
    labeler_url = None
    if not args.no_label_ui:
        ui_info = out / "labeling_ui.json"
        ui_info.unlink(missing_ok=True)
        ui = stack.start(
            "labeling_ui",
            ["label-ui", "--api", api, "--run", str(run_id), "--port", str(args.ui_port), "--info-json", str(ui_info)],
        )
        labeler_url = wait_for(ui_info, ui, "the labeling UI")["url"] + "?token=" + quote(tokens["labeler"])
    dashboard = f"{api}/?token={quote(tokens['operator'])}"
    if labeler_url:  # the dashboard's "watch skills in 3D" link opens the labeling UI in watch mode
        dashboard += "&ui=" + quote(labeler_url.split("?")[0], safe="")
    urls = {"api": api, "labeling_ui": labeler_url, "dashboard": dashboard}
    write_info(args.info_json, urls, run_id, tokens)
    print(f"collie up: run {run_id} · {args.env} {run_name(args)} {args.method} ({args.preset})")
    print(f"  service   {api}   (API docs {api}/docs)")
    if labeler_url:
        print(f"  label     {labeler_url}")
    print(f"  dashboard {dashboard}")
    print(f"  tokens    operator {tokens['operator']} · labeler {tokens['labeler']}")
    print(f"  logs      {out / 'logs'}   trainer output {trainer_out}")
    print("  Ctrl-C stops everything; the same command resumes.", flush=True)
    return watch(api, tokens["operator"], run_id, stack, args.exit_when_done, stopping)


def wait_healthy(client: CollieClient, service: subprocess.Popen, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            client.health()
            return
        except Exception:  # not up yet
            if service.poll() is not None:
                raise RuntimeError(f"the service exited with code {service.returncode}") from None
            time.sleep(0.2)
    raise TimeoutError("the service did not become healthy")


def write_info(path: Path | None, urls: dict, run_id: int, tokens: dict) -> None:
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({**urls, "run_id": run_id, "tokens": tokens}, indent=1))
    path.chmod(0o600)


class ProgressLine:
    """The run's status, epoch and labels on one line, redrawn in place on a terminal and printed
    once per change otherwise (no tqdm: that is the trainer's dependency, not the light package's)."""

    def __init__(self) -> None:
        self._last = ""
        self._inline = sys.stderr.isatty()

    def show(self, r: RunRead) -> None:
        epochs = f"{r.epoch}/{r.epochs_total}" if r.epochs_total else str(r.epoch)
        line = f"{r.status}: epoch {epochs} · labels {r.n_labels}/{r.n_total if r.n_total is not None else '-'}"
        if line != self._last:
            self._last = line
            sys.stderr.write(f"\r{line:<72}" if self._inline else line + "\n")
            sys.stderr.flush()

    def close(self) -> None:
        if self._inline and self._last:
            sys.stderr.write("\n")
            sys.stderr.flush()


def watch(api: str, token: str, run_id: int, stack: Stack, exit_when_done: bool, stopping: dict) -> int:
    """Show the run's progress until it ends (or Ctrl-C). Returns the trainer's exit code."""
    bar = ProgressLine()
    trainer = stack.procs["trainer"]
    with CollieClient(api, token) as client:
        while not stopping["flag"]:
            with contextlib.suppress(Exception):  # the service may be restarting; keep watching
                bar.show(client.run(run_id))
            if trainer.poll() is not None:
                bar.close()
                code = trainer.returncode
                print(f"collie up: trainer finished with code {code}; outputs in {stack.out / 'trainer'}")
                if exit_when_done or code != 0:
                    return code
                print("collie up: the service stays up for inspection; Ctrl-C to stop.", flush=True)
                while not stopping["flag"]:
                    time.sleep(0.5)
                return 0
            broken = [n for n in stack.dead() if n in ("service", "labeling_ui")]
            if broken:
                raise RuntimeError(f"{', '.join(broken)} exited unexpectedly")
            time.sleep(0.5)
    bar.close()
    print("collie up: stopping…", flush=True)
    return 130
