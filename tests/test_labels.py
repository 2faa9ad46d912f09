"""One Label type: the values and names everyone uses, and the wire accepts exactly its integers."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from collie.labels import Label
from collie.schemas import LabelSubmit
from collie.tasks import BAD, CLASS_NAMES, GOOD, NEUTRAL


def test_label_values_and_names() -> None:
    assert [(int(v), v.word) for v in Label] == [(0, "bad"), (1, "neutral"), (2, "good")]
    assert (BAD, NEUTRAL, GOOD) == (Label.BAD, Label.NEUTRAL, Label.GOOD)
    assert CLASS_NAMES == {0: "bad", 1: "neutral", 2: "good"}


@pytest.mark.parametrize("value", [0, 1, 2, "skip"])
def test_a_submission_is_a_label_or_skip(value: int | str) -> None:
    body = LabelSubmit.model_validate_json(
        f'{{"query_id": "q", "value": {value!r}, "client_request_id": "r"}}'.replace("'", '"')
    )
    assert body.value == value and (value == "skip" or isinstance(body.value, Label))
    assert LabelSubmit.model_validate_json(body.model_dump_json()) == body


@pytest.mark.parametrize("raw", ['"2"', "3", "-1", "true", "2.0", "null"])
def test_anything_else_is_refused(raw: str) -> None:
    with pytest.raises(ValidationError):
        LabelSubmit.model_validate_json(f'{{"query_id": "q", "value": {raw}, "client_request_id": "r"}}')
