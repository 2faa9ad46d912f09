"""How clients take their token (collie/tokens.py): --token=-abc and --token -abc parse, --token-file and
COLLIE_TOKEN keep it out of argv, and files holding secrets are 0600 from the start."""

import argparse
import json
import os
import stat
import subprocess
import sys

import pytest

from collie.tokens import add_token_arguments, resolve_token, write_secret


def parse(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_token_arguments(p, "trainer")
    return p.parse_args(argv)


def test_a_token_that_starts_with_a_dash_parses_in_the_equals_form(monkeypatch):
    monkeypatch.delenv("COLLIE_TOKEN", raising=False)
    assert resolve_token(parse("--token=-Pjy_x"), "trainer") == "-Pjy_x"


def test_file_then_environment_then_role_variable(tmp_path, monkeypatch):
    secret = tmp_path / "t"
    write_secret(secret, "-from-file\n")
    assert stat.S_IMODE(os.stat(secret).st_mode) == 0o600
    monkeypatch.setenv("COLLIE_TRAINER_TOKEN", "role")
    assert resolve_token(parse(), "trainer") == "role"
    monkeypatch.setenv("COLLIE_TOKEN", "generic")
    assert resolve_token(parse(), "trainer") == "generic"
    assert resolve_token(parse("--token-file", str(secret)), "trainer") == "-from-file"
    assert resolve_token(parse(), "trainer", from_env=False) is None


def test_a_missing_or_empty_token_file_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match=r"--token-file .*missing"):
        resolve_token(parse("--token-file", str(tmp_path / "missing")), "trainer")
    (tmp_path / "empty").write_text("\n")
    with pytest.raises(ValueError, match="is empty"):
        resolve_token(parse("--token-file", str(tmp_path / "empty")), "trainer")


def test_a_tokens_file_gives_the_role_and_a_bad_file_never_echoes_its_text(tmp_path, capsys):
    tokens = tmp_path / "tokens.json"
    write_secret(tokens, json.dumps({"api": "http://x", "tokens": {"operator": "OP-secret", "trainer": "tr-1"}}))
    assert resolve_token(parse("--token-file", str(tokens)), "trainer") == "tr-1"
    with pytest.raises(ValueError, match="a tokens file without a labeler token \\(it has: operator, trainer\\)"):
        resolve_token(parse("--token-file", str(tokens)), "labeler")
    two_lines = tmp_path / "two"
    write_secret(two_lines, "OP-secret\nsecond line\n")
    with pytest.raises(ValueError, match="does not hold a token") as refused:
        resolve_token(parse("--token-file", str(two_lines)), "trainer")
    assert "secret" not in str(refused.value)
    open_file = tmp_path / "open"
    open_file.write_text("tok-1\n")
    open_file.chmod(0o644)
    assert resolve_token(parse("--token-file", str(open_file)), "trainer") == "tok-1"
    assert "readable by other users (chmod 600 it)" in capsys.readouterr().err


def test_a_token_with_a_space_from_the_environment_is_refused_by_name(monkeypatch):
    monkeypatch.setenv("COLLIE_TOKEN", "two words")
    with pytest.raises(ValueError, match=r"^COLLIE_TOKEN does not hold a token"):
        resolve_token(parse(), "trainer")


def test_a_bootstrap_token_a_client_could_not_send_is_weak():
    from collie.tokens import weakness

    assert weakness("a passphrase with spaces in it") == (
        "holds spaces or characters a bearer token cannot carry (printable ASCII only)"
    )
    assert weakness("ünïcödé-" * 3) is not None and weakness("x" * 16) is None


def test_a_new_token_never_starts_with_a_dash() -> None:
    from collie.tokens import random_token

    tokens = {random_token() for _ in range(5000)}  # token_urlsafe alone: one in 64 would
    assert len(tokens) == 5000 and not any(t.startswith("-") for t in tokens)
    assert all(len(t) == 43 for t in tokens)


@pytest.mark.parametrize(
    ("command", "said"),
    [
        (
            ["teacher", "--run", "1", "--api", "http://127.0.0.1:9"],
            "does not answer (connection refused)",
        ),  # it called the service
        (["train", "--preset", "smoke", "--epochs", "0", "--api", "http://127.0.0.1:9"], "--epochs must be ≥ 1"),
    ],
)
def test_a_token_starting_with_a_dash_is_taken_as_the_value_of_token(command: list[str], said: str) -> None:
    argv = [sys.executable, "-m", "collie.cli", *command, "--token", "-" + "t" * 30]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and said in proc.stderr and "expected one argument" not in proc.stderr, proc.stderr
