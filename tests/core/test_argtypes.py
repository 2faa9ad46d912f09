"""The command line's number types: a refusal says what is wrong with the value given."""

from __future__ import annotations

import argparse

import pytest

from collie.argtypes import float_in, sqlite_file


@pytest.mark.parametrize(
    ("value", "said"),
    [
        ("inf", "inf must be a finite number ≥ 0"),  # was "inf must be ≥ 0", which it is
        ("nan", "nan must be a finite number ≥ 0"),
        ("-1", "-1 must be ≥ 0"),
        ("soon", "'soon' is not a number"),
    ],
)
def test_a_refused_number_says_why(value: str, said: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError) as refused:
        float_in(0, low_open=False)(value)
    assert str(refused.value) == said


def test_numbers_in_range_are_taken() -> None:
    assert float_in(0, 10)("10") == 10.0 and float_in(0, low_open=False)("0") == 0.0
    with pytest.raises(argparse.ArgumentTypeError, match=r"^0 must be > 0 and ≤ 10$"):
        float_in(0, 10)("0")


@pytest.mark.parametrize("value", ["", "  "])
def test_an_empty_db_path_is_refused_as_empty(value: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="is empty"):  # was "'.' is a folder", from Path("")
        sqlite_file(value)
