"""`collie report / archive / rescore / sweep` with an --out that cannot be written: a read-only or
full file system, or a path through a file, is one line naming the path (exit 2), not a traceback."""

import contextlib
import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from small_disk import fill, small_disk

from collie.cli import main

from .test_report import fake_run
from .test_rescore import finished_run


@contextlib.contextmanager
def small_file_system(where: Path, how: str) -> Iterator[Path]:
    """A 1 MB tmpfs at `where`, read-only or full."""
    with small_disk(where) as disk:
        if how == "read-only":
            subprocess.run(["mount", "-o", "remount,ro", str(disk)], check=True)
        else:
            fill(disk)
        yield disk


def commands(tmp_path: Path, out: Path) -> list[list[str]]:
    """Each command with `out` (or a folder in it) as its --out, on tiny finished runs."""
    fake_run(tmp_path / "runs", "point", "north", "metra", 0, 3.0)
    ant, _ = finished_run(tmp_path / "ants")
    return [
        ["report", str(tmp_path / "runs"), "--out", str(out / "report")],
        ["archive", str(tmp_path / "runs"), "--out", str(out / "archive")],
        ["rescore", "--task", "range", str(ant), "--out", str(out / "rescored")],
        # refused before any run trains: nothing is started, so this takes no time
        ["sweep", "--tasks", "north", "--methods", "metra", "--seeds", "1", "--out", str(out / "sweep")],
    ]


@pytest.mark.parametrize(("how", "said"), [("read-only", "Read-only file system"), ("full", "No space left on device")])
def test_an_out_on_a_read_only_or_full_file_system_is_one_line_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], how: str, said: str
) -> None:
    with small_file_system(tmp_path / "fs", how) as fs:
        for argv in commands(tmp_path, fs):
            assert main(argv) == 2, argv
            err = capsys.readouterr().err
            assert "FAILED" not in err and "Traceback" not in err, err  # sweep: before any run, not run by run
            line = err.strip().splitlines()[-1]
            assert line.startswith(f"collie {argv[0]}: error: cannot write {argv[-1]}"), err
            assert line.endswith(f": {said}"), err


def test_an_out_through_a_file_is_one_line_naming_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "a-file").write_text("kept")
    for argv in commands(tmp_path, tmp_path / "a-file"):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith(f"collie {argv[0]}: error: cannot use {argv[-1]}"), err  # archive: its run's folder
        assert err.endswith(": Not a directory\n") and len(err.splitlines()) == 1, err
    assert (tmp_path / "a-file").read_text() == "kept"


def test_an_out_where_the_file_system_makes_no_folder_is_one_line_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """/proc makes no folder, for root neither (mkdir: "No such file or directory"). Was a traceback."""
    for argv in commands(tmp_path, Path("/proc")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith(f"collie {argv[0]}: error: cannot use {argv[-1]}"), err
        assert err.endswith(": No such file or directory\n") and len(err.splitlines()) == 1, err


def test_an_out_through_a_link_to_nowhere_is_one_line_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A folder linked to a disk not mounted now. Was: FileExistsError's traceback ("File exists")."""
    link = tmp_path / "on-the-usb-disk"
    link.symlink_to(tmp_path / "mnt" / "usb")
    for argv in commands(tmp_path, link):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        said = f"collie {argv[0]}: error: cannot use {link}: a link to {tmp_path / 'mnt' / 'usb'}, which does not exist"
        assert err == said + "\n", err
    assert not (tmp_path / "mnt").exists()


def test_a_rescore_that_fills_the_disk_midway_leaves_no_half_written_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Was: the output folder left holding eval_latest.npz and part of checkpoint.pt, no summary.json."""
    ant, _ = finished_run(tmp_path / "ants")
    (ant / "checkpoint.pt").write_bytes(b"\0" * 400_000)
    with small_file_system(tmp_path / "fs", "full") as fs:
        filler = fs / "filler"
        os.truncate(filler, filler.stat().st_size - 128 * 1024)  # room for the final skills, not the checkpoint
        out = fs / "rescored"
        argv = ["rescore", "--task", "range", str(ant), "--out", str(out)]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"collie rescore: error: cannot write {out}"), err
        assert err.endswith(": No space left on device\n") and len(err.splitlines()) == 1, err
        assert sorted(p.name for p in fs.iterdir()) == ["filler"]  # neither the folder nor a partial one beside it
        filler.unlink()
        assert main(argv) == 0  # nothing left in the way of the rerun
        assert sorted(p.name for p in fs.iterdir()) == ["rescored"]
        assert (out / "checkpoint.pt").stat().st_size == 400_000 and (out / "summary.json").exists()


def archived_files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_an_archive_that_fills_the_disk_midway_leaves_no_run_folder_or_its_older_copy_as_it_was(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Was: a first archive left the run's folder without summary.json; a refresh left its older copy
    holding some of the new files (downstream.json here) beside the old ones."""
    run = fake_run(tmp_path / "runs", "point", "north", "metra", 0, 3.0)
    (run / "metrics.jsonl").write_text('{"epoch": 1}\n' * 20)
    big_metrics = '{"epoch": 1, "loss": 0.123456789}\n' * 12_000  # ≈ 400 kB
    with small_file_system(tmp_path / "fs", "full") as fs:
        filler, kept = fs / "filler", fs / "archive"
        os.truncate(filler, filler.stat().st_size - 128 * 1024)  # room for the small files, not the big log
        (run / "metrics.jsonl").write_text(big_metrics)
        argv = ["archive", str(run), "--out", str(kept)]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err == f"collie archive: error: cannot write {kept}: No space left on device\n", err
        assert sorted(p.name for p in fs.iterdir()) == ["filler"]  # no run folder, no archive, no partial one

        (run / "metrics.jsonl").write_text('{"epoch": 1}\n' * 20)
        assert main(argv) == 0  # the small log fits
        out = kept / run.name
        old = archived_files(out)
        (run / "downstream.json").write_text(json.dumps({"zero_shot": {"mean": 1.0, "best": 2.0}}))
        (run / "metrics.jsonl").write_text(big_metrics)  # the same run, refreshed with its full log
        assert main(argv) == 2
        assert capsys.readouterr().err.endswith(": No space left on device\n")
        assert archived_files(out) == old and [p.name for p in kept.iterdir()] == [run.name]  # nothing hidden beside
        assert main(["report", str(kept), "--no-figures", "--out", str(tmp_path / "report")]) == 0
        assert f"{out}," in (tmp_path / "report" / "runs.csv").read_text()  # the older copy, read as a run

        filler.unlink()
        assert main(argv) == 0  # nothing left in the way of the rerun
        assert archived_files(out) == archived_files(run) and [p.name for p in kept.iterdir()] == [run.name]
