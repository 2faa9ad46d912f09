"""Every fault the client can meet on the way to the service is one of its typed errors, never
httpx's or pydantic's own: transient ones (Unavailable) for what a retry may mend, refusals
(ApiError) for what it would meet again, each one line naming the URL. A real stand-in server
(tests/canned_http.py) gives the answers a real service never does: a body that lies about its
Content-Encoding, a proxy's HTML page, a body cut short."""

from __future__ import annotations

import socket
import threading
import time

import pytest
from canned_http import answering, answering_raw

from collie.client import (
    ApiError,
    Backoff,
    BadAnswer,
    CollieClient,
    EventStream,
    GarbledAnswer,
    Overloaded,
    Unavailable,
    Unreachable,
    Unsendable,
    no_answer,
    retrying,
)
from collie.schemas import StreamEvent
from labeling_ui.service import Rejected, ServiceDown, ServiceLink
from trainer.feedback import SourceRefused
from trainer.feedback.http import HttpFeedback

from .conftest import TOKENS

NOT_GZIP = (200, b"not gzip at all", {"Content-Encoding": "gzip"})  # a broken proxy's body
LOGIN_PAGE = b"<html><head><title>Sign in to the proxy</title></head><body><form>\n</form></body></html>"
HTML_200 = (200, LOGIN_PAGE, {"Content-Type": "text/html"})
NGINX_502 = (
    b"<html>\r\n<head><title>502 Bad Gateway</title></head>\r\n<body>\r\n<hr><center>nginx</center>\r\n</body></html>"
)


def test_a_body_that_is_not_in_its_declared_encoding_is_a_garbled_answer_waited_out() -> None:
    """Was: httpx.DecodingError, which no caller catches (a traceback)."""
    with (
        answering(*NOT_GZIP) as api,
        CollieClient(api, TOKENS["operator"]) as client,
        pytest.raises(GarbledAnswer) as garbled,
    ):
        retrying(client.health, Backoff(0.0, 0.0), attempts=2)  # retried as transient, then raised
    assert isinstance(garbled.value, Unreachable) and isinstance(garbled.value, Unavailable)
    said = str(garbled.value)
    assert said.startswith(f"GET {api}/api/health: the body is not in its declared Content-Encoding (")
    assert "\n" not in said


def test_a_2xx_body_that_is_not_json_is_a_bad_answer_naming_the_url() -> None:
    """A proxy's sign-in page with a 200. Was: pydantic's multi-line ValidationError."""
    with (
        answering(*HTML_200) as api,
        CollieClient(api, TOKENS["operator"]) as client,
        pytest.raises(BadAnswer) as bad,
    ):
        client.run(3)
    assert bad.value.status == 200 and not isinstance(bad.value, Unavailable)
    assert str(bad.value) == f"GET {api}/api/runs/3 answered 200 with an HTML page (Sign in to the proxy), not JSON"


def test_json_that_is_not_the_expected_model_is_a_bad_answer_naming_the_field() -> None:
    with answering(200, b'{"hello": "world"}') as api, CollieClient(api, TOKENS["operator"]) as client:
        with pytest.raises(BadAnswer) as bad:
            client.health()
        assert str(bad.value).startswith(f"GET {api}/api/health answered 200 with JSON that is not Health (")
        with pytest.raises(BadAnswer, match=r"with JSON that is not a list of RunRead \(Input should be a valid array"):
            client.runs()


def test_a_redirect_is_a_bad_answer_naming_where_to() -> None:
    """The client follows no redirects (so it never meets TooManyRedirects). Was: a ValidationError
    of the 301's empty body."""
    moved = (301, b"", {"Location": "https://collie.example/api/health"})
    with (
        answering(*moved) as api,
        CollieClient(api, TOKENS["operator"]) as client,
        pytest.raises(BadAnswer) as bad,
    ):
        client.health()
    assert bad.value.status == 301
    assert str(bad.value) == (
        f"GET {api}/api/health answered 301, a redirect to https://collie.example/api/health "
        "(this client follows none: give that address)"
    )


def test_a_proxys_html_error_page_is_busy_said_in_one_short_line() -> None:
    """Was: "502: " and the whole page, over several lines."""
    with (
        answering(502, NGINX_502, {"Content-Type": "text/html"}) as api,
        CollieClient(api, "t" * 20) as client,
        pytest.raises(Overloaded) as busy,
    ):
        client.health()
    assert str(busy.value) == "502: an HTML page (502 Bad Gateway)"


def test_a_body_cut_short_is_unreachable() -> None:
    """A chunked body that ends mid-chunk (httpx's RemoteProtocolError): transient."""
    cut = b'HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n5\r\n{"sta\r\n'
    with (
        answering_raw(cut) as api,
        CollieClient(api, TOKENS["operator"]) as client,
        pytest.raises(Unreachable, match="incomplete chunked read"),
    ):
        client.health()


