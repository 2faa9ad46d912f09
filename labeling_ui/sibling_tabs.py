"""What one tab's session tells, and asks, the labeler's other tabs (the app keeps them all): the id
it goes by, that it showed or preloaded a segment, that a label or skip of one landed, that it
handed claims back; and what the app keeps of a tab across its reloads (TabMemory). Tabs of one
labeler that go by one id (a reload and the connection it replaced) share that id's claims at the
service, so each must hear what the others did with them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from labeling_ui.tab import Key

if TYPE_CHECKING:
    from labeling_ui.session import LabelerSession


@dataclass
class TabMemory:
    """What the app keeps of one browser tab (by its id) across its reloads: who signed in there
    last, and the labels made there since (U walks back through them; another labeler signing in
    here must not: `TabState.accepted` forgets them when the name changes)."""

    who: str | None = None
    labelled: list[Key] = field(default_factory=list)


class SiblingTabs(Protocol):
    tab_memory: dict[str, TabMemory]  # by tab id

    def tab_id(self, session: LabelerSession, tab: str) -> str:
        """The id `session` goes by, given the one its page keeps (a duplicated tab gets its own)."""
        ...

    def shown(self, session: LabelerSession, key: Key) -> None:
        """`session` put `key` on screen: the labeler's other tabs no longer label or release it."""
        ...

    def preloaded(self, session: LabelerSession, key: Key) -> None:
        """`session` holds `key` to show next: a closed tab of the labeler (in its grace period) no
        longer releases it. An open one that shows it keeps it (the first to show a segment takes it)."""
        ...

    def done(self, session: LabelerSession, key: Key, skipped: bool) -> None:
        """A label (or skip) of `key` sent from `session` was taken: a tab that shows it moves on."""
        ...

    def released(self, session: LabelerSession, keys: list[Key]) -> None:
        """`session` closed and handed `keys` back to the pool: a claim may bring them to another tab."""
        ...
