"""`collie train`: one run of Algorithm 1. Every config value can be overridden from the command line
(`--hidden 256 --feedback-every 50 …`); `--resume` continues exactly from DIR/checkpoint.pt."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import errno
import json
import os
import re
import shlex
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from collie import early_term
from collie.argtypes import Given, http_url, int_in, record_id, seed
from collie.env_names import PIXEL_ENVS
from collie.processes import LockHeld, hold_lock, lock_holder
from collie.startup import mark
from collie.tasks import default_task, task_names
from collie.tokens import add_token_arguments, resolve_token
from collie.whole_files import UNWRITABLE, broken_link, read_only_disk
from trainer.config import PRESETS, Config, field_notes, first_version, flag, make_config, people_schedule
from trainer.methods import METHODS
from trainer.run_files import ResumeError, RunFolderError, has_checkpoint, read_json_object, write_json
from trainer.same_run import differing_keys
from trainer.task_choice import INSTRUCTION_TASK, RunRule, choose_rule, from_stored, saved_rule

if TYPE_CHECKING:
    from collie.client import ApiError
    from collie.env_names import EnvName
    from collie.schemas import RunRead
    from trainer.feedback.http import HttpFeedback

CREATION_FILE = "run_creation.json"  # a run's creation on the service, sent but not yet answered (begun_creation)
SERVICE_FLAGS = ("--run-id", "--feedback-timeout", "--token", "--token-file")  # meaningless without --api
MAIN_ARGS = ("env", "task", "task_file", "instruction", "method", "preset", "seed", "out")


DASHED_VALUE_OPTIONS = ("--token",)  # a token may start with "-": `--token -x…` is its value (collie/cli.py)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.set_defaults(given=frozenset())  # the run's flags given on this command line (Given)
    p.add_argument(
        "--env",
        default="point",
        action=Given,
        help="point, ant, half_cheetah, quadruped, humanoid or car (default point)",
    )
    p.add_argument(
        "--task",
        default=None,
        action=Given,
        help=f"one of: {', '.join(task_names())} (default north; right on half_cheetah, hazard on car; docs/tasks.md)",
    )
    p.add_argument(
        "--task-file",
        default=None,
        action=Given,
        help="a task rule from a TOML/JSON spec or a Python file (docs/tasks.md)",
    )
    p.add_argument(
        "--instruction", default=None, action=Given, help="no rule: people label by this intent in words (needs --api)"
    )
    p.add_argument("--method", default="collie", action=Given, help=f"one of: {', '.join(METHODS)} (default collie)")
    p.add_argument("--preset", default="cpu", action=Given, help=f"one of: {', '.join(PRESETS)} (default cpu)")
    p.add_argument("--seed", type=seed, default=0, action=Given, help="the run's seed (default 0)")
    p.add_argument("--out", default=None, help="run folder (default runs/<env>-<task>-<method>-s<seed>)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--api", default=None, type=http_url, help="labeling service URL: labels come over HTTP instead of the oracle"
    )
    add_token_arguments(p, "trainer")  # --token / --token-file / COLLIE_TOKEN, for --api
    p.add_argument(
        "--run-id",
        type=record_id,
        default=None,
        help="existing run id on the service, whose task and label budget it follows (default: create one)",
    )
    p.add_argument(
        "--feedback-timeout",
        type=float,
        default=None,
        help="seconds to wait for a session's labels before continuing with what arrived "
        "(an operator may change it from the dashboard)",
    )
    p.add_argument(
        "--people-schedule",
        action="store_true",
        help="people label this run: its first session comes earlier where the preset's warm-up would keep "
        "them waiting (trainer/config.py people_schedule), unless --epochs/--warmup/--feedback-every are given",
    )
    p.add_argument(
        "--print-config", action="store_true", help="print the config these flags make (JSON) and exit: no run"
    )
    group = p.add_argument_group("hyperparameters (override the preset; --print-config shows its values)")
    notes = field_notes()
    for f in dataclasses.fields(Config):
        if f.name in MAIN_ARGS or f.name in ("extra", "preset"):
            continue
        option, note = flag(f.name), notes.get(f.name)
        values = re.findall(r"'([^']*)'|\"([^\"]*)\"", str(f.type)) if "Literal" in str(f.type) else []
        if values:
            note = f"{note or ''} (one of: {', '.join(a or b for a, b in values)})".lstrip()
        if f.type in ("bool", bool, "bool | None"):  # None: the option's own default (e.g. fast_ops)
            # a bare flag means true (`--compile`); `--compile false` still works
            group.add_argument(
                option,
                dest=f.name,
                default=None,
                type=_parse_bool,
                metavar="BOOL",
                nargs="?",
                const=True,
                action=Given,
                help=note,
            )
        else:
            kinds: dict[str, Callable[[str], Any]] = {"int": int_type(f.name), "float": float}
            kind = kinds.get(str(f.type), str)
            group.add_argument(option, dest=f.name, default=None, type=kind, action=Given, help=note)


MAX_HIDDEN = 65_536  # units per layer: one layer this wide already holds 17 GB of weights (hidden² float32)
# intra-op threads: OpenMP starts them all at torch's import; 100000 failed there and then crashed (SIGSEGV)
MAX_THREADS = 1024


def int_type(name: str) -> Callable[[str], int]:
    """An int hyperparameter's argparse type: bounded above (the Config's checks say what is too
    low), --epochs by what the labeling service stores, --hidden by memory, the others by what a
    32-bit integer holds (a larger one overflows in numpy or torch, as a traceback)."""
    from collie.schemas import MAX_INT

    if name == "hidden":
        return int_in(None, MAX_HIDDEN, "units per layer; a layer's weights grow with its square")
    if name == "threads":
        return int_in(None, MAX_THREADS, "intra-op threads; more than the cores only slows a run")
    if name == "epochs":
        return int_in(None, MAX_INT, "the most a run's epochs on the labeling service may be")
    return int_in(None, MAX_INT)


RESUME_MAY_CHANGE = ("epochs",)  # what a resumed run takes from the command line (it may only extend them)
# how many cores and which device a resumed run uses, not what it computes: taken from the command
# line when given (more intra-op threads or another device may round some reductions differently, as
# a fresh run with them would; a run moved off a GPU machine resumes with --device cpu).
# Not --physics-threads: the number of rollout groups changes the policy's noise draws.
RESUME_RUNTIME = ("threads", "device")


def moved_device(stored: str, given: str) -> bool:
    """Whether a resume moves a run to another kind of device (cpu, cuda, mps): its fast ops are
    chosen again. "auto" names no kind: the run keeps its own."""
    kinds = {name.split(":")[0] for name in (stored, given)}
    return len(kinds) == 2 and "auto" not in kinds


def ignored_on_resume(args: argparse.Namespace, asked: Config, run: Config) -> list[str]:
    """The given flags whose values differ from the resumed run's own config (which wins), and
    --epochs below the run's own (epochs may only be extended)."""
    extend_only = "; epochs may only be extended"
    return [
        f"{flag(k)} {getattr(asked, k)} (the run's: {getattr(run, k)}{extend_only * (k == 'epochs')})"
        for k in sorted(args.given)
        if (k == "epochs" and asked.epochs < run.epochs)
        or (k not in (*RESUME_MAY_CHANGE, *RESUME_RUNTIME) and hasattr(run, k) and getattr(asked, k) != getattr(run, k))
    ]


