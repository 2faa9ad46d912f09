"""Keyboard-first labeling: viser commands with hotkeys (they fire anywhere on the page except
while typing in a text field, so the token field never labels by accident)."""

from __future__ import annotations

from collections.abc import Callable

import viser

from collie.labels import Label
from labeling_ui.panels import Actions


def bind_keys(client: viser.ClientHandle, actions: Actions) -> None:
    bindings: list[tuple[str, str, Callable[[], None]]] = [
        *((str(v + 1), f"Label {v.word}", lambda v=v: actions.label(v)) for v in Label),  # keys 1 2 3
        ("S", "Skip this segment", actions.skip),
        ("U", "Undo the last label", actions.undo),
        ("space", "Replay from the start", actions.replay),
        ("P", "Play / pause", actions.toggle_play),
        ("arrowleft", "Previous frame", lambda: actions.step(-1)),
        ("arrowright", "Next frame", lambda: actions.step(1)),
    ]
    for key, label, do in bindings:
        command = client.gui.add_command(label, hotkey=key)  # type: ignore[arg-type]
        command.on_trigger(lambda _event, do=do: do())
