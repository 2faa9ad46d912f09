"""`collie up`: the whole loop on one machine — service, trainer, labeling UI (unless --no-label-ui)
and (optionally) the oracle teacher, on the embedded SQLite default. Each part is its own process
talking HTTP, as in production, and is supervised (collie/supervisor.py): one that dies is
restarted — the trainer from its checkpoint.
Tokens reach the children through their environment, never their command line, and are written
only to files their owner alone may read. Ctrl-C stops them all cleanly, and running the same
command again resumes the run."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shlex
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

from collie.addresses import is_loopback, link_host, local_address, network_address, not_listenable
from collie.argtypes import Given, ipv4_host, port, seed, sqlite_file
from collie.child_log import last_error
from collie.early_term import INTERRUPTED
from collie.feedback_schedule import next_feedback_epoch
from collie.pass_through import owned_flags
from collie.processes import LockHeld, hold_lock, running
from collie.run_state import run_state
from collie.stack_folder import STACK_LOCK, STACK_RUN
from collie.startup import LOG_ENV, mark
from collie.supervisor import ChildFailed, Supervisor
from collie.tasks import default_task
from collie.teacher_principal import teacher_token
from collie.tokens import MIN_TOKEN, TOKEN_ENV, random_token, read_tokens_file, weakness, write_secret
from collie.whole_files import broken_link

if TYPE_CHECKING:  # the HTTP client and schemas load after the children are spawned: they start sooner
    from collie.client import CollieClient
    from collie.schemas import RunRead

ROLES = ("operator", "trainer", "labeler")
DATABASE_ENV = "COLLIE_DATABASE_URL"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.set_defaults(given=frozenset())  # the run's flags given on this command line (Given)
    p.add_argument(
        "--env", default="point", action=Given, help="point (default), ant, half_cheetah, quadruped, humanoid or car"
    )
    p.add_argument(
        "--task",
        default=None,
        help="a built-in task (default north; right on half_cheetah, hazard on car), or one a --task-file registers",
    )
    p.add_argument("--task-file", type=Path, default=None, help="a task rule from a TOML/JSON/Python file")
    p.add_argument("--instruction", default=None, help="no rule: people label by this intent in words")
    p.add_argument(
        "--method", default="collie", action=Given, help="collie (default), metra, oracle, or a baseline (collie train)"
    )
    p.add_argument(
        "--preset", default="cpu", action=Given, help="cpu (default: this machine), paper (a GPU) or smoke (seconds)"
    )
    p.add_argument("--seed", type=seed, default=0, action=Given, help="the run's seed (default 0)")
    p.add_argument(
        "--teacher",
        choices=("none", "oracle"),
        default="none",
        help="oracle: a scripted labeler labels through the API (default: people label)",
    )
    p.add_argument("--teacher-rate", type=float, default=None, help="oracle labels per second (like a person)")
    p.add_argument("--noise-band", type=float, default=0.0, help="oracle R_error noise band")
    p.add_argument(
        "--db",
        type=sqlite_file,
        default=None,
        help="SQLite file (default: COLLIE_DATABASE_URL when set, else OUT/collie.db)",
    )
    p.add_argument("--out", type=Path, default=None, help="folder for everything (default runs/up-ENV-TASK)")
    p.add_argument("--port", type=port, default=8000, help="service port (0 = any free port; default 8000)")
    p.add_argument(
        "--host",
        type=ipv4_host,
        default="127.0.0.1",
        help="address the service and labeling UI listen on (default 127.0.0.1: this machine only; "
        "0.0.0.0: people on other machines label and watch too, by links naming this machine's address)",
    )
    p.add_argument("--info-json", type=Path, default=None, help="write URLs, run id and tokens here")
    p.add_argument("--exit-when-done", action="store_true", help="exit 0 when the run finishes")
    p.add_argument("--no-label-ui", action="store_true", help="do not start the labeling UI")
    p.add_argument("--ui-port", type=port, default=8090, help="labeling UI port (0 = any free port; default 8090)")
    p.add_argument("--train-args", default="", help='extra `collie train` flags, e.g. "--epochs 50"')
    p.add_argument(
        "--max-restarts",
        type=int,
        default=5,
        help="restarts of a part that keeps dying before the stack gives up (default 5)",
    )


class Stopped(Exception):
    """Ctrl-C (or SIGTERM) while the stack was starting."""


def wait_for(
    path: Path,
    proc: subprocess.Popen,
    what: str,
    key: str | None = None,
    timeout_s: float = 120.0,
    stopping: dict | None = None,
    log: Path | None = None,
    since: int = 0,
) -> dict:
    """The JSON at path once it exists (and holds `key`), or an error if proc exits first (with the
    last error line of its `log` from byte `since`, where this start's lines begin); Stopped on Ctrl-C."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if stopping is not None and stopping["flag"]:
            raise Stopped
        if path.exists():
            try:
                found = json.loads(path.read_text())
                if key is None or key in found:
                    return found
            except json.JSONDecodeError:
                pass  # being written
        if proc.poll() is not None:
            said = last_error(log, since) if log is not None else ""
            code = proc.returncode  # a killed one's is -signal: said as the supervisor says it
            how = f"signal {-code}" if code < 0 else f"code {code}"
            raise RuntimeError(f"{what} exited with {how} before it was ready{': ' + said if said else ''}")
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

        # a bad file fails here, before anything starts; the run is named by its task, as collie train names it
        args.file_task = load_task_file(args.task_file, args.task, args.env, args.seed).name
        return [*flags, "--task-file", str(args.task_file.resolve())]
    return flags or ["--task", default_task(args.env)]


def run_task_flags(args: argparse.Namespace, resume: bool) -> list[str]:
    """The rule flags a (re)started trainer gets: none for a resumed stack given no rule, which
    continues its run's own (a default --task would contradict a run made with another)."""
    given = args.task is not None or args.task_file is not None or args.instruction is not None
    return args.task_flags if given or not resume else []


def run_flags(args: argparse.Namespace, resume: bool) -> list[str]:
    """The trainer's flags for the run (where it writes and which service it talks to aside)."""
    people = ["--people-schedule"] if args.teacher == "none" else []  # the first session earlier
    return [
        *("--env", args.env, *run_task_flags(args, resume), "--method", args.method, "--preset", args.preset),
        *("--seed", str(args.seed), "--noise-band", str(args.noise_band), *people, *args.train_flags),
    ]


def refused_by_trainer(args: argparse.Namespace) -> str | None:
    """What `collie train` would refuse in the run's flags (an env, task or method misspelt, a typo
    or a value out of range in --train-args), asked of `collie train --print-config` (a third of a
    second) before anything starts: else the stack started, made OUT, and its trainer said so."""
    command = [sys.executable, "-m", "collie.cli", "train", *run_flags(args, resume=False), "--print-config"]
    try:
        said = subprocess.run(command, capture_output=True, text=True, env=child_env(), stdin=subprocess.DEVNULL)
    except OSError:  # no Python to ask (this user may not run it): the started trainer will say what it refuses
        return None
    if said.returncode == 0:
        return None
    lines = said.stderr.strip().splitlines() or [f"exit status {said.returncode}"]
    return lines[-1].removeprefix("collie train: error: ")


def run_name(args: argparse.Namespace) -> str:
    if args.instruction is not None:
        return "instruction"
    return args.task or getattr(args, "file_task", None) or default_task(args.env)


DASHED_VALUE_OPTIONS = ("--train-args",)  # its value is flags: `--train-args "--compile"` (collie/cli.py)

# `collie train` flags that `collie up` sets itself: given in --train-args they would contradict it
UP_OWNS = ("--out", "--api", "--run-id", "--resume", "--env", "--task", "--task-file", "--instruction",
           "--method", "--preset", "--seed", "--token", "--token-file")  # fmt: skip


def checked(args: argparse.Namespace) -> Path:
    """OUT, once the arguments are known to make sense together (ValueError naming what does not)."""
    args.task_flags = task_flags(args)
    try:  # as a shell splits it: `--train-args "--instruction 'keep off the east side'"`
        args.train_flags = shlex.split(args.train_args)
    except ValueError as exc:  # an unclosed quote
        raise ValueError(f"--train-args {args.train_args!r}: {exc}") from None
    owned = owned_flags(args.train_flags, UP_OWNS)
    if owned:
        raise ValueError(f"--train-args may not set {', '.join(owned)}: give it to collie up itself (or not at all)")
    out = args.out or Path(f"runs/up-{args.env}-{run_name(args)}")
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    if args.info_json is not None and args.info_json.is_dir():
        raise ValueError(f"--info-json {args.info_json} is a folder; give a file path")
    if args.max_restarts < 0:
        raise ValueError("--max-restarts must be ≥ 0")
    cannot = not_listenable(args.host)
    if cannot is not None:
        raise ValueError(f"--host {args.host} is not an address of this machine ({cannot})")
    if args.teacher_rate is not None and args.teacher_rate <= 0:
        raise ValueError("--teacher-rate must be > 0 (oracle labels per second)")
    new, lab = not (out / "tokens.json").exists(), on_lab_database(args)
    if new or lab:  # a new stack, or any on the lab's database, takes COLLIE_<ROLE>_TOKEN (stack_tokens)
        names = [f"COLLIE_{r.upper()}_TOKEN" for r in ROLES]
        for name in names:
            why = weakness(os.environ.get(name) or "x" * MIN_TOKEN)
            if why:
                raise ValueError(f"{name} {why}: unset it (a random one is made) or choose a longer random one")
        missing = [name for name in names if not os.environ.get(name)]
        if lab and missing:  # new random ones, or this --out's from an earlier start, would replace the lab's
            kept = "new ones" if new else f"new ones, or the older ones in {out / 'tokens.json'},"
            raise ValueError(
                f"{DATABASE_ENV} names the lab's database: give its tokens in {', '.join(missing)} ({kept} would "
                "replace the tokens everyone else uses there), or --db FILE for a stack of its own"
            )
        if new and args.db is not None and is_sqlite_database(args.db) and missing:  # a database of another stack
            raise ValueError(
                f"--db {args.db} holds a database already, but {out} has no tokens.json: give its tokens "
                f"in {', '.join(missing)} (new ones would replace the tokens of every link handed out for it), "
                "the --out it was started with, or a new --db"
            )
    return out


def on_lab_database(args: argparse.Namespace) -> bool:
    """The stack runs on the lab's database (COLLIE_DATABASE_URL, no --db), whose tokens are the lab's."""
    return bool(os.environ.get(DATABASE_ENV)) and args.db is None


def is_sqlite_database(path: Path) -> bool:
    """`path` is a SQLite database file (its header says so; an empty file is not one yet)."""
    try:
        with path.open("rb") as f:
            return f.read(16) == b"SQLite format 3\x00"
    except OSError:
        return False


def made(folder: Path, what: str) -> list[Path]:
    """`folder` exists as a folder afterwards, else ValueError naming `what` and why. Returns the
    folders this made, the deepest last (a refused start removes them again: `unmake`)."""
    missing = [f for f in [folder, *folder.parents] if not f.exists()][::-1]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot create {what} {folder}: {broken_link(exc) or exc.strerror or exc}") from None
    return missing


def unmake(folders: list[Path]) -> None:
    """Remove the folders `made` made, deepest first, where nothing else was put in them."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            folder.rmdir()


def locked(out: Path) -> int:
    """An exclusive lock on OUT/up.lock, held by this stack and every part of it (children inherit
    the descriptor), so a second `collie up` on the same OUT — or on what a killed one left running
    — is refused; ValueError naming the processes in the way."""
    try:
        return hold_lock(out / STACK_LOCK)
    except LockHeld:
        try:
            before = json.loads((out / "children.json").read_text())
            named = [("collie up", before["up"]), *before["children"].items()]
            pids = [f"{n} {p}" for n, p in named if running(p)]  # the file keeps those a SIGKILL ended
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pids = []
        pids = pids or [f"find them with `fuser -v {out / STACK_LOCK}`"]
        raise ValueError(
            f"another collie up runs on --out {out} ({', '.join(pids)}): stop it (Ctrl-C there, or kill "
            "these processes), or give another --out"
        ) from None


def run(args: argparse.Namespace) -> int:
    new_info: list[Path] = []  # folders this start made: a refused one leaves none behind
    new_out: list[Path] = []
    try:
        out = checked(args)
        why = refused_by_trainer(args)
        if why is not None:
            raise ValueError(f"collie train would refuse the run: {why}")
        if args.info_json is not None:
            new_info = made(args.info_json.parent, "the folder of --info-json")
        new_out = made(out, "--out")
        lock = locked(out)
        sock = listening_socket(args.host, args.port)  # a port in use: refused before anything is written
    except ValueError as exc:
        if new_out:  # nothing of a stack yet
            (out / STACK_LOCK).unlink(missing_ok=True)
        unmake(new_info + new_out)
        print(f"collie up: error: {exc}", file=sys.stderr)
        return 2
    # an explicit --db, else the lab's database when COLLIE_DATABASE_URL names one, else OUT's SQLite file
    db = args.db or (None if on_lab_database(args) else out / "collie.db")
    if db is None:
        print("collie up: database: COLLIE_DATABASE_URL (give --db FILE for a SQLite file instead)", flush=True)
    stack = Supervisor(out, max_restarts=args.max_restarts, inherited=(lock,))
    stopping = {"flag": False}

    def on_signal(signum: int, _frame: object) -> None:
        stopping["flag"] = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:  # a closed terminal stops the stack; nohup does not
        signal.signal(signal.SIGHUP, on_signal)
    made_db, unheld, code = db is not None and not Path(db).exists(), False, 1
    try:
        code = supervise(args, out, db, stack, stopping, sock)
        return code
    except Stopped:
        print("collie up: stopped while starting", file=sys.stderr)
        code = INTERRUPTED
        return code
    except (RuntimeError, TimeoutError) as exc:  # ChildFailed included
        unheld = isinstance(exc, RunNotHeld)
        stack.log(f"error: {exc}")
        print(f"collie up: error: {exc} (logs in {out / 'logs'})", file=sys.stderr)
        return 1
    finally:
        stack.stop()
        if unheld and made_db:  # the service made it empty just now: the refused start leaves none behind
            for path in (Path(f"{db}{end}") for end in ("", "-wal", "-shm")):
                path.unlink(missing_ok=True)
        if code == INTERRUPTED and (out / "trainer" / "checkpoint.pt").is_file():  # what Ctrl-C kept, and how on
            kept = out / "trainer"
            print(f"collie up: stopped; the trainer's checkpoint is in {kept}: the same command goes on from it")


def stack_tokens(tokens_file: Path, lab: bool) -> dict[str, str]:
    """A resumed stack keeps its tokens (links already handed out stay valid); a new one takes
    COLLIE_<ROLE>_TOKEN from the environment, else fresh random ones. On the lab's database
    (`lab`) the environment's always win (`checked` made sure of them): the lab may have rotated
    its tokens since this stack last ran, and the service would put the older ones back."""
    if tokens_file.exists() and not lab:
        try:
            kept = read_tokens_file(tokens_file)
        except ValueError as exc:  # reported as the stack's error, with the logs' folder
            raise RuntimeError(f"{exc}; move it away to start with new tokens") from None
        gone = [role for role in ROLES if role not in kept]  # the service leaves a revoked role's out
        if gone:
            raise RuntimeError(
                f"{tokens_file} holds no {' or '.join(gone)} token (revoked on the service: final); "
                "this stack cannot run again: start a new one in another --out"
            )
        return kept
    return {r: os.environ.get(f"COLLIE_{r.upper()}_TOKEN") or random_token() for r in ROLES}


SECRETS = (TOKEN_ENV, DATABASE_ENV)  # and every COLLIE_<ROLE>_TOKEN: only the service needs them


def is_secret(name: str) -> bool:
    return name in SECRETS or (name.startswith("COLLIE_") and name.endswith("_TOKEN"))


def child_env(token: str | None = None) -> dict[str, str]:
    """Our environment without the stack's secrets (the database URL holds a password), plus the
    one token this child may use."""
    env = {k: v for k, v in os.environ.items() if not is_secret(k)}
    return {**env, TOKEN_ENV: token} if token is not None else env


def supervise(
    args: argparse.Namespace, out: Path, db: Path | None, stack: Supervisor, stopping: dict, sock: socket.socket
) -> int:
    timeline = out / "logs" / "startup.jsonl"  # every part's startup marks (collie/startup.py), this start's only
    timeline.unlink(missing_ok=True)
    os.environ[LOG_ENV] = str(timeline.resolve())  # for our own marks and, through child_env, the parts'
    mark("python start")
    tokens_file = out / "tokens.json"
    tokens = stack_tokens(tokens_file, on_lab_database(args))
    write_secret(tokens_file, json.dumps({"tokens": tokens}))  # kept even if the service fails to start
    lab = {DATABASE_ENV: os.environ[DATABASE_ENV]} if db is None else {}  # the lab's database, for the service only
    service_env = {**child_env(), **lab, **{f"COLLIE_{r.upper()}_TOKEN": t for r, t in tokens.items()}}
    port = {"labeling_ui": args.ui_port}  # after the first start: the bound port
    # We bind the service's socket and hand it over: its URL is known at once, so the trainer starts
    # (and imports torch) while the service imports and migrates; requests queue until it serves,
    # and a restarted service keeps the port.
    stack.closing(sock)
    api = f"http://{local_address(args.host)}:{sock.getsockname()[1]}"  # the parts' own way in
    shown = link_host(args.host)  # what the links name: where other machines reach us
    serve = ["serve", "--fd", str(sock.fileno()), *(["--db", str(db)] if db else []), "--tokens-json", str(tokens_file)]
    service = stack.start("service", lambda: serve, service_env, pass_fds=(sock.fileno(),))
    trainer_out = out / STACK_RUN
    memo = trainer_out / "service_run.json"
    # The service holds the run once the trainer made it: the stack continues it, from the checkpoint if
    # one was written (else from epoch 0, reusing the sessions posted), never a new run beside it.
    resume = memo.exists()
    train = ["train", *run_flags(args, resume), "--out", str(trainer_out), "--api", api, "--no-progress"]

    def train_args() -> list[str]:
        """A (re)started trainer continues the run it created, from its checkpoint when it wrote one."""
        more = ["--run-id", str(json.loads(memo.read_text())["run_id"])] if memo.exists() else []
        return [*train, *more, *(["--resume"] if (trainer_out / "checkpoint.pt").exists() and more else [])]

    # OpenMP threads that sleep while idle (trainer/threads.py); `collie train` picks the thread count
    trainer_env = {**child_env(tokens["trainer"]), "OMP_WAIT_POLICY": "PASSIVE"}

    def run_is_over() -> bool:
        """A trainer's exit 0 ends the run unless it was interrupted (a SIGTERM from outside the
        stack; summary.json says so): then it is restarted, and resumes, like one that died."""
        try:
            return json.loads((trainer_out / "summary.json").read_text()).get("status") != "interrupted"
        except (OSError, ValueError):
            return True

    def run_failed() -> str | None:
        """A trainer that exited with its run failed (summary.json says so: it diverged) ends the
        stack: a restart would replay the run to the same failure."""
        try:
            summary = json.loads((trainer_out / "summary.json").read_text())
        except (OSError, ValueError):
            return None
        return f"run failed: {summary.get('error', 'see its log')}" if summary.get("status") == "failed" else None

    def checkpointed() -> int:
        """The newest replay chunk a checkpoint wrote (trainer/replay_log.py): it grows only with new
        trajectories, so a trainer killed again and again still progresses while each start gets
        this far, and one that only rewrites its checkpoint at the same epoch on the way out does not."""
        chunks = (trainer_out / "replay").glob("*.npz") if (trainer_out / "replay").is_dir() else ()
        return max((int(f.stem) for f in chunks if f.stem.isdigit()), default=-1)

    trainer = stack.start(
        "trainer", train_args, trainer_env, done_when_ok=run_is_over, fatal=run_failed, progress=checkpointed
    )  # it waits for the service itself
    from collie.client import CollieClient

    logs = out / "logs"
    # short requests: one sent to our socket before a service that then died is never answered
    with CollieClient(api, tokens["operator"], timeout_s=WATCH_TIMEOUT_S) as client:
        wait_healthy(client, service, logs / "service.log", stopping, since=stack.children["service"].log_from)
        resumed = json.loads(memo.read_text())["run_id"] if resume else None
        if resumed is not None:
            held_by_database(client, resumed, memo, db)
    mark("waited: service healthy")
    if resumed is not None:
        run_id = resumed
    else:
        since = stack.children["trainer"].log_from
        run_id = wait_for(memo, trainer, "the trainer", stopping=stopping, log=logs / "trainer.log", since=since)[
            "run_id"
        ]
    mark("waited: run created")
    if args.teacher == "oracle":
        teach = ["teacher", "--api", api, "--run", str(run_id), "--until-done", "--noise-band", str(args.noise_band)]
        teach += ["--seed", str(args.seed), *(["--rate", str(args.teacher_rate)] if args.teacher_rate else [])]
        # Its work is over with the trainer's: one that found the run finished before the trainer
        # reopened it for more epochs (a resumed --epochs) is started again.
        teacher_done = lambda: stack.finished("trainer")  # noqa: E731
        own = teacher_token(api, tokens["operator"], out, run_id)  # not the link's: a person there is another labeler
        stack.start("teacher", lambda: teach, child_env(own), teacher_done, again_after_s=TEACHER_AGAIN_S)
    labeler_url = None
    if not args.no_label_ui:
        ui_info = out / "labeling_ui.json"
        ui_info.unlink(missing_ok=True)

        def ui_args() -> list[str]:
            where = ["--host", args.host, "--port", str(port["labeling_ui"]), "--info-json", str(ui_info)]
            where += ["--warm", args.env]
            return ["label-ui", "--api", api, "--run", str(run_id), *where]

        ui = stack.start("labeling_ui", ui_args, child_env())
        since = stack.children["labeling_ui"].log_from
        ui_meta = wait_for(ui_info, ui, "the labeling UI", stopping=stopping, log=logs / "labeling_ui.log", since=since)
        mark("waited: labeling UI serving")
        if args.ui_port and int(ui_meta["port"]) != args.ui_port:  # said in its log only, else
            print(f"collie up: --ui-port {args.ui_port} is in use; the labeling UI serves on port {ui_meta['port']}")
        port["labeling_ui"] = int(ui_meta["port"])
        labeler_url = ui_meta["url"] + "?token=" + quote(tokens["labeler"])  # its URL names `shown` too
    site = f"http://{shown}:{sock.getsockname()[1]}"
    dashboard = f"{site}/?token={quote(tokens['operator'])}"
    if labeler_url:  # the dashboard's "watch skills in 3D" link opens the labeling UI in watch mode
        dashboard += "&ui=" + quote(labeler_url.split("?")[0], safe="")
    urls = {"api": site, "labeling_ui": labeler_url, "dashboard": dashboard}
    write_info(args.info_json, urls, run_id, tokens)
    print(f"collie up: run {run_id} · {what_runs(args, trainer_out / 'config.json' if resume else None)}")
    print(f"  service   {site}   (API docs {site}/docs)")
    if labeler_url:  # links with tokens go to the terminal of the person who started the stack, not to logs
        print(f"  label     {labeler_url}")
    elif args.teacher == "none":  # else the run would wait for labels with no word of who gives them
        print(f"  label     no labeling UI here (--no-label-ui): `collie label-ui --api {site} --run {run_id} "
              "--token TOKEN` with a labeler's token (dashboard → Labelers), or --teacher oracle")  # fmt: skip
    print(f"  dashboard {dashboard}")
    print(f"  tokens    in {tokens_file} (readable by you only)")
    print(f"  logs      {out / 'logs'}   trainer output {trainer_out}")
    if not is_loopback(args.host):
        print(f"  reachable from other machines on {args.host}; these links carry tokens over plain HTTP "
              "(a trusted network, or a TLS proxy in front). The dashboard link is the operator's: keep it.\n"
              "  The label link is one labeler's; give each colleague their own (dashboard → Labelers):"
              " their labels then count as theirs, and each may open up to 4 tabs.")  # fmt: skip
        if args.host in ("0.0.0.0", "") and network_address() is None:
            print(f"collie up: warning: this machine has no network address; the links name {shown}, which "
                  "other machines may not resolve (give --host this machine's address)", file=sys.stderr)  # fmt: skip
    print("  Ctrl-C stops everything; the same command resumes.", flush=True)
    stack.log(f"stack up: run {run_id}, service {api}")
    return watch(api, tokens["operator"], run_id, stack, args.exit_when_done, stopping)


def what_runs(args: argparse.Namespace, stored: Path | None) -> str:
    """env, task, method and preset of the run: a resumed run's own (with a warning for the flags
    given that differ: the trainer keeps the run's), else those asked for."""
    asked = {"env": args.env, "task": run_name(args), "method": args.method, "preset": args.preset, "seed": args.seed}
    try:
        config = json.loads(stored.read_text()) if stored is not None else {}
    except (OSError, ValueError):
        config = {}
    if args.instruction is not None or args.task is None:  # only a task given by name is compared
        config.pop("task", None)
    runs = {k: str(config.get(k, v)) for k, v in asked.items()}
    given = {*args.given, *(["task"] if args.task is not None else [])}
    differ = [f"--{k} {asked[k]}" for k in asked if k in given and runs[k] != str(asked[k])]
    if differ:
        print(f"collie up: warning: resuming a {runs['env']} {runs['task']} {runs['method']} run; "
              f"{', '.join(differ)} ignored (another --out starts a new run)", file=sys.stderr)  # fmt: skip
    return f"{runs['env']} {runs['task']} {runs['method']} ({runs['preset']})"


