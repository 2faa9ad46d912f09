"""`collie label-ui --api URL`: serve the labeling UI for the service at URL."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import NoReturn
from urllib.parse import urlsplit

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco loads: offscreen, no X display (as collie up sets it)

from collie.addresses import not_listenable
from collie.argtypes import float_in, http_url, ipv4_host, port, record_id
from collie.mjmodels import MODEL_NAMES
from collie.schemas import MAX_LEASE_S
from collie.startup import mark
from collie.tokens import resolve_token
from collie.whole_files import write_whole
from labeling_ui.app import LabelingApp
from labeling_ui.session import UiConfig

MAX_FPS = 1000  # far above any screen's: more only skips frames
PROBE_S = 3.0  # the look at the service as the UI starts: no longer, so a silent host delays nothing much


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--api", required=True, type=http_url, help="the labeling service, e.g. http://127.0.0.1:8000")
    parser.add_argument("--port", type=port, default=8090, help="port to serve on (0: any free port; default 8090)")
    parser.add_argument("--host", type=ipv4_host, default="127.0.0.1", help="interface to bind (0.0.0.0 for every one)")
    parser.add_argument("--run", type=record_id, default=None, help="label only this run (default: newest with work)")
    parser.add_argument("--token", default=None, help="print a labeler URL that signs in with this token")
    parser.add_argument("--token-file", type=Path, default=None, help="the same, with the token read from this file")
    parser.add_argument(
        "--lease-s",
        type=float_in(0, MAX_LEASE_S),  # the service refuses a longer (or no) claim: every claim would fail
        default=60.0,
        help=f"claim length, renewed while a tab is open (default 60 s; at most {MAX_LEASE_S:g} s)",
    )
    parser.add_argument(
        "--fps",
        type=float_in(0, MAX_FPS),
        default=20.0,
        help=f"segment frames per second at 1x (default 20; at most {MAX_FPS})",
    )
    parser.add_argument(
        "--warm",
        default=",".join(MODEL_NAMES),
        help="envs whose models compile as the UI starts, comma-separated (the others on first use)",
    )
    parser.add_argument("--info-json", type=Path, default=None, help="write the URL and port here once serving")


def refuse(why: str) -> NoReturn:
    """A usage error, as argparse reports its own: one line on stderr, exit status 2."""
    print(f"collie label-ui: error: {why}", file=sys.stderr)
    raise SystemExit(2)


def warn(why: str) -> None:
    print(f"collie label-ui: warning: {why}", file=sys.stderr, flush=True)


def probe(api: str, token: str | None, run_id: int | None) -> list[str]:
    """What is wrong with the service at `api` as this UI will use it, one line each: nothing
    answers, it is not a collie service, --token is refused, --run names no run. Warnings, not
    refusals: the service may come up (or the run appear) after the UI starts, as under compose."""
    from collie.client import ApiError, BadAnswer, CollieClient, Unauthorized, Unreachable, Unsendable, no_answer

    where = f"the labeling service at {api}"
    # /api/health needs no token; the client sends one always, and an empty one is no legal header
    with CollieClient(api, token or "none", timeout_s=PROBE_S) as client:
        try:
            client.health()
        except Unreachable as exc:
            return [f"{where} {no_answer(exc)}; the UI starts, and labels once it does"]
        except Unsendable as exc:
            return [f"cannot ask {where}: {exc}"]
        except BadAnswer as exc:  # e.g. a proxy's page, or another web service's
            return [f"{api} is not a collie service ({exc}); check --api"]
        except ApiError as exc:  # a 503 is collie's own: its database, said on the page
            if exc.status != 503:
                path = f"{urlsplit(api).path.rstrip('/')}/api/health"
                return [f"{api} is not a collie service ({exc.status} on {path}); check --api"]
        if not token:
            return []
        try:
            client.me()
            if run_id is not None:
                client.run(run_id)
        except Unauthorized as exc:
            return [f"{where} refused --token ({exc}): the labeler URL will not sign in"]
        except BadAnswer as exc:  # e.g. a newer collie's run: the page says what it cannot show
            return [f"{where} sent an answer this collie cannot read (a newer collie's?): {exc}"]
        except ApiError as exc:
            return [f"{where} has no run {run_id}" if exc.status == 404 else f"{where} answered {exc}"]
        except Unreachable as exc:
            return [f"{where} {no_answer(exc)}"]
    return []


def probed(api: str, token: str | None, run_id: int | None) -> list[str]:
    """`probe`, in the start's background thread: an error it did not foresee is one more warning,
    not a thread's traceback (the UI starts either way)."""
    try:
        return probe(api, token, run_id)
    except Exception as exc:
        return [f"could not check the labeling service at {api}: {exc!r}"]


