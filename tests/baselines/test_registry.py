"""The method registry is the one place that knows each method: names, labels, learner, w."""

from __future__ import annotations

import pytest

from trainer.config import make_config
from trainer.methods import METHODS, method


def test_the_table_says_who_asks_for_labels_and_how_w_is_made() -> None:
    assert list(METHODS) == ["collie", "metra", "oracle", "dodont", "ddg", "lsd", "diayn"]
    assert {m.name for m in METHODS.values() if m.asks_labels} == {"collie", "dodont", "ddg"}
    assert {m.name: m.guidance for m in METHODS.values() if m.guidance != "one"} == {
        "collie": "labels",
        "oracle": "task",
        "dodont": "instruction",
    }


def test_an_unknown_method_is_named_with_the_valid_ones() -> None:
    with pytest.raises(ValueError, match=r"unknown method 'nope'; valid: collie, metra"):
        method("nope")
    with pytest.raises(ValueError, match="unknown method 'nope'"):
        make_config("smoke", method="nope")
