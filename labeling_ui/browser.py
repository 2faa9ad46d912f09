"""The labeler's token in the browser: from the labeler URL (`?token=…`) or the sign-in field, kept
in the page's localStorage so a reload stays signed in. `?watch=RUN` (the dashboard's "watch
skills in 3D" link) asks for watch mode instead of labeling; it stays in the address bar.

viser does not pass the page URL to the server, so a one-line script (viser's RunJavascript
message, the channel viser itself uses to ship plotly.js) moves the token from the URL into
localStorage and drops it from the address bar; the server then reads it back with viser's public
localStorage API.
"""

from __future__ import annotations

import json

import viser
from viser import _messages

TOKEN_KEY = "collie-token"
WATCH_KEY = "collie-watch"
_STORAGE_PREFIX = "viser-user:"  # what viser's client puts before keys written via its API

_TOKEN_FROM_URL = """
const url = new URL(window.location.href);
const token = url.searchParams.get("token");
if (token !== null) {
  localStorage.setItem(%s, token);
  url.searchParams.delete("token");
  window.history.replaceState(null, document.title, url.toString());
}
const watch = url.searchParams.get("watch");
if (watch !== null) localStorage.setItem(%s, watch); else localStorage.removeItem(%s);
"""


def read_token(client: viser.ClientHandle, timeout_s: float = 30.0) -> str | None:
    """The token given in the URL, else the one remembered from before, else None."""
    watch = json.dumps(_STORAGE_PREFIX + WATCH_KEY)
    script = _TOKEN_FROM_URL % (json.dumps(_STORAGE_PREFIX + TOKEN_KEY), watch, watch)
    client._websock_connection.queue_message(_messages.RunJavascriptMessage(source=script))
    try:
        token = client.local_storage.get_item(TOKEN_KEY, timeout=timeout_s)
    except (RuntimeError, TimeoutError):
        return None
    return token or None


def read_watch(client: viser.ClientHandle, timeout_s: float = 10.0) -> int | None:
    """The run to watch (`?watch=RUN` in the URL; read after read_token, which moves it into the
    page's storage), else None: label."""
    try:
        value = client.local_storage.get_item(WATCH_KEY, timeout=timeout_s)
    except (RuntimeError, TimeoutError):
        return None
    return int(value) if value and value.strip().isdigit() else None


def remember_token(client: viser.ClientHandle, token: str | None) -> None:
    if token:
        client.local_storage.set_item(TOKEN_KEY, token)
    else:
        client.local_storage.remove_item(TOKEN_KEY)