def listening_socket(host: str, port: int) -> socket.socket:
    """host:port (0: any free port), bound and listening; an error naming a port in use."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ValueError(
            f"cannot listen on {host}:{port} for the service: {exc.strerror} (--port 0 takes any free port)"
        ) from None
    sock.listen(128)
    return sock


def wait_healthy(
    client: CollieClient, service: subprocess.Popen, log: Path, stopping: dict, timeout_s: float = 60.0, since: int = 0
) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if stopping["flag"]:
            raise Stopped
        try:
            client.health()
            return
        except Exception:  # not up yet
            if service.poll() is not None:
                said = last_error(log, since)
                raise RuntimeError(
                    f"the service exited with code {service.returncode}{': ' + said if said else ''}"
                ) from None
            time.sleep(0.2)
    raise TimeoutError("the service did not become healthy")


class RunNotHeld(RuntimeError):
    """OUT/trainer belongs to a run the stack's database does not hold."""


def held_by_database(client: CollieClient, run_id: int, memo: Path, db: Path | None) -> None:
    """The run OUT/trainer belongs to is in the database, else RuntimeError saying so: a trainer
    resumed on a database without it would only ever be refused (404) and restarted."""
    from collie.client import ApiError, Unavailable, answered

    try:
        client.run(run_id)
    except Unavailable as exc:  # it died or stopped answering just after it was healthy
        raise RuntimeError(f"the service did not answer when asked for run {run_id}: {exc}") from None
    except ApiError as exc:
        if exc.status != 404:
            raise RuntimeError(f"the service {answered(exc)} when asked for run {run_id}") from None
        where = db if db is not None else DATABASE_ENV
        raise RunNotHeld(
            f"{memo} belongs to run {run_id}, which the database ({where}) does not hold (was it deleted or "
            "replaced?): give the --db that holds it, or another --out for a new run"
        ) from None


