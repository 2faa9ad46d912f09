"""The stack's startup timeline (collie/startup.py) and the split bench-first-segment prints from it."""

import sys
from pathlib import Path

import pytest

from collie import startup
from collie.schemas import StartupMark
from collie.startup import LOG_ENV, PART_ENV, mark, read_marks

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_first_segment import split  # the bench folder is not a package


@pytest.fixture(autouse=True)
def fresh(monkeypatch):
    monkeypatch.setattr(startup, "_done", False)


def test_marks_go_to_the_named_file_with_their_part_until_done(tmp_path, monkeypatch):
    log = tmp_path / "startup.jsonl"
    monkeypatch.delenv(LOG_ENV, raising=False)
    mark("nowhere")  # outside a timed start: nothing written
    assert not log.exists()
    monkeypatch.setenv(LOG_ENV, str(log))
    monkeypatch.setenv(PART_ENV, "trainer")
    mark("imports")
    mark("collect", epoch=3)
    startup.done()
    mark("after the first segment")
    with open(log, "a") as f:
        f.write('{"t": 1.0, "par')  # a process killed while writing
    marks = read_marks(log)
    assert [(m.part, m.what, m.epoch) for m in marks] == [("trainer", "imports", None), ("trainer", "collect", 3)]
    assert marks[0].t <= marks[1].t and 0 < marks[0].cpu <= marks[1].cpu


def test_the_split_charges_each_piece_the_time_since_its_process_s_previous_mark():
    def m(t: float, cpu: float, part: str, pid: int, what: str, epoch: int | None = None) -> StartupMark:
        return StartupMark(t=100.0 + t, cpu=cpu, part=part, pid=pid, what=what, epoch=epoch)

    marks = [
        m(0.5, 0.3, "up", 1, "python start"),
        m(1.0, 0.3, "up", 1, "spawned trainer"),
        m(2.0, 0.2, "trainer", 2, "python start"),  # from its spawn at 1.0
        m(5.0, 2.9, "trainer", 2, "imports"),
        m(6.0, 3.4, "trainer", 2, "collect", 1),
        m(8.0, 5.4, "trainer", 2, "update", 1),
        m(9.0, 5.9, "trainer", 2, "collect", 2),
        m(9.5, 6.4, "trainer", 2, "query selection", 2),
        m(9.7, 6.5, "trainer", 2, "segments posted", 2),
    ]
    r = split(marks, t0=100.0)
    assert r["parts"]["up"] == {"python start": 0.5}
    assert r["parts"]["trainer"] == {
        "python start": 1.0,
        "imports": 3.0,
        "epochs: collect": 2.0,
        "epochs: update": 2.0,
        "query selection": 0.5,
        "segments posted": 0.2,
    }
    assert r["parts_cpu"]["trainer"]["imports"] == 2.7 and r["parts_cpu"]["trainer"]["epochs: collect"] == 1.0
    assert r["trainer"] == {"collect": 2.0, "update": 2.0, "evaluate": 0.0, "checkpoint": 0.0}
    assert (
        r["first_feedback_epoch"] == 2 and r["last_epoch"] == 2 and r["trainer_spawn_s"] == 1.0 and r["posted_s"] == 9.7
    )


def test_a_mark_that_cannot_be_written_does_not_stop_the_process(tmp_path, monkeypatch):
    """A timeline is a measurement: a full or read-only disk under it ends no part of the stack."""
    monkeypatch.setenv(LOG_ENV, str(tmp_path))  # a folder: open() fails as on an unwritable file system
    mark("imports")
    assert list(tmp_path.iterdir()) == []


def test_a_mark_refused_by_a_closing_reader_is_written_again(tmp_path, monkeypatch):
    """A FIFO's reader that closed just as the mark opened it (tests/paced_marks.py): the mark's
    write meets EPIPE, and a second open waits for the next reader."""
    log = tmp_path / "startup.jsonl"
    monkeypatch.setenv(LOG_ENV, str(log))
    opened: list[str] = []

    class ClosedReader:  # what open() gives when the only reader closes between the open and the write
        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, _text):
            raise BrokenPipeError(32, "Broken pipe")

    def open_once_refused(path, mode="r"):
        opened.append(path)
        return ClosedReader() if len(opened) == 1 else open(path, mode)

    monkeypatch.setattr(startup, "open", open_once_refused, raising=False)
    mark("collect", epoch=5)
    assert len(opened) == 2 and [(m.what, m.epoch) for m in read_marks(log)] == [("collect", 5)]
