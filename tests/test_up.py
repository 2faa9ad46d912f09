"""`collie up` end to end with real processes: service (uvicorn + SQLite file), trainer and the
oracle teacher over HTTP. Every feedback session completes, and the labels in the database are
exactly those the trainer applied (no label lost, none counted twice)."""

import json
import os
import socket
import subprocess
import sys

import pytest
import torch

from collie.startup import read_marks

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)


@pytest.mark.parametrize("env", ["point", "quadruped"])  # quadruped: pixel segments travel packed
def test_collie_up_with_oracle_teacher_completes_and_agrees_with_the_database(tmp_path, env):
    info = tmp_path / "info.json"
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    taken = busy.getsockname()[1]
    cmd = [
        sys.executable,
        "-m",
        "collie.cli",
        "up",
        "--env",
        env,
        "--task",
        "north",
        "--teacher",
        "oracle",
        "--preset",
        "smoke",
        "--port",
        "0",
        "--ui-port",
        str(taken) if env == "point" else "0",  # point: a port in use, said and moved from
        "--out",
        str(tmp_path),
        "--info-json",
        str(info),
        "--exit-when-done",
    ]
    # point: the lab's database named by COLLIE_DATABASE_URL (here a SQLite URL), not OUT/collie.db
    db = tmp_path / ("lab.db" if env == "point" else "collie.db")
    lab_tokens = {f"COLLIE_{r}_TOKEN": f"lab-{r.lower()}-" + "t" * 20 for r in ("OPERATOR", "TRAINER", "LABELER")}
    lab = {**os.environ, "COLLIE_DATABASE_URL": f"sqlite:///{db}", **lab_tokens} if env == "point" else None
    with busy:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=lab)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    moved = f"collie up: --ui-port {taken} is in use; the labeling UI serves on port "
    assert (moved in proc.stdout) == (env == "point"), proc.stdout[-2000:]
    assert db.exists() and (env != "point" or not (tmp_path / "collie.db").exists())
    meta = json.loads(info.read_text())
    assert set(meta) >= {"api", "labeling_ui", "dashboard", "run_id", "tokens"}
    assert set(meta["tokens"]) == {"operator", "labeler", "trainer"}
    assert meta["labeling_ui"].startswith("http://") and "token=" in meta["labeling_ui"]
    assert meta["dashboard"].startswith(meta["api"]) and "token=" in meta["dashboard"] and "&ui=" in meta["dashboard"]

    summary = json.loads((tmp_path / "trainer" / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["epoch"] == summary["config"]["epochs"]
    # every part marked its start (bench-first-segment's split), the trainer up to its first session only
    marks = read_marks(tmp_path / "logs" / "startup.jsonl")
    assert {m.part for m in marks} == {"up", "service", "trainer", "labeling_ui", "teacher"}
    trainer = [m.what for m in marks if m.part == "trainer"]
    assert trainer[:2] == ["python start", "imports"] and trainer[-2:] == ["query selection", "segments posted"]
    assert trainer.count("segments posted") == 1
    n_total = summary["config"]["total_queries"]
    assert summary["n_labels"] == n_total  # every feedback session was answered

    export = subprocess.run(
        [
            sys.executable,
            "-m",
            "collie.cli",
            "export",
            "--db",
            str(db),
            "--run",
            str(meta["run_id"]),
            "--format",
            "json",
            "--effective",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert export.returncode == 0, export.stderr
    in_db = {row["query_id"]: row["label"] for row in json.loads(export.stdout)}
    # the teacher labels as its own principal: a person on the label link (`labeler`) is another one
    assert {row["labeler"] for row in json.loads(export.stdout)} == {"oracle-teacher"}
    teacher = json.loads((tmp_path / "teacher_token.json").read_text())
    assert (
        teacher["token"] not in meta["tokens"].values()
        and (tmp_path / "teacher_token.json").stat().st_mode & 0o077 == 0
    )
    ckpt = torch.load(tmp_path / "trainer" / "checkpoint.pt", weights_only=False)
    applied = {qid: seg["label"] for qid, seg in ckpt["labelled"].items()}
    assert applied == in_db and len(applied) == n_total
