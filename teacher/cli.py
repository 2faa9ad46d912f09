"""`collie teacher`: the scripted oracle labels a run's queries through the API, like a person."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import time
from urllib.parse import urlsplit

from collie.argtypes import float_in, http_url, record_id, seed
from collie.client import (
    ApiError,
    BadAnswer,
    CollieClient,
    Unauthorized,
    Unavailable,
    Unreachable,
    Unsendable,
    no_answer,
)
from collie.tokens import add_token_arguments, resolve_token
from teacher import TeacherLoop, oracle_for

DASHED_VALUE_OPTIONS = ("--token",)  # a token may start with "-": `--token -x…` is its value (collie/cli.py)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--api", required=True, type=http_url, help="service URL, e.g. http://127.0.0.1:8000")
    add_token_arguments(parser, "labeler")
    parser.add_argument("--run", type=record_id, required=True, help="run id")
    parser.add_argument(
        "--noise-band",
        type=float_in(0, low_open=False),
        default=0.0,
        help="R_error: random labels this close to a boundary (≥ 0)",
    )
    parser.add_argument("--seed", type=seed, default=0, help="seed of the noise")
    # > 0, as `collie up --teacher-rate`: a rate of 0 or less would never label
    parser.add_argument("--rate", type=float_in(0), default=None, help="at most this many labels per second (> 0)")
    parser.add_argument(
        "--until-done", action="store_true", help="keep waiting for new queries until the run is finished or stopped"
    )
    parser.add_argument(
        "--wait",
        type=float_in(0, low_open=False),
        default=0.0,
        help="seconds to wait for the service and the run to appear (compose)",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log every label")


def wait_for_run(client: CollieClient, run_id: int, patience_s: float) -> None:
    """Started beside a trainer that has yet to create its run: wait for it (or give up)."""
    deadline = time.monotonic() + patience_s
    while True:
        try:
            client.run(run_id)
            return
        except (ApiError, Unreachable) as exc:
            if (isinstance(exc, ApiError) and exc.status != 404) or time.monotonic() > deadline:
                raise
        time.sleep(1.0)


def service_fault(client: CollieClient, exc: ApiError | Unreachable, run_id: int) -> str:
    """What went wrong, naming the service: no answer (or one damaged on the way), not a collie
    service (a 404 where the run should be, and on /api/health too), a refused token, no such run,
    an answer this collie cannot read, a request it cannot send, or what it answered."""
    where = f"the labeling service at {client.api}"
    if isinstance(exc, Unreachable):
        return f"{where} {no_answer(exc)}"
    if isinstance(exc, Unauthorized):
        return f"{where} refused the token ({exc})"
    if isinstance(exc, Unavailable):  # 5xx, 429
        return f"{where} is busy or failing now ({exc})"
    if isinstance(exc, BadAnswer):  # e.g. a proxy's page with a 200
        return f"{where} sent an answer this collie cannot read: {exc}"
    if isinstance(exc, Unsendable):
        return f"cannot ask {where}: {exc}"
    if exc.status == 404:  # no such run, or no collie there at all: its health says which
        try:
            client.health()
        except Unavailable:
            return f"{where} has no run {run_id}, or is busy now (its health check failed too)"
        except ApiError:
            path = f"{urlsplit(client.api).path}/api/runs/{run_id}"
            return f"{client.api} is not a collie service (404 on {path}); check --api"
        return f"{where} has no run {run_id}"
    return f"{where} answered {exc}"


def unreadable_run(client: CollieClient, exc: BadAnswer) -> str:
    """An answer where the run should be that is not a run: from something other than a collie
    service (its health check fails too), or a run this collie cannot read (a newer collie's?)."""
    try:
        client.health()
    except (ApiError, Unavailable):
        return f"{client.api} is not a collie service (no run in its answer: {exc})"
    return (
        f"the labeling service at {client.api} answered with a run this collie cannot read (a newer collie's?): {exc}"
    )


def run(args: argparse.Namespace) -> int:
    try:
        token = resolve_token(args, "labeler")
    except ValueError as exc:
        print(f"collie teacher: error: {exc}", file=sys.stderr)
        return 2
    if not token:
        print(
            "collie teacher: error: give --token-file, set COLLIE_TOKEN (or COLLIE_LABELER_TOKEN), or --token",
            file=sys.stderr,
        )
        return 2
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(message)s")
    with CollieClient(args.api, token) as client:
        try:
            wait_for_run(client, args.run, args.wait)
            oracle = oracle_for(client, args.run, args.noise_band, args.seed)
        except BadAnswer as exc:  # an answer, but not a run's: another web service, or a newer collie's run
            print(f"collie teacher: error: {unreadable_run(client, exc)}", file=sys.stderr)
            return 2
        except (ApiError, Unreachable) as exc:
            print(f"collie teacher: error: {service_fault(client, exc, args.run)}", file=sys.stderr)
            # a refusal (token, path, run) fails again: a usage error, as argparse's (2); a service
            # that does not answer or is busy (5xx, 429) may be restarting: 1, after which `collie
            # up` restarts the teacher (two 2s in a row end the stack)
            return 1 if isinstance(exc, Unavailable) else 2
        except ValueError as exc:  # NoRule, or a stored rule this version cannot read
            print(f"collie teacher: error: {exc}", file=sys.stderr)
            return 2
        loop = TeacherLoop(client, args.run, oracle, rate=args.rate)

        def on_interrupt(_signum: int, _frame: object) -> None:
            # A plain flag the loop checks too (Python drops a raise that lands in a weakref callback);
            # not loop.stop.set(), whose lock the interrupted thread may hold inside stop.wait().
            loop.interrupted = True
            raise KeyboardInterrupt

        signal.signal(signal.SIGINT, on_interrupt)
        try:
            n = loop.run(until_done=args.until_done)
        except KeyboardInterrupt:
            n = loop.labelled
        except ApiError as exc:  # e.g. a trainer's token, or one revoked meanwhile
            said = service_fault(client, exc, args.run)
            print(f"collie teacher: error: {said} (after {loop.labelled} labels)", file=sys.stderr)
            return 2
    print(f"collie teacher: labelled {n} queries of run {args.run}", flush=True)
    return 0