def _parse_bool(text: str) -> bool:
    if text.lower() in ("1", "true", "yes", "on"):
        return True
    if text.lower() in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected true/false, got {text!r}")


SCHEDULE_KEYS = ("epochs", "warmup", "feedback_every")  # a schedule of the person's own


def config_from_args(args: argparse.Namespace) -> Config:
    overrides = {
        f.name: getattr(args, f.name, None)
        for f in dataclasses.fields(Config)
        if f.name not in ("env", "preset", "extra")
    }
    if args.instruction is not None and not args.instruction.strip():  # else read as the task "instruction"
        raise ValueError("--instruction is empty: say in words what people label by (or drop it for a task rule)")
    if args.instruction is not None and args.task is not None:
        raise ValueError("--instruction is for a run without a rule: drop --task (or drop --instruction)")
    if args.instruction is not None:
        overrides["task"] = INSTRUCTION_TASK
    elif args.task_file is not None and args.task is None:
        overrides["task"] = ""  # the file names its task
    name = overrides["task"] or (Path(args.task_file).stem if args.task_file else default_task(args.env))
    overrides["out"] = args.out or f"runs/{args.env}-{name}-{args.method}-s{args.seed}"
    if getattr(args, "people_schedule", False) and all(overrides[k] is None for k in SCHEDULE_KEYS):
        overrides.update(people_schedule(args.preset, args.env))
    return make_config(args.preset, args.env, **overrides)


def idle_parts(cfg: Config) -> list[str]:
    """What the run's sizes leave undone, said before it trains hours for it (not refused: a larger
    --epochs on --resume may give them room)."""
    said = []
    collected = cfg.epochs * cfg.episodes_per_epoch * cfg.episode_steps
    if cfg.start_transitions > collected:
        said.append(
            f"no gradient step in this run: --start-transitions {cfg.start_transitions} is more than the "
            f"{collected} transitions its {cfg.epochs} epochs collect"
        )
    # epochs run 1 … --epochs, and the first session comes at epoch --warmup (an equal one is the last)
    if METHODS[cfg.method].asks_labels and (cfg.warmup > cfg.epochs or cfg.total_queries == 0):
        why = "--total-queries 0" if cfg.total_queries == 0 else f"--warmup {cfg.warmup} > --epochs {cfg.epochs}"
        said.append(f"{cfg.method} asks for no label in this run ({why}): it learns as METRA does")
    return said


def wait_for_service(api: str, token: str, timeout_s: float = 120.0) -> None:
    """Until the service answers (`collie up` starts us beside it, before it serves)."""
    from collie.client import Backoff, CollieClient, Unavailable

    deadline = time.monotonic() + timeout_s
    with early_term.raising(), CollieClient(api, token) as client:  # SIGTERM (docker stop) ends the wait at once
        for delay in Backoff(0.1, 1.0).delays():
            try:
                client.health()
                return
            except Unavailable:
                if early_term.ASKED.is_set():  # its KeyboardInterrupt was lost in a finalizer
                    raise KeyboardInterrupt from None
                if delay == 0.1:  # the first miss: say what we wait for
                    said = f"waiting for the labeling service at {api} (at most {timeout_s:.0f} s)"
                    print(f"collie train: {said}", file=sys.stderr, flush=True)
                if time.monotonic() + delay > deadline:
                    raise ValueError(f"the labeling service at {api} did not answer in {timeout_s:.0f} s") from None
                time.sleep(delay)