def info_folder(path: Path) -> None:
    """--info-json's folder, made as `collie up` and `collie serve --tokens-json` make theirs; a
    folder given as the file, or one that cannot be made, is refused before the UI starts."""
    if path.is_dir():
        refuse(f"--info-json {path} is a folder; give a file path")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        refuse(f"cannot create the folder of --info-json {path.parent}: {exc.strerror or exc}")


def run(args: argparse.Namespace) -> int:
    config = UiConfig(api=args.api, run_id=args.run, lease_s=args.lease_s, fps=args.fps)
    mark("imports")  # viser, mujoco, the UI's modules
    warm = tuple(e for e in args.warm.split(",") if e)
    unknown = [e for e in warm if e not in MODEL_NAMES]
    if unknown:
        refuse(f"--warm: unknown env {unknown[0]!r}; valid: {', '.join(MODEL_NAMES)}")
    try:
        token = resolve_token(args, "labeler", from_env=False)
    except ValueError as exc:
        refuse(str(exc))
    why = not_listenable(args.host)  # viser would retry it forever, silent
    if why is not None:
        refuse(f"--host {args.host} is not an address of this machine ({why})")
    if args.info_json is not None:
        info_folder(args.info_json)
    # Looked at while the UI starts (in a thread: a silent host costs its timeout there, not here).
    warnings: list[str] = []
    looking = threading.Thread(target=lambda: warnings.extend(probed(args.api, token, args.run)), daemon=True)
    looking.start()
    app = LabelingApp(config, host=args.host, port=args.port, warm=warm)
    mark("serving")  # viser's server is up; models compile in the background
    if args.port and app.port != args.port:  # viser moves on from a port in use: say so, not only the URL
        print(f"collie labeling UI: port {args.port} is in use; serving on port {app.port} instead", flush=True)
    looking.join(PROBE_S * 3)  # health, me, the run: each within PROBE_S
    for said in warnings:
        warn(said)
    print(f"collie labeling UI: {app.url}  (service {args.api})", flush=True)
    if token:  # asked for by the person who started it: their terminal, not a log
        print(f"labeler URL: {app.labeler_url(token)}", flush=True)
    if args.info_json is not None:  # how `collie up` learns the port when it asked for any free one
        try:
            info = json.dumps({"url": app.url, "port": app.port}).encode()
            write_whole(args.info_json, lambda f: f.write(info))
        except OSError as exc:
            app.stop()
            said = f"cannot write --info-json {args.info_json}: {exc.strerror or exc}"
            refuse(said)
    stopping: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):  # either way, tabs hand their claims back first
        # No lock in the handler: it runs in the main thread wherever that is, and was stop.set() on
        # an Event whose lock the main thread held inside stop.wait(); the UI then hung for good.
        signal.signal(sig, lambda signum, _frame: stopping.append(signum))
    # Wait in short steps: a signal the kernel hands to one of viser's threads runs our handler only
    # when the main thread next runs Python.
    while not stopping:
        time.sleep(0.2)
    app.stop()
    return 0


def main(argv: list[str] | None = None) -> int:
    """`python -m labeling_ui.cli` (the same as `collie label-ui`)."""
    parser = argparse.ArgumentParser(prog="collie label-ui", description=__doc__)
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
