"""A run folder's JSON files are written whole: a failure while writing leaves the old file as it
was (resume and report read it), and what is read back is what was written."""

from __future__ import annotations

import json
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pytest

from collie.whole_files import write_whole
from trainer.run_files import (
    RunFolderError,
    copy_whole,
    folder_written_whole,
    read_arrays,
    read_json_object,
    recover_beside,
    write_json,
)


def test_a_write_cut_short_leaves_the_old_file_whole(tmp_path: Path) -> None:
    """A full disk mid-write (a file size limit stands in: the kernel refuses the write past 16 bytes)."""
    import resource
    import signal

    path = tmp_path / "summary.json"
    write_json(path, {"status": "finished", "epochs_done": 3})
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG, not death
    resource.setrlimit(resource.RLIMIT_FSIZE, (16, hard))
    try:
        with pytest.raises(OSError, match="File too large"):
            write_json(path, {"status": "finished", "epochs_done": 4})
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)
    assert read_json_object(path) == {"status": "finished", "epochs_done": 3}
    assert not (tmp_path / "summary.json.partial").exists()


def test_a_file_cut_short_is_named(tmp_path: Path) -> None:
    path = tmp_path / "config.json"
    path.write_text(json.dumps({"epochs": 3})[:5])
    with pytest.raises(RunFolderError, match=r"config\.json: not JSON"):
        read_json_object(path)


def test_a_binary_write_cut_short_leaves_the_old_file_whole(tmp_path: Path) -> None:
    path = tmp_path / "eval_latest.npz"
    write_whole(path, lambda f: np.savez_compressed(f, epoch=3))

    def disk_full(f: BinaryIO) -> None:
        f.write(b"PK\x03\x04 half an archive")
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        write_whole(path, disk_full)
    assert int(read_arrays(path, ("epoch",))["epoch"]) == 3
    assert not path.with_name(path.name + ".partial").exists()  # nothing half-written left beside it
    copy_whole(path, tmp_path / "archived.npz")
    assert int(read_arrays(tmp_path / "archived.npz", ("epoch",))["epoch"]) == 3


@pytest.mark.parametrize("how", ["json", "whole", "secret"])
def test_a_path_that_is_no_regular_file_is_written_in_place_not_renamed_over(tmp_path: Path, how: str) -> None:
    """`--info-json /dev/null` (as root) once made /dev/null a plain file for the whole machine: a
    rename over it. A FIFO stands in for /dev/null here: a reader gets the text, and it stays a FIFO."""
    import os
    import stat
    import threading

    from collie.tokens import write_secret

    fifo = tmp_path / "sink"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    if how == "json":
        write_json(fifo, {"a": 1})
    elif how == "whole":
        write_whole(fifo, lambda f: f.write(b'{"a": 1}'))
    else:
        write_secret(fifo, '{"a": 1}')
    reader.join(10)
    assert stat.S_ISFIFO(fifo.stat().st_mode) and json.loads(got[0]) == {"a": 1}
    assert not (tmp_path / "sink.partial").exists()


def test_the_machines_own_files_are_never_renamed_over() -> None:
    """/dev/stdout is a link: replaced by a rename, it would be a plain file for every program."""
    from collie.whole_files import not_replaceable

    assert not_replaceable(Path("/dev/stdout")) and not_replaceable(Path("/dev/null"))
    assert not not_replaceable(Path("/tmp/collie-info.json"))  # a link planted there is replaced, not followed


def test_a_folder_written_whole_is_there_whole_or_not_at_all(tmp_path: Path) -> None:
    """A failure in the block leaves neither the folder nor the one it was written in; its error names
    the file where it was to be."""
    out = tmp_path / "runs" / "rescored"
    with pytest.raises(FileNotFoundError) as caught, folder_written_whole(out) as new:
        write_json(new / "config.json", {})
        (new / "no" / "summary.json").write_text("{}")
    assert caught.value.filename == str(out / "no" / "summary.json")
    assert list(tmp_path.iterdir()) == []  # nor the folder it made to hold it
    out.mkdir(parents=True)  # an empty folder given: kept on failure, replaced on success
    with pytest.raises(KeyboardInterrupt), folder_written_whole(out) as new:
        write_json(new / "config.json", {})
        raise KeyboardInterrupt
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["rescored"] and list(out.iterdir()) == []
    mode = out.stat().st_mode
    with folder_written_whole(out) as new:
        write_json(new / "summary.json", {"status": "finished"})
    assert read_json_object(out / "summary.json") == {"status": "finished"}
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["rescored"] and out.stat().st_mode == mode


def test_a_folder_replaced_whole_is_the_old_one_until_the_new_one_is_whole(tmp_path: Path) -> None:
    """`collie archive` refreshing a run: a failure leaves the older copy exactly as it was; success
    leaves the new one alone (no file of the old one), and nothing hidden beside it."""
    out = tmp_path / "run"
    out.mkdir()
    write_json(out / "summary.json", {"copy": "old"})
    (out / "downstream.json").write_text("{}")
    older = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(KeyboardInterrupt), folder_written_whole(out, replace=True) as new:
        write_json(new / "summary.json", {"copy": "new"})
        raise KeyboardInterrupt
    assert {p.name: p.read_bytes() for p in out.iterdir()} == older and list(tmp_path.iterdir()) == [out]
    with folder_written_whole(out, replace=True) as new:
        write_json(new / "summary.json", {"copy": "new"})
    assert [p.name for p in out.iterdir()] == ["summary.json"] and read_json_object(out / "summary.json")[
        "copy"
    ] == "new"
    assert list(tmp_path.iterdir()) == [out]
    of_another = tmp_path / ".run.x.0123abcd.partial"  # run.x's folder being written, not run's
    of_another.mkdir()
    recover_beside(out)
    assert of_another.is_dir()