def test_a_service_that_takes_the_connection_and_never_answers_is_said_with_the_time_waited() -> None:
    """A host that accepts and stays silent (a hung service, a proxy waiting on it): the line says how
    long was waited. Was "does not answer (no answer in time)"."""
    with socket.create_server(("127.0.0.1", 0)) as silent:  # the kernel accepts; nobody reads or writes
        api = f"http://127.0.0.1:{silent.getsockname()[1]}"
        with CollieClient(api, TOKENS["operator"], timeout_s=0.5) as client, pytest.raises(Unreachable) as lost:
            client.health()
    assert no_answer(lost.value) == "does not answer (nothing within 0.5 s)"


def test_a_request_that_cannot_be_sent_is_unsendable_not_unreachable() -> None:
    """Was: UnsupportedProtocol as Unreachable (waited out forever), httpx.InvalidURL raw."""
    with (
        CollieClient("ftp://127.0.0.1:9", TOKENS["operator"]) as client,
        pytest.raises(Unsendable) as unsendable,
    ):
        retrying(client.health, Backoff(0.0, 0.0), attempts=5)
    assert str(unsendable.value) == (
        "GET ftp://127.0.0.1:9/api/health cannot be sent: Request URL has an unsupported protocol 'ftp://'."
    )
    assert isinstance(unsendable.value, ApiError) and not isinstance(unsendable.value, Unavailable)
    with CollieClient("http://127.0.0.1:9", TOKENS["operator"]) as client, pytest.raises(Unsendable):
        client.query(1, "0-\x00")
    with pytest.raises(Unsendable, match=r"^http://\[::1 is no URL a request can be sent to: "):
        CollieClient("http://[::1", TOKENS["operator"])


def consume(client: CollieClient) -> tuple[list[StreamEvent], list[BaseException], EventStream]:
    """A run's event stream read in a thread: what it yielded, what it raised, the stream."""
    stream = client.stream(1, max_backoff_s=0.05)
    received: list[StreamEvent] = []
    raised: list[BaseException] = []

    def read() -> None:
        try:
            received.extend(stream)
        except BaseException as exc:
            raised.append(exc)

    threading.Thread(target=read, daemon=True).start()
    return received, raised, stream


def test_the_event_stream_reconnects_after_a_garbled_answer() -> None:
    """Was: the DecodingError ended the stream's iteration (the consumer's thread died)."""
    lying = (200, b"not gzip at all", {"Content-Encoding": "gzip", "Content-Type": "text/event-stream"})
    with answering(*lying) as api, CollieClient(api, TOKENS["operator"]) as client:
        _, raised, stream = consume(client)
        deadline = time.monotonic() + 30
        while stream.reconnects < 3 and not raised and time.monotonic() < deadline:
            time.sleep(0.02)
        stream.close()
    assert not raised and stream.reconnects >= 3


@pytest.mark.parametrize(
    ("answer", "said"),
    [
        (HTML_200, "answered 200 with text/html, not an event stream (an HTML page (Sign in to the proxy))"),
        ((200, b"data: {oops}\n\n", {"Content-Type": "text/event-stream"}), "sent an event this client cannot read ("),
    ],
)
def test_an_answer_that_is_no_event_stream_ends_the_stream_with_a_bad_answer(
    answer: tuple[int, bytes, dict[str, str]], said: str
) -> None:
    """Was: an HTML page read as an empty stream and fetched again at once, forever; an unreadable
    event pydantic's ValidationError."""
    with answering(*answer) as api, CollieClient(api, TOKENS["operator"]) as client:
        received, raised, _ = consume(client)
        deadline = time.monotonic() + 30
        while not raised and time.monotonic() < deadline:
            time.sleep(0.02)
    assert not received and len(raised) == 1 and isinstance(raised[0], BadAnswer), raised
    assert str(raised[0]).startswith(f"GET {api}/api/runs/1/stream {said}")


def test_the_trainer_is_refused_in_one_line_by_an_answer_it_cannot_read() -> None:
    """Was: pydantic's ValidationError out of the trainer (a traceback); a SourceRefused ends the
    run checkpointed, with its line."""
    with answering(*HTML_200) as api:
        feedback = HttpFeedback(api, TOKENS["trainer"], 1)
        try:
            with pytest.raises(SourceRefused) as refused:
                feedback.held_run()
        finally:
            feedback.close()
    assert str(refused.value) == (
        f"the labeling service could not be used for run 1: GET {api}/api/runs/1 answered 200 with an HTML page "
        "(Sign in to the proxy), not JSON"
    )
    assert refused.value.advice == ""


def test_the_labeling_ui_says_a_garbled_or_unreadable_answer_in_one_line() -> None:
    """ServiceDown (the page retries) for a damaged answer; Rejected (the page says it) for one it
    cannot read. Was: DecodingError and ValidationError, which the UI's handlers do not catch."""
    with answering(*NOT_GZIP) as api:
        link = ServiceLink(api, TOKENS["labeler"])
        with pytest.raises(ServiceDown, match=f"^the labeling service at {api} sent an answer damaged on the way"):
            link.run(1)
        link.close()
    with answering(*HTML_200) as api:
        link = ServiceLink(api, TOKENS["labeler"])
        with pytest.raises(Rejected) as rejected:
            link.run(1)
        link.close()
    assert (
        str(rejected.value) == f"GET {api}/api/runs/1 answered 200 with an HTML page (Sign in to the proxy), not JSON"
    )
