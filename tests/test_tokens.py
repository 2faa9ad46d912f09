"""How clients take their token (collie/tokens.py): --token=-abc parses, --token-file and
COLLIE_TOKEN keep it out of argv, and files holding secrets are 0600 from the start."""

import argparse
import os
import stat

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
