"""The method registry is the one place that knows each method: names, labels, learner, w."""

from __future__ import annotations

import pytest

from trainer.config import Config, make_config
from trainer.methods import METHOD_SPECIFIC_KEYS, METHODS, matters, method


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


def test_the_keys_only_some_methods_read_matter_to_those_alone() -> None:
    assert not METHOD_SPECIFIC_KEYS - set(Config.__dataclass_fields__)  # each names a config key
    assert (
        METHODS["metra"].specific_keys == frozenset() and not matters("diayn", "metra") and matters("hidden", "metra")
    )
    assert METHODS["diayn"].specific_keys == {"diayn"} and matters("diayn", "diayn")
    assert {m for m in METHODS if matters("total_queries", m)} == {"collie", "dodont", "ddg"}
    assert {m for m in METHODS if matters("projection_dim", m)} == {"dodont", "ddg"}
    assert {m for m in METHODS if matters("w_at", m)} == {"collie", "oracle", "dodont"}
    assert {m for m in METHODS if matters("k_beta", m)} == {"collie"}