def write_info(path: Path | None, urls: dict, run_id: int, tokens: dict) -> None:
    if path is not None:
        write_secret(path, json.dumps({**urls, "run_id": run_id, "tokens": tokens}, indent=1))


class ProgressLine:
    """The run's status, epoch and labels on one line, redrawn in place on a terminal and printed
    once per change otherwise (no tqdm: that is the trainer's dependency, not the light package's)."""

    def __init__(self) -> None:
        self._last = ""
        self._inline = sys.stderr.isatty()

    def show(self, r: RunRead) -> None:
        epochs = f"{r.epoch}/{r.epochs_total}" if r.epochs_total else str(r.epoch)
        line = f"{run_state(r)}: epoch {epochs} · labels {r.n_labels}/{r.n_total if r.n_total is not None else '-'}"
        upcoming = next_feedback_epoch(r) if r.status == "training" else None
        if upcoming is not None:  # when people will have something to label
            line += f" · next feedback session at epoch {upcoming}"
        if line != self._last:
            self._last = line
            sys.stderr.write(f"\r{line:<72}" if self._inline else line + "\n")
            sys.stderr.flush()

    def close(self) -> None:
        if self._inline and self._last:
            sys.stderr.write("\n")
            sys.stderr.flush()


WATCH_TIMEOUT_S = 2.0  # the progress line's request; a restart of a dead part waits at most this long
TEACHER_AGAIN_S = 2.0  # a teacher that ended while the trainer runs starts again after this


