"""Keyboard-first labeling: viser commands with hotkeys (they fire anywhere on the page except
while typing in a text field, so the token field never labels by accident). No key here is one of
viser's camera keys (W A S D Q E and the arrows, which its page binds and no option turns off), so
stepping a frame or skipping never turns the north-up view."""

from __future__ import annotations

import functools
from collections.abc import Callable

import viser

from collie.labels import Label
from labeling_ui.panels import Actions


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
