"""The one retry policy of every client: typed errors, and `retrying` waits out only Unavailable."""

from __future__ import annotations

import itertools
import threading

import pytest

from collie.client import (
    ApiError,
    Backoff,
    Conflict,
    Overloaded,
    Unauthorized,
    Unavailable,
    Unreachable,
    api_error,
    retrying,
)

NO_WAIT = Backoff(first_s=0.0, max_s=0.0)


class Flaky:
    """Fails with the given errors in turn, then answers "ok"."""

    def __init__(self, *errors: Exception) -> None:
        self.errors = list(errors)
        self.calls = 0

    def __call__(self) -> str:
        self.calls += 1
        if self.errors:
            raise self.errors.pop(0)
        return "ok"


def test_error_statuses_are_typed_by_what_a_caller_does_about_them() -> None:
    assert type(api_error(401, "x")) is Unauthorized and type(api_error(403, "x")) is Unauthorized
    assert type(api_error(409, "x")) is Conflict
    for status in (500, 503, 429):
        error = api_error(status, "x")
        assert isinstance(error, Overloaded) and isinstance(error, Unavailable) and error.status == status
    assert type(api_error(422, "x")) is ApiError and not isinstance(api_error(422, "x"), Unavailable)
    assert issubclass(Unreachable, Unavailable) and not issubclass(Unreachable, ApiError)


def test_backoff_doubles_up_to_its_ceiling() -> None:
    assert list(itertools.islice(Backoff(0.1, 1.0).delays(), 6)) == pytest.approx([0.1, 0.2, 0.4, 0.8, 1.0, 1.0])


def test_an_unavailable_service_is_waited_out() -> None:
    call = Flaky(Unreachable("down"), api_error(503, "restarting"), api_error(429, "busy"))
    assert retrying(call, NO_WAIT) == "ok" and call.calls == 4


@pytest.mark.parametrize("error", [api_error(409, "lease lost"), api_error(401, "revoked"), api_error(422, "bad")])
def test_anything_else_raises_at_once(error: ApiError) -> None:
    call = Flaky(error)
    with pytest.raises(type(error)):
        retrying(call, NO_WAIT)
    assert call.calls == 1


def test_attempts_and_stop_bound_the_wait() -> None:
    call = Flaky(*[Unreachable("down")] * 5)
    with pytest.raises(Unreachable):
        retrying(call, NO_WAIT, attempts=3)
    assert call.calls == 3
    stop = threading.Event()
    stop.set()
    call = Flaky(Unreachable("down"))
    with pytest.raises(Unreachable):
        retrying(call, NO_WAIT, stop=stop)
    assert call.calls == 1