def watch(api: str, token: str, run_id: int, stack: Supervisor, exit_when_done: bool, stopping: dict) -> int:
    """Show the run's progress and keep every part alive until the run ends (or Ctrl-C). Returns 0
    when the trainer finished, 1 when a part could not be kept alive, 130 on Ctrl-C."""
    from collie.client import CollieClient

    bar = ProgressLine()
    # A short timeout: while the service is dead, our listening socket still accepts the request and it
    # hangs until the service is back, which only `stack.check()` below can bring about.
    with CollieClient(api, token, timeout_s=WATCH_TIMEOUT_S) as client:
        while not stopping["flag"]:
            try:
                stack.check()
            except ChildFailed:
                bar.close()
                raise
            with contextlib.suppress(Exception):  # the service may be restarting; keep watching
                bar.show(client.run(run_id))
            if stack.finished("trainer"):
                bar.close()
                print(f"collie up: trainer finished; outputs in {stack.out / 'trainer'}")
                stack.log("trainer finished")
                if exit_when_done:
                    return 0
                print("collie up: the service stays up for inspection; Ctrl-C to stop.", flush=True)
                while not stopping["flag"]:
                    stack.check()
                    time.sleep(0.5)
                return 0
            time.sleep(0.5)
    bar.close()
    print("collie up: stopping…", flush=True)
    return INTERRUPTED
