"""The command line: `collie serve` (port 0, tokens file), `collie export`, and the schema the
migrations build matching the models."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from contextlib import closing, contextmanager
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from small_disk import fill, small_disk

from backend.db import Database
from backend.migrate import alembic_config, head, upgrade
from backend.models import Base
from collie.client import CollieClient

from .conftest import make_run_spec, make_session


def collie(*args: str, **kwargs: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "collie.cli", *args], capture_output=True, text=True, timeout=60, **kwargs
    )  # type: ignore[call-overload]


def test_serve_then_export(tmp_path: Path) -> None:
    db, tokens_file = tmp_path / "svc.db", tmp_path / "tokens.json"
    env = {**os.environ, "COLLIE_LABELER_TOKEN": "labeler-from-env-0123"}
    command = [
        sys.executable,
        "-m",
        "collie.cli",
        "serve",
        "--port",
        "0",
        "--db",
        str(db),
        "--tokens-json",
        str(tokens_file),
    ]
    env = {**env, "PYTHONFAULTHANDLER": "1"}  # for stop(): a hung server's stacks on SIGABRT
    server = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        banner = server.stdout.readline()  # type: ignore[union-attr]
        assert banner.startswith("collie service listening on http://127.0.0.1:")
        info = json.loads(tokens_file.read_text())
        assert info["api"] in banner and info["tokens"]["labeler"] == "labeler-from-env-0123"
        assert oct(tokens_file.stat().st_mode & 0o777) == "0o600"
        rest = [server.stdout.readline() for _ in range(3)]  # type: ignore[union-attr]
        assert "labeler token: (from environment)" in "".join(rest)  # secrets given by env are not echoed
        assert info["tokens"]["trainer"] not in "".join(rest)  # generated ones are in the 0600 file, not the log
        assert f"trainer token: (in {tokens_file})" in "".join(rest)
        trainer = CollieClient(info["api"], info["tokens"]["trainer"])
        labeler = CollieClient(info["api"], info["tokens"]["labeler"])
        run = trainer.create_run(make_run_spec())
        trainer.post_session(run.id, make_session(0, 2))
        for value in (2, 0):
            labeler.submit(run.id, labeler.claim(run.id).query.query_id, value)
        labeler.undo(run.id, "0-1")
        out = collie("export", "--db", str(db), "--run", str(run.id), "--format", "json")
        assert out.returncode == 0, out.stderr
        assert [(e["query_id"], e["kind"]) for e in json.loads(out.stdout)] == [
            ("0-0", "label"),
            ("0-1", "label"),
            ("0-1", "undo"),
        ]
        out = collie("export", "--db", str(db), "--run", str(run.id), "--format", "csv", "--effective")
        assert [(r["query_id"], r["label"]) for r in csv.DictReader(io.StringIO(out.stdout))] == [("0-0", "2")]
        assert out.stdout == trainer.export(run.id, "csv", effective=True).rstrip("\n") + "\n"
        trainer.close()
        labeler.close()
    finally:
        stop(server)
    missing = collie("export", "--db", str(tmp_path / "nope.db"), "--run", "1")
    assert missing.returncode == 2 and "nope.db does not exist" in missing.stderr
    assert not (tmp_path / "nope.db").exists()
    unknown = collie("export", "--db", str(db), "--run", "99")
    assert unknown.returncode == 2 and "no run 99" in unknown.stderr


def test_export_reads_older_databases_and_refuses_what_is_none(tmp_path: Path) -> None:
    """A database from before the newest migration is brought up to date (as `collie serve` would)
    and exported; a file that is no database, or none at all, is a one-line error."""
    out = collie("export", "--db", str(migrated(tmp_path / "old.db", "0008")), "--run", "1", "--effective")
    assert (
        out.returncode == 2 and "no run 1" in out.stderr and "upgraded" in out.stderr and "Traceback" not in out.stderr
    )
    junk = tmp_path / "checkpoint.pt"
    junk.write_bytes(b"\x80\x02not sqlite at all" * 100)
    out = collie("export", "--db", str(junk), "--run", "1")
    assert out.returncode == 2 and "not a collie database" in out.stderr and "Traceback" not in out.stderr
    empty = tmp_path / "empty"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "COLLIE_DATABASE_URL"}
    out = collie("export", "--run", "1", cwd=empty, env=env)
    assert out.returncode == 2 and "collie.db does not exist" in out.stderr and list(empty.iterdir()) == []
    out = collie("export", "--db", str(empty), "--run", "1")
    assert (
        out.returncode == 2 and f"{empty} is a folder; give a SQLite file's path" in out.stderr
    )  # was "no database at"


def test_an_export_that_upgrades_leaves_the_upgrade_in_the_database_file(tmp_path: Path) -> None:
    """The upgraded file stands alone: no write-ahead log left beside it, and the file by itself
    (copied away, as one copies a database) is at the newest schema. Was: export's read-only
    connection stayed open, so closing the upgrade's connection was not the file's last close,
    SQLite neither checkpointed nor removed the log, and the file alone was still at 0008."""
    (tmp_path / "old").mkdir()  # a folder of its own: what the export leaves beside the file
    old = migrated(tmp_path / "old" / "collie.db", "0008")
    out = collie("export", "--db", str(old), "--run", "1")
    assert out.returncode == 2 and "upgraded" in out.stderr and "no run 1" in out.stderr, out.stderr
    assert sorted(p.name for p in old.parent.iterdir()) == ["collie.db"]
    alone = tmp_path / "copy.db"
    shutil.copy(old, alone)
    with closing(sqlite3.connect(f"file:{alone}?mode=ro&immutable=1", uri=True)) as conn:
        assert conn.execute("SELECT version_num FROM alembic_version").fetchall() == [(head(),)]


def test_a_refused_export_leaves_the_file_as_it_was(tmp_path: Path) -> None:
    """Was: an empty file got 4 KB (and another program's database WAL mode) before the refusal."""
    empty = tmp_path / "empty.db"
    empty.touch()
    other = tmp_path / "other.db"
    with closing(sqlite3.connect(other)) as conn:
        conn.execute("CREATE TABLE notes (text TEXT)")
        conn.commit()
    for path in (empty, other):
        before = path.read_bytes()
        out = collie("export", "--db", str(path), "--run", "1")
        assert out.returncode == 2 and f"{path} is not a collie database (no schema version)" in out.stderr, out.stderr
        assert path.read_bytes() == before and not path.with_name(path.name + "-wal").exists()


def test_migrations_build_exactly_the_models(tmp_path: Path) -> None:
    db = Database(f"sqlite:///{tmp_path / 'm.db'}")
    upgrade(db.engine)
    upgrade(db.engine)  # idempotent
    with db.engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
        modes = (
            conn.exec_driver_sql("PRAGMA journal_mode").scalar(),
            conn.exec_driver_sql("PRAGMA foreign_keys").scalar(),
        )
    assert modes == ("wal", 1)
    db.dispose()


def test_the_bound_socket_accepts_connections_before_the_server_runs() -> None:
    """`collie serve` prints its banner after `bind` and before uvicorn starts: a client that
    connects at once must queue, not be refused."""
    from backend.server import bind

    sock, url = bind("127.0.0.1", 0)
    try:
        with socket.create_connection(("127.0.0.1", sock.getsockname()[1]), timeout=2):
            assert url.startswith("http://127.0.0.1:")
    finally:
        sock.close()


def start_serve(db: Path, tokens_file: Path | None, env: dict[str, str]) -> tuple[subprocess.Popen[str], list[str]]:
    command = [sys.executable, "-m", "collie.cli", "serve", "--port", "0", "--db", str(db)]
    if tokens_file is not None:
        command += ["--tokens-json", str(tokens_file)]
    env = {**env, "PYTHONFAULTHANDLER": "1"}  # for stop(): a hung server's stacks on SIGABRT
    server = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines = [server.stdout.readline() for _ in range(4)]  # type: ignore[union-attr]
    return server, lines


def stop(server: subprocess.Popen[str]) -> None:
    server.send_signal(signal.SIGINT)
    try:
        code = server.wait(20)
    except subprocess.TimeoutExpired:  # show where it hangs: faulthandler prints every thread's stack
        server.send_signal(signal.SIGABRT)
        _, err = server.communicate(timeout=20)
        pytest.fail(f"collie serve did not stop within 20 s of Ctrl-C; its threads:\n{err[-8000:]}")
    assert code == 0


def test_a_restarted_service_keeps_its_tokens(tmp_path: Path) -> None:
    """Clients holding the tokens keep working across a plain restart, with a tokens file or
    without (then the tokens printed at the first start stay the valid ones)."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    db, tokens_file = tmp_path / "keep.db", tmp_path / "tokens.json"
    server, _ = start_serve(db, tokens_file, env)
    first = json.loads(tokens_file.read_text())["tokens"]
    stop(server)
    server, lines = start_serve(db, tokens_file, env)
    try:
        info = json.loads(tokens_file.read_text())
        assert info["tokens"] == first and f"trainer token: (kept, in {tokens_file})" in "".join(lines)
        with CollieClient(info["api"], first["trainer"]) as trainer:
            assert trainer.me().name == "trainer"
    finally:
        stop(server)
    server, lines = start_serve(db, None, env)  # no tokens file: the database's tokens stay
    try:
        assert "operator token: (kept from the last start" in "".join(lines)
        api = lines[0].split("listening on ")[1].split()[0]
        with CollieClient(api, first["operator"]) as operator:
            assert operator.me().name == "operator"
    finally:
        stop(server)
    fresh, later = tmp_path / "fresh.db", tmp_path / "later.json"
    stop(start_serve(fresh, None, env)[0])  # printed its tokens; a later start names a tokens file
    server, lines = start_serve(fresh, later, env)
    try:  # was: "--tokens-json FILE writes tokens to a file", with --tokens-json given
        said = f"operator token: (kept from a start that printed it and wrote no {later}; to replace it, set "
        assert said + "COLLIE_OPERATOR_TOKEN to write it there)" in "".join(lines), lines
    finally:
        stop(server)


def test_no_generate_tokens_keeps_the_tokens_file_s_other_tokens(tmp_path: Path) -> None:
    """Was: a start with --no-generate-tokens rewrote the tokens file with the environment's tokens
    only, and the tokens an earlier start generated (written nowhere else) were lost."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    db, tokens_file = tmp_path / "keep.db", tmp_path / "tokens.json"
    server, _ = start_serve(db, tokens_file, env)
    first = json.loads(tokens_file.read_text())["tokens"]
    stop(server)
    env = {**env, "COLLIE_TRAINER_TOKEN": "trainer-from-env-0123456789"}
    command = [sys.executable, "-m", "collie.cli", "serve", "--port", "0", "--db", str(db)]
    command += ["--tokens-json", str(tokens_file), "--no-generate-tokens"]
    server = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        api = server.stdout.readline().split("listening on ")[1].split()[0]  # type: ignore[union-attr]
        kept = json.loads(tokens_file.read_text())["tokens"]
        assert kept == {**first, "trainer": "trainer-from-env-0123456789"}
        with CollieClient(api, first["operator"]) as operator:
            assert operator.me().name == "operator"
    finally:
        stop(server)
    db.unlink()  # a new database: the old tokens are valid nowhere, and the file keeps none of them
    env["COLLIE_OPERATOR_TOKEN"] = "operator-from-env-0123456789"
    server = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        server.stdout.readline()  # type: ignore[union-attr]  # the banner: the file is written
        assert json.loads(tokens_file.read_text())["tokens"] == {
            "operator": "operator-from-env-0123456789",
            "trainer": "trainer-from-env-0123456789",
        }
    finally:
        stop(server)


def test_a_start_that_cannot_listen_is_a_one_line_error_that_makes_no_database(tmp_path: Path) -> None:
    """A port in use, an address not this machine's, a bad --fd: refused before the database and its
    tokens are made (they would never be printed, and the next start would keep them: a lockout)."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    db, tokens_file = tmp_path / "c.db", tmp_path / "tokens.json"
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        refused = [
            (["--port", str(port)], f"cannot listen on 127.0.0.1:{port}: Address already in use (--port 0 takes"),
            (["--host", "999.9.9.9"], "cannot listen on 999.9.9.9:8000: "),
            (["--fd", "-1"], "argument --fd: -1 is less than 0 (a file descriptor)"),
        ]
        for flags, said in refused:
            out = collie("serve", "--db", str(db), *flags, env=env)
            assert out.returncode == 2 and said in out.stderr and "Traceback" not in out.stderr, out.stderr
            assert out.stderr.strip().splitlines()[-1].startswith("collie serve: error: ")
            assert not db.exists()
    server, _ = start_serve(db, tokens_file, env)  # the next start makes (and writes) every token
    try:
        assert sorted(json.loads(tokens_file.read_text())["tokens"]) == ["labeler", "operator", "trainer"]
    finally:
        stop(server)


def test_a_tokens_file_that_cannot_be_written_is_refused_before_any_token_is_made(tmp_path: Path) -> None:
    """Was: the tokens were made and stored (as hashes), then writing --tokens-json failed with a
    traceback; the next start said they were "kept from the last start, which printed it": a lockout."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    db = tmp_path / "c.db"
    (tmp_path / "unmounted").symlink_to(tmp_path / "gone")
    (tmp_path / "a-folder").mkdir()
    refused = [
        (tmp_path / "unmounted" / "t.json", f"{tmp_path / 'unmounted'}: a link to {tmp_path / 'gone'}, which"),
        (tmp_path / "a-folder", "is a folder; give a file's path"),
    ]
    for path, said in refused:
        out = collie("serve", "--db", str(db), "--port", "0", "--tokens-json", str(path), env=env)
        assert out.returncode == 2 and said in out.stderr and "Traceback" not in out.stderr, out.stderr
        assert not db.exists()
    server, _ = start_serve(db, tmp_path / "tokens.json", env)  # the next start makes (and writes) every token
    try:
        assert sorted(json.loads((tmp_path / "tokens.json").read_text())["tokens"]) == [
            "labeler",
            "operator",
            "trainer",
        ]
    finally:
        stop(server)


def test_a_tokens_file_the_disk_will_not_take_stores_no_token(tmp_path: Path) -> None:
    """A file that cannot be replaced (immutable here; a full disk fails the same write): a folder
    that takes an empty file passed the first check, then the tokens were stored (as hashes) and the
    write failed, and the next start printed them "kept from the last start, which printed it"."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    db, tokens_file = tmp_path / "c.db", tmp_path / "tokens.json"
    tokens_file.write_text('{"tokens": {}}')
    if subprocess.run(["chattr", "+i", str(tokens_file)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i is refused here (not root, or a file system without it)")
    try:
        out = collie("serve", "--db", str(db), "--port", "0", "--tokens-json", str(tokens_file), env=env)
    finally:
        subprocess.run(["chattr", "-i", str(tokens_file)], check=True)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    said = f"collie serve: error: --tokens-json {tokens_file}: cannot write it (operation not permitted)"
    assert out.stderr.startswith(said) and out.stderr.endswith("; no token was stored, nothing changed\n"), out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.db", "tokens.json"]  # no copy of the tokens beside
    server, lines = start_serve(db, tokens_file, env)
    try:
        assert not any("kept" in line for line in lines), lines
        assert sorted(json.loads(tokens_file.read_text())["tokens"]) == ["labeler", "operator", "trainer"]
    finally:
        stop(server)


def test_a_start_refused_for_one_token_given_to_two_roles_leaves_the_tokens_file_as_it_was(tmp_path: Path) -> None:
    """The file is written before the tokens are stored; a start refused after (the trainer's token
    pasted as the operator's) must not leave its tokens there: the file held the only copy of the
    stored operator token, and every later start read the conflict back from it."""
    env = {k: v for k, v in os.environ.items() if not (k.startswith("COLLIE_") and k.endswith("_TOKEN"))}
    db, tokens_file = tmp_path / "c.db", tmp_path / "tokens.json"
    server, _ = start_serve(db, tokens_file, env)
    stop(server)
    before = tokens_file.read_bytes()
    trainer_token = json.loads(before)["tokens"]["trainer"]
    pasted = {**env, "COLLIE_OPERATOR_TOKEN": trainer_token}
    out = collie("serve", "--db", str(db), "--port", "0", "--tokens-json", str(tokens_file), env=pasted)
    assert out.returncode == 2 and "already the token of 'trainer'" in out.stderr, out.stderr
    assert tokens_file.read_bytes() == before
    server, lines = start_serve(db, tokens_file, env)  # the mistake undone: a plain start, as before it
    try:
        assert lines[0].startswith("collie service listening on "), lines
        assert json.loads(tokens_file.read_text())["tokens"] == json.loads(before)["tokens"]
    finally:
        stop(server)


def test_one_token_for_two_roles_is_a_one_line_error(tmp_path: Path) -> None:
    env = {
        **os.environ,
        "COLLIE_OPERATOR_TOKEN": "same-token-0123456789",
        "COLLIE_LABELER_TOKEN": "same-token-0123456789",
    }
    out = collie("serve", "--port", "0", "--db", str(tmp_path / "same.db"), env=env)
    assert out.returncode == 2 and "Traceback" not in out.stderr  # no restart mends it (was exit 1)
    assert "already the token of 'operator'" in out.stderr


def test_a_new_database_with_no_token_anyone_could_use_is_refused(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")}
    out = collie("serve", "--port", "0", "--db", str(tmp_path / "none.db"), "--no-generate-tokens", env=env)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "on a new database: nobody could sign in (set them, or drop --no-generate-tokens)" in out.stderr


def migrated(path: Path, revision: str) -> Path:
    """A SQLite database at schema `revision`."""
    db = Database(f"sqlite:///{path}")
    config = alembic_config(db.url)
    with db.engine.begin() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, revision)
    db.dispose()
    return path


def test_a_newer_collies_database_is_a_one_line_error(tmp_path: Path) -> None:
    db = migrated(tmp_path / "future.db", "head")
    with Database(f"sqlite:///{db}").engine.begin() as conn:
        conn.exec_driver_sql("UPDATE alembic_version SET version_num = '9999_future'")
    out = collie("serve", "--port", "0", "--db", str(db))
    assert out.returncode != 0 and "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert f"{db} is at schema revision 9999_future, which this collie does not know" in out.stderr
    assert "a newer collie made it" in out.stderr
    out = collie("export", "--db", str(db), "--run", "1")  # the same words: one check for both commands
    assert out.returncode == 2 and "9999_future, which this collie does not know" in out.stderr


def test_serve_says_it_upgraded_the_schema(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")}
    db = migrated(tmp_path / "old.db", "0005")
    server, _ = start_serve(db, None, env)
    stop(server)
    said = server.stderr.read()  # type: ignore[union-attr]
    assert f"upgraded {db} from schema 0005 to {head()}" in said and "Traceback" not in said
    server, _ = start_serve(db, None, env)  # up to date: nothing to say
    stop(server)
    assert "upgraded" not in server.stderr.read()  # type: ignore[union-attr]


@pytest.mark.parametrize(
    "url",
    [
        "postgres://collie:s3cret@127.0.0.1:5432/collie",
        "mysql://collie:s3cret@127.0.0.1/collie",
        "hello",
        "hello://collie:s3cret@",
    ],
)
def test_a_database_url_collie_cannot_use_is_a_one_line_error(tmp_path: Path, url: str) -> None:
    env = {**os.environ, "COLLIE_DATABASE_URL": url}
    for args in (("serve", "--port", "0"), ("export", "--run", "1")):
        out = collie(*args, env=env, cwd=tmp_path)
        assert out.returncode == 2 and "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
        assert "COLLIE_DATABASE_URL" in out.stderr and "postgresql+psycopg://" in out.stderr
        assert "s3cret" not in out.stderr and url.split(":")[0] in out.stderr


def test_export_bounds_the_run_id_and_takes_no_url_for_a_path(tmp_path: Path) -> None:
    """Run ids are bounded as the API bounds them (PostgreSQL's INTEGER); a database URL given as
    --db (a SQLite file's path, as for `collie serve`) is refused without echoing its password."""
    db = str(migrated(tmp_path / "c.db", "head"))
    out = collie("export", "--db", db, "--run", "99999999999")
    assert out.returncode == 2 and "Traceback" not in out.stderr and "2147483647" in out.stderr
    assert collie("export", "--db", db, "--run", "0").returncode == 2
    url = "postgresql+psycopg://collie:s3cret@127.0.0.1:5432/collie"
    for args in (("export", "--run", "1"), ("serve", "--port", "0")):
        out = collie(*args, "--db", url, cwd=tmp_path)
        assert out.returncode == 2 and "Traceback" not in out.stderr and "argument --db: takes a SQLite" in out.stderr
        assert "s3cret" not in out.stderr and "COLLIE_DATABASE_URL" in out.stderr
        assert not (tmp_path / "postgresql+psycopg:").exists()


@pytest.mark.parametrize(
    ("variable", "token", "why"),
    [
        ("COLLIE_OPERATOR_TOKEN", "change-me-operator", "placeholder"),
        ("COLLIE_LABELER_TOKEN", "Zq9", "shorter than 16"),
        ("COLLIE_TRAINER_TOKEN", "Change-Me-Please-0123456789", "placeholder"),
    ],
)
def test_a_weak_bootstrap_token_is_refused_at_start(tmp_path: Path, variable: str, token: str, why: str) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")}
    out = collie("serve", "--port", "0", "--db", str(tmp_path / "weak.db"), env={**env, variable: token})
    assert out.returncode == 2 and "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert variable in out.stderr and why in out.stderr and token not in out.stderr
    assert not (tmp_path / "weak.db").exists()  # refused before anything was written


def test_a_revoked_built_in_token_is_never_presented_as_valid(tmp_path: Path) -> None:
    """After an operator revokes the built-in labeler, no start writes its token to the tokens
    file or calls it kept, whether COLLIE_LABELER_TOKEN still holds it or not."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")}
    db, tokens_file = tmp_path / "rev.db", tmp_path / "tokens.json"
    server, _ = start_serve(db, tokens_file, env)
    try:
        first = json.loads(tokens_file.read_text())
        with CollieClient(first["api"], first["tokens"]["operator"]) as operator:
            operator.revoke(next(p.id for p in operator.labelers() if p.name == "labeler"))
    finally:
        stop(server)
    for extra in ({"COLLIE_LABELER_TOKEN": first["tokens"]["labeler"]}, {}):
        server, lines = start_serve(db, tokens_file, {**env, **extra})
        stop(server)
        said = "".join(lines) + server.stderr.read()  # type: ignore[union-attr]
        assert "labeler token: revoked" in said and "kept" not in said.split("labeler token:")[1].split("\n")[0]
        assert "labeler" not in json.loads(tokens_file.read_text())["tokens"]


def test_serve_refuses_another_program_s_database_and_leaves_it_as_it_was(tmp_path: Path) -> None:
    """Was: `collie serve --db photos.db` added collie's tables to it (and switched it to WAL mode).
    An empty file is a new database, as a missing one is."""
    other = tmp_path / "photos.db"
    with closing(sqlite3.connect(other)) as conn:
        conn.execute("CREATE TABLE photos (path TEXT)")
        conn.commit()
    before = other.read_bytes()
    out = collie("serve", "--port", "0", "--db", str(other))
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert out.stderr.strip() == (
        f"collie serve: error: {other} is not a collie database (no schema version; its tables: photos): "
        "give a new file or a collie one"
    )
    assert other.read_bytes() == before and not other.with_name(other.name + "-wal").exists()
    empty = tmp_path / "empty.db"
    empty.touch()
    server, lines = start_serve(empty, None, {k: v for k, v in os.environ.items() if not k.startswith("COLLIE_")})
    stop(server)
    assert lines[0].startswith("collie service listening on ")


def test_a_damaged_database_is_a_one_line_error(tmp_path: Path) -> None:
    """Was: export's traceback "no such table: label_events", and serve started on it (every
    request touching the table then failed)."""
    db = migrated(tmp_path / "damaged.db", "head")
    with closing(sqlite3.connect(db)) as conn:
        conn.execute("DROP TABLE label_events")
        conn.commit()
    said = f"database {db} is damaged: its table label_events is missing (restore it from a backup)"
    for flags in (["export", "--run", "1"], ["export", "--run", "1", "--effective"], ["serve", "--port", "0"]):
        out = collie(*flags, "--db", str(db))
        assert out.returncode == 2 and out.stderr == f"collie {flags[0]}: error: {said}\n", out.stderr


@contextmanager
def tmpfs_mount(folder: Path) -> Iterator[Path]:
    """`folder` as a 16 MB file system of its own, for the caller to fill, or to remount read-only
    (root writes to no file there, unlike in a chmod'ed folder)."""
    with small_disk(folder, "16m") as disk:
        yield disk


def test_a_database_on_a_full_disk_is_said_to_be_on_a_full_disk(tmp_path: Path) -> None:
    """SQLite says only "disk I/O error" (it cannot make the -shm file its WAL database needs). Exit 1:
    the disk may have room again at the next start (`collie up` retries)."""
    with tmpfs_mount(tmp_path / "disk") as disk:
        shutil.copy(migrated(tmp_path / "good.db", "head"), disk / "good.db")
        fill(disk)
        out = collie("serve", "--port", "0", "--db", str(disk / "good.db"))
        assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
        assert out.stderr.startswith(
            f"collie serve: error: cannot open the database {disk / 'good.db'}: its disk is full"
        )


def test_export_reads_a_read_only_database_and_serve_names_a_missing_folder(tmp_path: Path) -> None:
    """Was: "is not a collie database (unable to open database file)" for a collie database on a
    read-only file system (SQLite cannot make the -shm file a WAL database wants there), and
    serve's "unable to open database file" for a --db in a folder that does not exist."""
    with tmpfs_mount(tmp_path / "ro") as ro:
        shutil.copy(migrated(tmp_path / "good.db", "head"), ro / "good.db")
        shutil.copy(migrated(tmp_path / "old.db", "0008"), ro / "old.db")
        subprocess.run(["mount", "-o", "remount,ro", ro], check=True)
        out = collie("export", "--db", str(ro / "good.db"), "--run", "1")
        assert out.returncode == 2 and out.stderr == "collie export: error: no run 1\n", out.stderr  # read it
        out = collie("export", "--db", str(ro / "old.db"), "--run", "1")
        assert out.returncode == 2 and out.stderr.startswith(f"collie export: error: {ro / 'old.db'} is at schema 0008")
        assert "cannot be upgraded here (unable to open database file): export a writable copy of it" in out.stderr
        for db in (ro / "good.db", ro / "new.db"):  # was "unable to open database file", exit 1 (retried by up)
            out = collie("serve", "--port", "0", "--db", str(db))
            assert out.returncode == 2, out.stderr
            assert out.stderr == (
                f"collie serve: error: {db} is on a read-only file system: the service writes to it "
                "(collie export reads it there)\n"
            )
    out = collie("serve", "--port", "0", "--db", "nope/x.db", cwd=tmp_path)
    assert out.returncode == 2 and not (tmp_path / "nope").exists()
    assert (
        out.stderr == f"collie serve: error: nope/x.db: the folder {tmp_path / 'nope'} does not exist (make it first)\n"
    )