def http_feedback(args: argparse.Namespace, cfg: Config, rule: RunRule) -> tuple[HttpFeedback, RunRule]:
    """Labels from the service: reuse the run named by --run-id or remembered in OUT/service_run.json
    (a restarted trainer rebuilds D0/D1/D2 from it; it follows the rule the service holds), else
    create a run with `rule` and remember it."""
    from collie.client import Conflict, new_request_id
    from collie.schemas import MAX_FEEDBACK_TIMEOUT_S, EnvDims, RunCreate
    from trainer.envs import make_env
    from trainer.feedback.http import HttpFeedback

    token = resolve_token(args, "trainer")
    if not token:
        raise ValueError("--api needs a trainer token: --token-file, COLLIE_TOKEN or --token")
    if args.feedback_timeout is not None and not 0 < args.feedback_timeout <= MAX_FEEDBACK_TIMEOUT_S:
        raise ValueError(f"--feedback-timeout must be in (0, {MAX_FEEDBACK_TIMEOUT_S}] seconds")
    wait_for_service(args.api, token)
    memo = Path(cfg.out) / "service_run.json"
    run_id = args.run_id
    remembered = None
    if memo.exists() and (run_id is None or args.resume):
        try:
            remembered = remembered_run(memo)
        except ValueError as exc:
            if run_id is None:
                raise ValueError(f"{exc}; give the run's --run-id") from None
            # the run is named: the memo would only check that it is this folder's, and cannot be read
            print(f"collie train: warning: {exc}; continuing with run {run_id}", file=sys.stderr)
    if remembered is not None and args.resume:  # the checkpoint is that run's: another's would lose its labels
        mine, where = remembered
        if run_id is not None and run_id != mine:
            raise ValueError(
                f"--resume: {cfg.out} belongs to run {mine}{f' on {where}' if where else ''} (service_run.json), "
                f"not run {run_id}: give --run-id {mine}, or another --out for run {run_id}"
            )
    creation = Path(cfg.out) / CREATION_FILE
    begun = begun_creation(creation) if run_id is None and remembered is None and creation.exists() else None
    if run_id is None and remembered is not None:
        run_id = remembered[0]
        if not args.resume:  # a trainer that died before its first checkpoint: a new run would orphan it
            raise ValueError(
                f"{cfg.out} belongs to run {run_id} of the service but holds no checkpoint: give --run-id {run_id} "
                f"to train it again from epoch 0 (its labels are kept), or remove {memo} to create a new run"
            )
    kwargs = {"timeout_s": args.feedback_timeout}
    if run_id is not None:
        source = HttpFeedback(args.api, token, int(run_id), **kwargs)
        held = source.held_run()
        unlike = unlike_the_run(held, cfg, args.given)
        if remembered is not None and args.resume and remembered[1] not in (None, args.api):
            # the service moved (`collie up --port 0`), or this is another service: its run must be this one
            moved = service_moved_unlike(held.config, cfg)
            if moved:
                raise ValueError(
                    f"--resume: {cfg.out} belongs to run {remembered[0]} on {remembered[1]} (service_run.json); "
                    f"run {run_id} on {args.api} is another run (its config differs in {', '.join(moved)}): give "
                    f"--api {remembered[1]}, or another --out"
                )
        if unlike:  # its sessions would not fit the run (the service refuses other dims) nor its labels mean the same
            raise ValueError(
                f"run {source.run_id} on the service is not this trainer's: {'; '.join(unlike)} (give the run's "
                "flags, or no --run-id for a new run)"
            )
        ended = ended_for_this_trainer(held, args.resume, cfg.out)
        if ended:  # its sessions would all be refused (409): say why now, not in a traceback later
            raise ValueError(ended)
        rule = from_stored(held.task_definition, held.instruction)
        if rule.task is None and rule.instruction is None:  # a run made before the service kept rules (12-01)
            try:
                rule = choose_rule(dataclasses.replace(cfg, task=held.task, task_file="", instruction=""))
            except ValueError as exc:
                raise ValueError(
                    f"run {source.run_id} on the service holds neither a task rule nor an instruction, and its "
                    f"task {held.task!r} is no built-in one ({exc})"
                ) from None
        cfg.task = held.task  # the rule it follows is the run's: its files and reports name that task
        joining = not args.resume  # a resumed trainer keeps its checkpoint's budget, as all its config
        if joining and METHODS[cfg.method].asks_labels and held.n_total is not None:  # the run's, as the dashboard's
            cfg.total_queries = held.n_total
    else:
        if rule.task is not None and rule.definition is None:
            raise ValueError(f"task {cfg.task!r} is a rule function: only a task painted from regions can travel")
        env = make_env(cfg.env, episode_steps=cfg.episode_steps)
        dims = EnvDims(obs_dim=env.obs_dim, nq=env.nq, nv=env.nv, horizon=cfg.segment_length, skill_dim=cfg.skill_dim)
        env.close()
        spec = RunCreate(
            env=cast("EnvName", cfg.env),  # one of the registry's, which are ENV_NAMES (tests/test_envs.py)
            task=cfg.task,
            method=cfg.method,
            config=cfg.to_dict(),
            dims=dims,
            n_total=cfg.total_queries if METHODS[cfg.method].asks_labels else 0,
            epochs_total=cfg.epochs,
            feedback_timeout_s=args.feedback_timeout,
            task_definition=rule.definition,
            instruction=rule.instruction,
            client_request_id=begun or new_request_id(),
        )
        # Remembered before it is sent: a trainer that dies before the answer, started again, sends the
        # same creation and gets the run the first made, not a second run beside an orphan.
        creation.parent.mkdir(parents=True, exist_ok=True)
        write_json(creation, {"client_request_id": spec.client_request_id})
        try:
            source = HttpFeedback.create(args.api, token, spec, **kwargs)
        except Conflict as exc:
            if begun is None:
                raise
            raise ValueError(
                f"{creation} began the creation of a run with other flags ({exc.detail}): give the flags it was "
                f"started with, or remove {creation} to create a new run"
            ) from None
        ended = ended_for_this_trainer(source.held_run(), False, cfg.out) if begun is not None else None
        if ended:  # the run the start before made, since stopped by an operator (or failed)
            raise ValueError(f"{ended}; remove {creation} to create a new run")
    try:
        memo.parent.mkdir(parents=True, exist_ok=True)
        write_json(memo, {"api": args.api, "run_id": source.run_id})
        creation.unlink(missing_ok=True)
    except OSError as exc:  # a full disk: a run no folder remembers would show "created" on the dashboard for good
        if run_id is None:
            with contextlib.suppress(Exception):  # best effort: the start fails with the disk's refusal either way
                why = f"its trainer could not write {memo} ({(exc.strerror or str(exc)).lower()})"
                source.client.set_status(source.run_id, "failed", message=why)
            with contextlib.suppress(OSError):  # sent again, it would answer that failed run
                creation.unlink(missing_ok=True)
        raise
    # the id a labeler's UI and a teacher are started with (`--run N`)
    made = "continues" if run_id is not None else "created" if begun is None else "created (or found again)"
    print(f"collie train: {made} run {source.run_id} on {args.api} (remembered in {memo})", file=sys.stderr)
    return source, rule


