"""What one tab's session tells, and asks, the labeler's other tabs (the app keeps them all): the id
it goes by, that it showed a segment, that a label or skip of one landed, that it handed claims
back. Tabs of one labeler that go by one id (a reload and the connection it replaced) share that
id's claims at the service, so each must hear what the others did with them."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from labeling_ui.tab import Key

if TYPE_CHECKING:
    from labeling_ui.session import LabelerSession


class SiblingTabs(Protocol):
    tab_labels: dict[str, list[Key]]  # each tab's labels by tab id, kept across the tab's reloads

    def tab_id(self, session: LabelerSession, tab: str) -> str:
        """The id `session` goes by, given the one its page keeps (a duplicated tab gets its own)."""
        ...

    def shown(self, session: LabelerSession, key: Key) -> None:
        """`session` put `key` on screen: the labeler's other tabs no longer label or release it."""
        ...

    def done(self, session: LabelerSession, key: Key, skipped: bool) -> None:
        """A label (or skip) of `key` sent from `session` was taken: a tab that shows it moves on."""
        ...

    def released(self, session: LabelerSession, keys: list[Key]) -> None:
        """`session` closed and handed `keys` back to the pool: a claim may bring them to another tab."""
        ...
