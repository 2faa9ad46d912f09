"""Keyboard-first labeling: viser commands with hotkeys. No key here is one of viser's camera keys
(W A S D Q E and the arrows, which its page binds and no option turns off), so stepping a frame or
skipping never turns the north-up view.

viser's hotkeys ignore every key pressed while an <input> has focus, so a click on the Loop box, the
Frame box or the Segment list used to silence 1 2 3 until the labeler clicked elsewhere. A script
hands such a key back to the page; only the sign-in field (a text input) keeps its keys, and Enter
there signs in. The Frame
box shows the frame and takes no typing (its digits would be labels): the slider and J L move it.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable

import viser

from collie.labels import Label
from labeling_ui.browser import run_script
from labeling_ui.panels import SIGN_IN, Actions

_HAND_KEYS_BACK = """
(() => {
  if (window.collieKeysHandedBack) return;  // once per page: a reload starts a new one
  window.collieKeysHandedBack = true;
  const keys = new Set(%(keys)s);
  const typedInto = (el) => el.classList.contains("mantine-TextInput-input");
  // only our controls hand keys back: the Frame box, the Segment list, the Loop and Shadows boxes
  // (never viser's command palette, a dialog, whose search field takes letters)
  const ours = (el) => !el.closest("[role=dialog]") && (el.type === "checkbox"
    || el.classList.contains("mantine-NumberInput-input") || el.classList.contains("mantine-Select-input"));
  window.addEventListener("focusin", (event) => {
    const el = event.target;
    if (el instanceof HTMLInputElement && el.classList.contains("mantine-NumberInput-input")) el.blur();
  }, true);
  window.addEventListener("keydown", (event) => {
    const el = event.target;
    if (event.key === "Enter" && el instanceof HTMLInputElement && typedInto(el)) {  // the sign-in field
      const button = [...document.querySelectorAll("button")].find((b) => b.textContent.trim() === %(sign_in)s);
      // after viser's 50 ms throttle has sent the field's last keystroke: the click must not overtake it
      if (button) setTimeout(() => button.click(), 120);
      return;
    }
    if (!(el instanceof HTMLInputElement) || !ours(el)) return;
    if (event.ctrlKey || event.metaKey || event.altKey || event.shiftKey) return;  // as viser's own hotkeys
    const listOpen = el.getAttribute("aria-expanded") === "true";  // an open list keeps its keys
    if (!keys.has(event.key.toLowerCase()) || listOpen) return;
    event.preventDefault();
    event.stopImmediatePropagation();
    el.blur();
    document.body.dispatchEvent(new KeyboardEvent("keydown", {key: event.key, code: event.code, bubbles: true}));
  }, true);
})();
"""


def _run(do: Callable[[], None], _event: object) -> None:
    do()


def bind_keys(client: viser.ClientHandle, actions: Actions) -> None:
    bindings: list[tuple[str, str, Callable[[], None]]] = [
        *((str(v + 1), f"Label {v.word}", functools.partial(actions.label, v)) for v in Label),  # keys 1 2 3
        ("X", "Skip this segment", actions.skip),
        ("U", "Undo the last label", actions.undo),
        ("space", "Replay from the start", actions.replay),
        ("P", "Play / pause", actions.toggle_play),
        ("J", "Previous frame", lambda: actions.step(-1)),
        ("L", "Next frame", lambda: actions.step(1)),
        ("V", "Reset the view: north up", actions.reset_view),
    ]
    for key, label, do in bindings:
        command = client.gui.add_command(label, hotkey=key)  # type: ignore[arg-type]  # viser's hotkey Literal lists every key name
        command.on_trigger(functools.partial(_run, do))
    page_keys = [" " if key == "space" else key.lower() for key, _, _ in bindings]
    run_script(client, _HAND_KEYS_BACK % {"keys": json.dumps(page_keys), "sign_in": json.dumps(SIGN_IN)})