def service_answered(api: str, exc: ApiError) -> str:
    """The service's refusal in one line (an unreadable answer said once: collie.client.answered)."""
    from collie.client import answered

    return f"the labeling service at {api} {answered(exc)}"


def service_moved_unlike(held: dict[str, Any], cfg: Config) -> list[str]:
    """The config keys in which the run a moved service holds differs from this folder's, among
    those it holds (a run made by hand may hold few or none), epochs aside (more extend a run)."""
    try:
        keys = differing_keys(held, cfg.to_dict(), besides=("epochs",))
    except ValueError:  # a hand-made config of the wrong types: nothing to compare by
        return []
    return [k for k in keys if k in held]


def remembered_run(memo: Path) -> tuple[int, str | None]:
    """The run id and service URL a run folder's service_run.json names (an id: a positive integer,
    as the service's; not 1.5 or true read as run 1); ValueError naming the file if it is damaged."""
    from collie.schemas import MAX_INT

    data = read_json_object(memo)  # RunFolderError (a ValueError) naming it
    run_id, api = data.get("run_id"), data.get("api")
    if not isinstance(run_id, int) or isinstance(run_id, bool) or not 1 <= run_id <= MAX_INT:
        raise ValueError(f"{memo} is damaged (run_id {json.dumps(run_id)} is not a run id)")
    if api is not None and not isinstance(api, str):
        raise ValueError(f"{memo} is damaged (api {json.dumps(api)} is not a URL)")
    return run_id, api


def begun_creation(creation: Path) -> str | None:
    """The client_request_id of a run creation whose answer this folder never got (CREATION_FILE,
    written just before POST /runs, removed once service_run.json names the run); a damaged file
    names none (a new creation: a trainer that died while writing it had sent nothing)."""
    try:
        key = read_json_object(creation).get("client_request_id")
    except ValueError:
        return None
    return key if isinstance(key, str) and key else None


def ended_for_this_trainer(held: RunRead, resume: bool, out: str) -> str | None:
    """Why the service's run takes no training from this trainer, if it does not: a run that failed
    takes no session again; one that ended (finished, or stopped by an operator) is continued only
    from a checkpoint (--resume: a stopped run then ends at once, a finished one may be extended)."""
    if held.status == "failed":
        return f"run {held.id} failed on the service: it takes no more sessions (start a new run: another --out)"
    if held.status == "finished" and not resume:
        how = "was stopped by an operator" if held.control == "stop" else "is finished"
        return f"run {held.id} on the service {how}, and {out} holds no checkpoint to continue it from"
    return None


