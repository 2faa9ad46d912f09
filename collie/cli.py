"""collie: human-in-the-loop guided skill discovery. Start with `collie up` (the whole loop on this
machine); `collie <command> --help` says more about each command."""

# Each subcommand lives in its own module, which exposes `add_arguments(parser)` and
# `run(args) -> int`; imports are lazy so `collie serve` never loads torch.

from __future__ import annotations

import argparse
import errno
import gc
import importlib
import sys

from collie.early_term import INTERRUPTED

# name → (module, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "train": ("trainer.cli", "run Algorithm 1 (METRA / COLLIE / Oracle) on one env and task"),
    "serve": ("backend.cli", "run the labeling service (FastAPI over a SQLite file or PostgreSQL)"),
    "teacher": ("teacher.cli", "label a run's queries through the API with the scripted oracle"),
    "label-ui": ("labeling_ui.cli", "serve the labeling UI (viser) for a labeling service"),
    "up": (
        "collie.up",
        "start service, trainer, labeling UI (and the oracle teacher) together (SQLite, or the lab's database)",
    ),
    "export": ("backend.export", "print a run's label events (or effective labels) as JSON or CSV"),
    "sweep": ("trainer.sweep", "run methods × tasks × seeds of `collie train` (resumable; local pool or Ray)"),
    "report": ("trainer.report", "turn run folders into the paper's tables (markdown, CSV) and skill figures"),
    "rescore": ("trainer.rescore", "judge finished METRA / LSD / DIAYN runs by another task's rule, without training"),
    "archive": ("trainer.archive", "keep finished runs' results, without checkpoint or replay, for `collie report`"),
}


def joined_values(argv: list[str], options: tuple[str, ...]) -> list[str]:
    """`--train-args "--compile"` as `--train-args=--compile`: argparse takes a separate value that
    starts with '-' for an option and refuses it, though such an option's value is a string of flags."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in options and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def refusal_line(exc: PermissionError) -> str:
    """What was refused, naming the paths it has (a port or a process has none)."""
    where = " → ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
    said = (exc.strerror or str(exc)).lower()
    return f"{said}: {where}" if where else said


def unwritable_line(exc: OSError) -> str | None:
    """ "cannot write PATH: Read-only file system" for a file system's refusal (a full disk's write
    names no path: "cannot write: No space left on device"); for a file where a folder must go (a
    path through a file, --out a-file/x), "cannot use PATH: Not a directory", and "No such file or
    directory" for a folder a file system will not make (/proc/x: `make_folder`); for a link to nowhere on
    the way, "cannot use PATH: a link to TARGET, which does not exist"; None for any other
    OSError, which is a bug to show whole."""
    said = exc.strerror or str(exc)
    where = exc.filename2 if exc.filename2 is not None else exc.filename  # a copy's or rename's: its target
    from collie.whole_files import UNWRITABLE, FolderRefused, broken_link

    if (dangling := broken_link(exc)) is not None:
        return f"cannot use {dangling}"
    if exc.errno in UNWRITABLE:
        return f"cannot write {where}: {said}" if where is not None else f"cannot write: {said}"
    # a file where a folder must go; a folder a file system will not make (/proc/x)
    if (exc.errno == errno.ENOTDIR or isinstance(exc, FolderRefused)) and exc.filename is not None:
        return f"cannot use {exc.filename}: {said}"
    return None


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("collie")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return "(not installed)"


def caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a Ctrl-C caused `exc`: MuJoCo's extension reports one that lands in its import as
    `ImportError: initialization failed`, the KeyboardInterrupt as its cause."""
    seen: BaseException | None = exc
    for _ in range(8):  # a chain, not a cycle
        if seen is None:
            return False
        if isinstance(seen, KeyboardInterrupt):
            return True
        seen = seen.__cause__ or seen.__context__
    return False


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    wanted = argv[0] if argv and not argv[0].startswith("-") else None
    try:
        return run_command(argv, wanted)
    except (KeyboardInterrupt, ImportError) as exc:  # Ctrl-C in the imports too (torch's take seconds): a line
        if not caused_by_interrupt(exc):
            raise
        print(f"collie{f' {wanted}' if wanted in SUBCOMMANDS else ''}: interrupted", file=sys.stderr)
        return INTERRUPTED


def run_command(argv: list[str], wanted: str | None) -> int:
    from collie.startup import mark

    if wanted == "train":  # a SIGTERM in its seconds of imports ends it with a word, as Ctrl-C does
        from collie import early_term

        early_term.note_sigterm()
    mark("python start")
    parser = argparse.ArgumentParser(prog="collie", description=__doc__)
    parser.add_argument("--version", action="version", version=f"collie {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    chosen = parser  # the command's own parser once known: its errors read "collie train: error: …"
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        # train: no abbreviated flags, so what `up --train-args` and `sweep -- …` may not set is matched exactly
        p = sub.add_parser(name, help=help_text, description=help_text, allow_abbrev=name != "train")
        if name == wanted:  # only import the module we run
            try:
                module = importlib.import_module(module_name)
            except ModuleNotFoundError as exc:
                parser.error(f"'{name}' is not available: {exc}")
            module.add_arguments(p)
            p.set_defaults(_module=module)
            chosen = p
            argv = joined_values(argv, getattr(module, "DASHED_VALUE_OPTIONS", ()))
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # as parse_args says it, with the command's hint where it has one (sweep: train flags after --)
        hint = getattr(getattr(args, "_module", None), "UNRECOGNIZED_HINT", "")  # none before the command's name
        chosen.error(f"unrecognized arguments: {' '.join(unknown)}{hint}")
    try:
        return int(args._module.run(args) or 0)
    except PermissionError as exc:  # a file, folder or port this user may not use: which, not a traceback
        print(f"collie {args.command}: error: {refusal_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:  # a read-only or full file system under --out (PermissionError is above)
        line = unwritable_line(exc)
        if line is None:
            raise
        print(f"collie {args.command}: error: {line}", file=sys.stderr)
        return 2


def entry() -> None:
    """The `collie` command (and `python -m collie.cli`): `main`, then an exit that leaves the objects it
    is about to free to the OS. Python's shutdown collection walks every object still alive, which in a
    process that imported torch costs about a second of CPU at the end of each `collie train`.
    Frozen objects are never collected, so a buffered file caught in a reference cycle would not be
    flushed at exit: commands close (or flush) what they write before `main` returns."""
    try:
        code = main()
    finally:  # also after argparse's exits and a traceback
        gc.freeze()  # moves every tracked object out of the collector's reach; little is allocated after it
    raise SystemExit(code)


if __name__ == "__main__":
    entry()
