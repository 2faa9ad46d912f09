"""`collie label-ui --api URL`: serve the labeling UI for the service at URL."""

from __future__ import annotations

import argparse
import json
import os
import signal
import threading
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco loads: offscreen, no X display (as collie up sets it)

from collie.argtypes import http_url, port
from collie.mjmodels import MODEL_NAMES
from collie.startup import mark
from collie.tokens import resolve_token
from labeling_ui.app import LabelingApp
from labeling_ui.session import UiConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--api", required=True, type=http_url, help="the labeling service, e.g. http://127.0.0.1:8000")
    parser.add_argument("--port", type=port, default=8090, help="port to serve on (0: any free port)")
    parser.add_argument("--host", default="127.0.0.1", help="interface to bind (0.0.0.0 for every one)")
    parser.add_argument("--run", type=int, default=None, help="label only this run (default: newest with work)")
    parser.add_argument("--token", default=None, help="print a labeler URL that signs in with this token")
    parser.add_argument("--token-file", type=Path, default=None, help="the same, with the token read from this file")
    parser.add_argument("--lease-s", type=float, default=60.0, help="claim length, renewed while a tab is open")
    parser.add_argument("--fps", type=float, default=20.0, help="segment frames per second at 1x")
    parser.add_argument(
        "--warm",
        default=",".join(MODEL_NAMES),
        help="envs whose models compile as the UI starts, comma-separated (the others on first use)",
    )
    parser.add_argument("--info-json", type=Path, default=None, help="write the URL and port here once serving")


def run(args: argparse.Namespace) -> int:
    config = UiConfig(api=args.api, run_id=args.run, lease_s=args.lease_s, fps=args.fps)
    mark("imports")  # viser, mujoco, the UI's modules
    warm = tuple(e for e in args.warm.split(",") if e)
    unknown = [e for e in warm if e not in MODEL_NAMES]
    if unknown:
        raise SystemExit(f"collie label-ui: error: --warm: unknown env {unknown[0]!r}; valid: {', '.join(MODEL_NAMES)}")
    try:
        token = resolve_token(args, "labeler", from_env=False)
    except ValueError as exc:
        raise SystemExit(f"collie label-ui: error: {exc}") from None
    app = LabelingApp(config, host=args.host, port=args.port, warm=warm)
    mark("serving")  # viser's server is up; models compile in the background
    if args.port and app.port != args.port:  # viser moves on from a port in use: say so, not only the URL
        print(f"collie labeling UI: port {args.port} is in use; serving on port {app.port} instead", flush=True)
    print(f"collie labeling UI: {app.url}  (service {args.api})", flush=True)
    if token:  # asked for by the person who started it: their terminal, not a log
        print(f"labeler URL: {app.labeler_url(token)}", flush=True)
    if args.info_json is not None:  # how `collie up` learns the port when it asked for any free one
        tmp = args.info_json.with_suffix(".tmp")
        tmp.write_text(json.dumps({"url": app.url, "port": app.port}))
        tmp.replace(args.info_json)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):  # either way, tabs hand their claims back first
        signal.signal(sig, lambda *_: stop.set())
    # Wait in short steps: a signal the kernel hands to one of viser's threads runs our handler only
    # when the main thread next runs Python, which a plain wait() never does.
    while not stop.wait(0.2):
        pass
    app.stop()
    return 0


def main(argv: list[str] | None = None) -> int:
    """`python -m labeling_ui.cli` (the same as `collie label-ui`)."""
    parser = argparse.ArgumentParser(prog="collie label-ui", description=__doc__)
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