def unlike_the_run(held: RunRead, cfg: Config, given: frozenset[str] = frozenset()) -> list[str]:
    """Where this trainer's config differs from the service's run in what its sessions carry, or in
    the task it was told (`given`: the flags on its command line; with none, it follows the run's)."""
    pairs = {
        "--env": (held.env, cfg.env),
        "--method": (held.method, cfg.method),
        "--segment-length": (held.dims.horizon, cfg.segment_length),
        "--skill-dim": (held.dims.skill_dim, cfg.skill_dim),
    }
    if given & {"task", "task_file", "instruction"}:  # its metrics would be another task's under this one's name
        pairs["--task"] = (held.task, cfg.task)
    if "total_queries" in given and METHODS[cfg.method].asks_labels and held.n_total is not None:  # past the budget
        pairs["--total-queries"] = (held.n_total, cfg.total_queries)
    return [f"{flag} {mine} here, {theirs} there" for flag, (theirs, mine) in pairs.items() if theirs != mine]


RUN_OUTPUTS = (  # what the end-of-run line lists, where written
    "metrics.jsonl",
    "summary.json",
    "task.json",
    "skills_latest.png",
    "guidance_latest.png",
    "curves.png",
    "plots/",
    "tb/",
    "checkpoint.pt",
)
RUN_FILES = ("checkpoint.pt", "summary.json")  # what a run leaves that a fresh start would overwrite


