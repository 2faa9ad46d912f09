"""Who a tab is: the labeler's token and the tab's own id, kept in the tab's sessionStorage.

A token comes from the labeler URL (`?token=…`, which signs in only the tab it opens) or the
sign-in field. sessionStorage belongs to one tab (it survives a reload of that tab; another tab,
or a link opened in one, has its own), so an operator link opened beside a labeler's tab, or a
wrong token in a new tab, never changes who the other tabs are. `?watch=RUN` asks for watch mode,
`?review=RUN&query=ID` for an operator's review of one query (the dashboard's "replay in 3D").
The tab id names the tab's claims at the service (a claim is one tab's: only it may label the
segment); it survives a reload, so a reloaded tab gets its segment back. A tab the browser
duplicates, or one opened with window.open, starts with a copy of the sessionStorage, id
included: the app (app.py, `tab_id`) gives such a copy an id of its own (`remember_tab`).

viser does not pass the page URL to the server and reads only localStorage, so a script (viser's
RunJavascript message, the channel viser itself uses to ship plotly.js) moves the token from the
URL into sessionStorage, drops it from the address bar, and hands it to the server under a key
unique to this connection, which the server deletes as soon as it has read it.
"""

from __future__ import annotations

import json
import re
import secrets
from dataclasses import dataclass, field

import viser
from viser import _messages

TOKEN_KEY = "collie-token"
TAB_KEY = "collie-tab"
LEGACY_KEY = "viser-user:collie-token"  # where earlier versions kept it, shared by every tab
TAB_ID = re.compile(r"tab-[0-9a-f]{24}")  # what the script above writes (collie.schemas.TabId allows it)
PAGE_ID = re.compile(r"page-[0-9a-f]{24}")  # one page load's id (window.colliePage)
_STORAGE_PREFIX = "viser-user:"  # what viser's client puts before keys written via its API

_HANDOFF = """
const url = new URL(window.location.href);
const token = url.searchParams.get("token");
if (token !== null) {
  sessionStorage.setItem(%(key)s, token);
  url.searchParams.delete("token");
  window.history.replaceState(null, document.title, url.toString());
}
if (sessionStorage.getItem(%(tab)s) === null) {  // crypto.randomUUID needs https; this does not
  const bytes = crypto.getRandomValues(new Uint8Array(12));
  sessionStorage.setItem(%(tab)s, "tab-" + Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join(""));
}
if (window.colliePage === undefined) {  // this page load's own: a reconnect of the page keeps it, a copy has another
  const bytes = crypto.getRandomValues(new Uint8Array(12));
  window.colliePage = "page-" + Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join("");
}
localStorage.removeItem(%(legacy)s);
localStorage.setItem(%(handoff)s, JSON.stringify({
  token: sessionStorage.getItem(%(key)s), watch: url.searchParams.get("watch"), tab: sessionStorage.getItem(%(tab)s),
  review: url.searchParams.get("review"), query: url.searchParams.get("query"), width: window.innerWidth,
  page: window.colliePage
}));
"""


def new_tab_id() -> str:
    return f"tab-{secrets.token_hex(12)}"


@dataclass(frozen=True)
class TabIdentity:
    token: str | None
    watch: int | None  # ?watch=RUN: replay that run's skills instead of labeling
    tab: str = field(default_factory=new_tab_id)  # the browser's, else one for this connection
    # ?review=RUN&query=ID: replay that query for an operator, label nothing (as given: review.py checks it)
    review: tuple[int, str] | None = None
    window_width: int | None = None  # the browser window's, in CSS pixels, when the tab opened
    # the page load's own id: a connection that comes back from the same page (a network blip) has it
    page: str | None = None


def run_script(client: viser.ClientHandle, source: str) -> None:
    client._websock_connection.queue_message(_messages.RunJavascriptMessage(source=source))


def read_identity(client: viser.ClientHandle, timeout_s: float = 30.0) -> TabIdentity:
    """This tab's token (from its URL, else from before a reload) and the run to watch."""
    handoff = f"collie-handoff-{secrets.token_hex(8)}"
    script = _HANDOFF % {
        "key": json.dumps(TOKEN_KEY),
        "tab": json.dumps(TAB_KEY),
        "legacy": json.dumps(LEGACY_KEY),
        "handoff": json.dumps(_STORAGE_PREFIX + handoff),
    }
    run_script(client, script)
    try:
        raw = client.local_storage.get_item(handoff, timeout=timeout_s)
    except (RuntimeError, TimeoutError):
        return TabIdentity(None, None)
    finally:
        client.local_storage.remove_item(handoff)
    try:
        found = json.loads(raw) if raw else {}
    except json.JSONDecodeError:
        found = {}
    watch, tab = found.get("watch"), found.get("tab")
    run, query = found.get("review"), found.get("query")
    return TabIdentity(
        found.get("token") or None,
        _run_id(watch),
        tab if isinstance(tab, str) and TAB_ID.fullmatch(tab) else new_tab_id(),
        None if run is None else (_run_id(run) or 0, query if isinstance(query, str) else ""),  # 0: no run
        width if isinstance(width := found.get("width"), int) and width > 0 else None,
        page if isinstance(page := found.get("page"), str) and PAGE_ID.fullmatch(page) else None,
    )


def _run_id(raw: object) -> int | None:
    return int(raw) if isinstance(raw, str) and raw.isascii() and raw.isdigit() else None  # "²" is a digit to isdigit


def remember_token(client: viser.ClientHandle, token: str | None) -> None:
    """Keep (or forget) the token in this tab only."""
    key = json.dumps(TOKEN_KEY)
    if token:
        run_script(client, f"sessionStorage.setItem({key}, {json.dumps(token)});")
    else:
        run_script(client, f"sessionStorage.removeItem({key});")


def remember_tab(client: viser.ClientHandle, tab: str) -> None:
    """This tab goes by `tab` from now on, across its reloads."""
    run_script(client, f"sessionStorage.setItem({json.dumps(TAB_KEY)}, {json.dumps(tab)});")


def load_prefs(client: viser.ClientHandle, who: str, timeout_s: float = 10.0) -> dict[str, object]:
    """A labeler's replay preferences (speed, loop), kept per labeler in this browser."""
    try:
        raw = client.local_storage.get_item(f"collie-prefs-{who}", timeout=timeout_s)
        found = json.loads(raw) if raw else {}
    except (RuntimeError, TimeoutError, json.JSONDecodeError):
        return {}
    return found if isinstance(found, dict) else {}


def save_prefs(client: viser.ClientHandle, who: str, prefs: dict[str, object]) -> None:
    client.local_storage.set_item(f"collie-prefs-{who}", json.dumps(prefs))