def check_out(out: Path, resume: bool) -> list[Path]:
    """Refuse a run folder that a fresh start would overwrite (a long run lost by a forgotten --resume),
    one --resume cannot continue, or one we cannot write; then makes it (creating it is the one
    test of writing there that root, for whom access() says yes everywhere, cannot pass by fiat).
    Returns the folders it created, deepest first (removed again if the start fails)."""
    way = [*reversed(out.absolute().parents), out.absolute()]  # from / down
    closed = next((p for p in way if os.path.isdir(p) and not os.access(p, os.X_OK)), None)
    if closed is not None:  # nothing below it can even be looked at
        raise ValueError(f"--out {out}: cannot enter {closed} (permission denied)")
    try:
        if out.exists() and not out.is_dir():
            raise ValueError(f"--out {out} is a file, not a folder")
        if resume and (out / "checkpoint.pt").is_dir():
            raise ValueError(f"--resume: {out / 'checkpoint.pt'} is a folder, not a checkpoint")
        holds_a_run = any((out / name).exists() for name in RUN_FILES)
        if resume and not has_checkpoint(out):
            busy = lock_holder(out / LOCK_FILE)
            if busy is not None:  # a run before its first checkpoint: "nothing to resume" would mislead
                raise ValueError(
                    f"another collie train (pid {busy or '?'}) is training in {out}, and has written no "
                    "checkpoint yet: wait for it or stop it, or choose another --out"
                )
            if holds_a_run:  # its checkpoint deleted, or a run stopped before its first one
                raise ValueError(
                    f"--resume: {out} holds a run but no checkpoint.pt to continue it from: start it again "
                    "in another --out (or remove this one)"
                )
            raise ValueError(f"--resume: no checkpoint at {out / 'checkpoint.pt'}: nothing to resume")
        source = rescored_from(out) if resume else None
        if source:
            raise ValueError(f"--resume: {out} is {source} judged by another task (collie rescore): resume {source}")
        if not resume and holds_a_run:
            continued = (
                "add --resume to continue it, or choose"
                if has_checkpoint(out)
                else "it has no checkpoint.pt to continue it from: choose"
            )
            raise ValueError(f"{out} already holds a run: {continued} another --out (or remove it)")
        nearest = next(p for p in (out.absolute(), *out.absolute().parents) if p.exists())  # the folder or its creator
        if not nearest.is_dir():
            raise ValueError(f"--out {out}: {nearest} is a file, not a folder")
        if not os.access(nearest, os.W_OK | os.X_OK):
            why = "read-only file system" if read_only_disk(nearest) else "permission denied"
            raise ValueError(f"--out {out}: cannot write in {nearest} ({why})")
    except PermissionError as exc:  # e.g. a file inside that this user may not read
        raise ValueError(f"--out {out}: permission denied ({exc.filename})") from None
    made = [p for p in (out.absolute(), *out.absolute().parents) if not p.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # e.g. /sys, read-only for root too; a link to an unmounted disk
        raise ValueError(f"--out {out}: cannot create it ({broken_link(exc) or exc.strerror})") from None
    return made


LOCK_FILE = "train.lock"


def finished_at(out: Path) -> int | None:
    """The epochs of a run that finished (summary.json), else None (also for a damaged summary.json:
    the checkpoint, not the summary, is what a resume reads, and the run rewrites it)."""
    path = out / "summary.json"
    try:
        summary = read_json_object(path) if path.exists() else {}
    except RunFolderError:
        return None
    done = summary.get("epochs_done")
    return int(done) if summary.get("status") == "finished" and isinstance(done, int) else None


def checkpoint_config(out: Path) -> dict[str, Any]:
    """The config a run's checkpoint.pt carries (for a run folder whose config.json was lost)."""
    from trainer.checkpoint import load_checkpoint

    config = load_checkpoint(out / "checkpoint.pt").get("config")
    if not isinstance(config, dict):
        raise ResumeError(f"{out / 'checkpoint.pt'} holds no config, and {out / 'config.json'} is missing")
    return dict(config)


def lock_run_folder(out: Path) -> int:
    """An exclusive lock on OUT/train.lock for this process's life (the descriptor stays open), so
    two trainers never write one run folder; ValueError naming the one that holds it."""
    try:
        return hold_lock(out / LOCK_FILE)
    except LockHeld as held:
        raise ValueError(
            f"another collie train (pid {held.holder or '?'}) is training in {out}: wait for it or stop it, "
            "or choose another --out"
        ) from None


def rescored_from(out: Path) -> str | None:
    """The run `collie rescore` made `out` from, if it did (a damaged summary.json: none, as a
    killed run may leave it; the resume does not read it)."""
    try:
        return read_json_object(out / "summary.json").get("rescored_from") if (out / "summary.json").is_file() else None
    except RunFolderError:
        return None


def remove_if_empty(folders: list[Path]) -> None:
    """Undo check_out's folders after a refused start (deepest first; any that holds a file stays)."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


def discard_unstarted(out: Path, held_before: set[str], made: list[Path]) -> None:
    """Undo a fresh start interrupted before its first checkpoint (its config.json, metrics.jsonl,
    tb/…: a folder `--resume` cannot continue). What the folder held before stays, and so does
    service_run.json, with which a start again continues the same run of the labeling service (and
    CREATION_FILE, with which it makes the run it was making)."""
    for entry in out.iterdir():
        if entry.name in held_before or entry.name in ("service_run.json", CREATION_FILE):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
    remove_if_empty(made)


def write_failure(exc: OSError, out: Path) -> str:
    """Why the run stopped writing, where, and how it goes on: checkpoints are written whole
    (write_whole), so the last one stays as it was and `--resume` continues from it."""
    said = (exc.strerror or str(exc)).lower()
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        said, when = f"the disk is full ({said})", "once there is space"
    else:  # EROFS
        said, when = f"the file system is read-only now ({said})", "once it is writable"
    where = exc.filename or out
    how = f"continue it with --resume {when}" if has_checkpoint(out) else f"start it again {when}"
    return f"the run stopped: {said} writing {where}: {how}"


# what a run allocates by (replay, evaluation envs, networks, batches, rollouts): named when memory runs out
SIZE_KEYS = (
    "replay_capacity",
    "eval_trajectories",
    "hidden",
    "layers",
    "batch_size",
    "episodes_per_epoch",
    "episode_steps",
    "epochs",  # the replay is counted as far as the run fills it
)


ALLOCATION_FAILED = ("Could not allocate memory", "DefaultCPUAllocator: can't allocate memory", "CUDA out of memory")


def short_of_memory(exc: BaseException, args: argparse.Namespace) -> str | None:
    """The line for an allocation that failed (the memory plan's refusal, numpy's MemoryError,
    MuJoCo's FatalError, torch's RuntimeError or OutOfMemoryError), naming the sizes given; None for
    any other error."""
    said = str(exc)
    # MuJoCo's, in any wrapper; torch's on the CPU (a RuntimeError) and on a GPU (torch.OutOfMemoryError)
    if not (isinstance(exc, MemoryError) or any(words in said for words in ALLOCATION_FAILED)):
        return None
    sizes = ", ".join(f"{flag(k)} {getattr(args, k)}" for k in SIZE_KEYS if k in args.given)
    if not sizes:
        sizes = "its config.json's" if args.resume else f"--preset {args.preset}'s"
    from trainer.memory_plan import NotEnoughMemory

    measured = f" ({exc})" if isinstance(exc, NotEnoughMemory) else ""  # checked before allocating: the figures
    later = ", or start it once those runs have ended" if isinstance(exc, NotEnoughMemory) and exc.fits_alone else ""
    return f"this machine has not enough memory for the run's sizes ({sizes}){measured}: give smaller ones{later}"


def run(args: argparse.Namespace) -> int:
    from trainer.envs import ENV_NAMES

    early_term.note_sigterm()  # collie.cli did already, before the imports; `python -m trainer.cli` did not

    made: list[Path] = []
    locked = False
    out: Path | None = None  # the run's folder, once its config is made
    try:
        if args.env not in ENV_NAMES:
            raise ValueError(f"unknown env {args.env!r}; valid: {', '.join(ENV_NAMES)}")
        cfg = config_from_args(args)
        out = Path(cfg.out)
        if args.print_config:
            if args.resume:
                raise ValueError("--print-config shows what flags make; a run's own config is OUT/config.json")
            rule = choose_rule(cfg)  # a bad task or task file is refused here as the run would refuse it
            if rule.definition is not None:
                cfg.task = rule.definition.name
            try:
                print(json.dumps(cfg.to_dict(), indent=2), flush=True)
            except OSError as exc:  # e.g. > /dev/full: no run folder is involved
                raise ValueError(f"--print-config: cannot write to standard output: {exc.strerror or exc}") from None
            return 0
        unused = [flag for flag in SERVICE_FLAGS if getattr(args, flag[2:].replace("-", "_"), None) is not None]
        if args.api is None and unused:  # a run without a service would ignore them, and a typo'd --api with them
            one = len(unused) == 1
            raise ValueError(f"{', '.join(unused)} {'is' if one else 'are'} for a run on a labeling service: "
                             f"give --api too (or drop {'it' if one else 'them'})")  # fmt: skip
        made = check_out(Path(cfg.out), args.resume)
        held_before = {entry.name for entry in Path(cfg.out).iterdir()}  # another's files; this start's are new
        lock_run_folder(Path(cfg.out))  # held until this process ends (the descriptor stays open)
        locked = True
        if args.resume and args.api is None and (Path(cfg.out) / "service_run.json").exists():
            raise ValueError(  # the oracle would label a run people label through the service
                f"--resume: {cfg.out} takes its labels from a labeling service (service_run.json): give --api "
                "and the trainer's token (or run `collie up` again with the same --out)"
            )
        if args.resume:
            # the run's own config wins, the command line may only extend epochs; a damaged config.json:
            # RunFolderError naming it; a missing one: the checkpoint's copy
            saved = Path(cfg.out) / "config.json"
            stored = read_json_object(saved) if saved.exists() else checkpoint_config(Path(cfg.out))
            source = str(saved if saved.exists() else Path(cfg.out) / "checkpoint.pt")
            asked, cfg = cfg, Config.from_stored(stored, source)  # a value of a wrong type: named
            cfg.epochs = max(cfg.epochs, asked.epochs if args.epochs else 0)
            cfg.out = asked.out  # where the folder is now (it may have been moved since)
            moved = "device" in args.given and moved_device(cfg.device, asked.device)
            if moved:  # fast ops as given, or chosen again below for the kind of device the run moves to
                cfg.fast_ops = asked.fast_ops
            for k in RESUME_RUNTIME:
                if k in args.given:
                    setattr(cfg, k, getattr(asked, k))
            try:  # the trainer checks again; here a value edited by hand is named with its file, not as a flag
                cfg.validate()
            except ValueError as exc:
                raise RunFolderError(f"{source}: {exc}") from None
            assumed = {k: v for k, v in first_version(stored).items() if k not in stored}
            if moved:
                assumed.pop("fast_ops", None)
            if assumed:  # config.json is rewritten with them: say so once, when they are filled in
                said = ", ".join(f"{flag(k)} {v if isinstance(v, str) else json.dumps(v)}" for k, v in assumed.items())
                print(f"collie train: {source} predates some options; it resumes as it ran: {said}", file=sys.stderr)
            ignored = ignored_on_resume(args, asked, cfg)
            if ignored:
                print(
                    f"collie train: warning: --resume keeps the run's config; ignored: {', '.join(ignored)}",
                    file=sys.stderr,
                )
            if finished_at(Path(cfg.out)) == cfg.epochs:
                print(
                    f"collie train: {cfg.out} finished all its {cfg.epochs} epochs: nothing to train "
                    f"(--epochs above {cfg.epochs} extends it)",
                    file=sys.stderr,
                )
        from trainer.threads import apply_openmp_env, resolve_threads

        cores = os.cpu_count() or 1
        if "threads" in args.given and cfg.threads > cores:  # allowed (a shared machine's may be low), but a slip?
            print(
                f"collie train: warning: --threads {cfg.threads} is more than this machine's {cores} cores",
                file=sys.stderr,
            )
        for said in idle_parts(cfg):
            print(f"collie train: warning: {said}", file=sys.stderr)
        apply_openmp_env(resolve_threads(cfg.threads, cfg.hidden))  # before torch loads OpenMP
        from trainer.fast_ops import fast_ops_pay
        from trainer.loop import Trainer, TrainingDiverged, pick_device

        mark("imports")  # torch, mujoco, the trainer's modules
        try:  # before a service is told of the run
            device = pick_device(cfg.device)
        except ValueError as exc:
            if not args.resume or "device" in args.given:
                raise
            raise ValueError(
                f"{exc} ({cfg.device} is the run's own, from {Path(cfg.out) / 'config.json'}; "
                "--resume with another --device moves the run)"
            ) from None
        if cfg.fast_ops is None:  # this machine's choice, in the service's copy of the config too
            cfg.fast_ops = fast_ops_pay(device)
        if cfg.env in PIXEL_ENVS and cfg.preset == "paper" and device.type == "cpu":  # else hours of it unsaid
            print(
                f"collie train: warning: the paper preset on {cfg.env}'s pixels is sized for a GPU: on this CPU "
                f"each of an epoch's {cfg.grad_steps} updates takes seconds (docs/envs.md); --preset cpu tries "
                "the loop out",
                file=sys.stderr,
                flush=True,
            )

        # a resumed run keeps the rule it started with, whatever its file says now
        rule = (saved_rule(cfg.out) if args.resume else None) or choose_rule(cfg)
        if rule.definition is not None:
            cfg.task = rule.definition.name
        feedback = None
        if args.api:
            from collie.client import ApiError
            from trainer.feedback import SourceRefused

            try:
                feedback, rule = http_feedback(args, cfg, rule)
            except ApiError as exc:  # a wrong token or run id: the service's answer, as `collie teacher` prints it
                raise ValueError(service_answered(args.api, exc)) from None
            except SourceRefused as exc:  # the same for an existing run (--run-id, --resume): its held_run()
                raise ValueError(f"{exc} at {args.api}") from None
            mark("run created")
        reporter = feedback.reporter if feedback is not None else None  # the same run's telemetry
        trainer = Trainer(cfg, feedback=feedback, progress=not args.no_progress, reporter=reporter, rule=rule)
        mark("trainer built")  # envs, observation statistics, networks, replay
    except BaseException as exc:  # Ctrl-C and SIGTERM too: a failed start leaves no empty run folder behind
        refusal = None
        if isinstance(exc, Exception):
            refusal = short_of_memory(exc, args) or (
                str(exc) if isinstance(exc, ValueError | FileNotFoundError) else None
            )
            if isinstance(exc, OSError) and exc.errno in UNWRITABLE and out is not None:  # a full disk names no file
                said = (exc.strerror or str(exc)).lower() + (f" (writing {exc.filename})" if exc.filename else "")
                refusal = f"cannot start the run in {out}: {said}"
        if made and locked and out is not None:  # a folder this start made holds nothing of a run yet
            (out / LOCK_FILE).unlink(missing_ok=True)  # (another's lock stays)
        remove_if_empty(made)
        if (
            refusal is None
            and isinstance(exc, SystemExit)
            and isinstance(exc.code, int)
            and exc.code
            and args.task_file
        ):
            refusal = f"the start ended with exit status {exc.code} while the task file {args.task_file} was read"
        if refusal is None and args.api and isinstance(exc, Exception):
            from collie.client import Unreachable, no_answer

            if isinstance(exc, Unreachable):  # e.g. gone while it created the run (asked again for ≈10 s): transient, 1
                print(f"collie train: error: the labeling service at {args.api} {no_answer(exc)}", file=sys.stderr)
                return 1
        if refusal is None:
            raise
        from trainer.memory_plan import refusal_status

        print(f"collie train: error: {refusal}", file=sys.stderr)
        return refusal_status(exc)  # 75 where memory promised to running runs is why
    from collie.client import ApiError
    from trainer.feedback import SourceRefused

    try:
        if early_term.ASKED.is_set():  # SIGTERM while the run started: `collie train: interrupted`, exit 130
            raise KeyboardInterrupt
        if feedback is not None and args.resume:  # once the run can train: a reopened run always has its trainer
            try:
                kept = feedback.extend_to(cfg.epochs)
                if kept:
                    print(f"collie train: warning: {kept}", file=sys.stderr)
            except ApiError as exc:
                print(f"collie train: error: {service_answered(args.api, exc)}", file=sys.stderr)
                return 2
        summary = trainer.run(resume=args.resume)
    except KeyboardInterrupt:  # before the loop's own handler (e.g. Ctrl-C in the epoch-0 evaluation), or a second
        out = Path(cfg.out)
        if not args.resume and not has_checkpoint(out):  # nothing trained: nothing to keep
            discard_unstarted(out, held_before, made)
            where = f"removed {out}, which it made" if not out.exists() else f"removed what it wrote in {out}"
            print(f"collie train: stopped before its first checkpoint: {where}", file=sys.stderr)
        elif trainer.checkpointed_at is not None and trainer.checkpointed_at < trainer.epoch:
            print(
                f"collie train: stopped in epoch {trainer.epoch} without a checkpoint of it: --resume continues "
                f"from epoch {trainer.checkpointed_at}'s",
                file=sys.stderr,
            )
        raise
    except OSError as exc:  # the run's own files: a full disk, a file system remounted read-only (was: a traceback)
        if exc.errno not in UNWRITABLE:  # any other is a fault to show whole
            raise
        print(f"collie train: error: {write_failure(exc, Path(cfg.out))}", file=sys.stderr)
        return 2
    except TrainingDiverged as exc:  # summary.json says "failed"; the last good checkpoint is kept
        print(f"collie train: error: the run failed: {exc}", file=sys.stderr)
        return 2
    except ResumeError as exc:  # a damaged or missing file of the run folder, named
        print(f"collie train: error: {exc}", file=sys.stderr)
        return 2
    except SourceRefused as exc:  # e.g. an operator revoked the token mid-run
        print(f"collie train: error: {exc}" + (f": {exc.advice}" if exc.advice else ""), file=sys.stderr)
        return 2
    except Exception as exc:  # an allocation that failed (e.g. the evaluation's envs); any other: raised
        refusal = short_of_memory(exc, args)
        if refusal is None:
            raise
        print(f"collie train: error: {refusal}", file=sys.stderr)
        return 2
    keys = (  # as summary.json: the last evaluation's epoch and metrics, the run's epochs and wall time
        "epochs_done",
        "epoch",
        "safe_coverage",
        "safe_ratio",
        "composite_coverage",
        "weighted_composite_coverage",
        "n_bins",
        "n_labels",
        "wall_s",
        "status",
    )
    print(json.dumps({k: summary.get(k) for k in keys}))
    written = [name for name in RUN_OUTPUTS if (Path(cfg.out) / name).exists()]  # e.g. no w(s) map without guidance
    print(f"run folder: {cfg.out}  ({', '.join(written)})")
    if summary.get("status") == "interrupted":  # "epoch" above is the last evaluation's: say where it stopped
        # a run labelled through a service resumes only with --api (refused without it, above)
        service = ["--api", args.api] if args.api else []
        again = shlex.join(["collie", "train", "--out", str(cfg.out), "--resume", *service])
        token = " with the trainer's token" if args.api else ""
        done = summary.get("epochs_done")
        print(f"collie train: stopped after epoch {done} of {cfg.epochs}; `{again}`{token} continues", file=sys.stderr)
    return 0 if summary.get("status") in ("finished", "stopped", "interrupted") else 1
