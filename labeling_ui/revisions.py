"""A labeler's own labels back on screen, on the tab's worker: undo (the newest label is withdrawn
and its segment comes back to label again) and relabel (one picked from "my labels" replays; a
label on it is a revision). Which label undo withdraws is the state machine's (tab.py)."""

from __future__ import annotations

from labeling_ui.claims import Claims
from labeling_ui.guarded_tab import GuardedTab
from labeling_ui.presenter import Presenter
from labeling_ui.service import Rejected, ServiceLink
from labeling_ui.tab import Refusal, Withdraw


class Revisions:
    def __init__(self, tab: GuardedTab, claims: Claims, presenter: Presenter) -> None:
        self.tab, self.claims, self.presenter = tab, claims, presenter
        self.panels = presenter.panels

    def undo(self, link: ServiceLink, request_id: str) -> None:
        mine = [(m.run_id, m.query_id) for m in self.presenter.mine if m.in_effect]
        with self.tab as state:
            decision = state.undo_target(mine, request_id)
        if isinstance(decision, Refusal):
            self.panels.notify(decision.title, decision.body, "gray")
        elif isinstance(decision, Withdraw):
            self.withdraw(link, decision)

    def withdraw(self, link: ServiceLink, withdraw: Withdraw) -> None:
        try:
            link.undo(withdraw.run_id, withdraw.query_id, withdraw.request_id)
        except Rejected as exc:
            with self.tab as state:
                state.undo_refused(withdraw)
            self.panels.notify("Cannot undo", str(exc), "red")
            return
        run = link.run(withdraw.run_id)
        segment = self.claims.prepare(run, link.query(withdraw.run_id, withdraw.query_id))
        with self.tab as state:
            state.withdrawn(withdraw, segment)
        self.presenter.player.pause()
        self.panels.notify("Label withdrawn", f"segment {withdraw.query_id} is back: label it again", "blue")
        self.presenter.show_next(link, run)

    def relabel(self, link: ServiceLink, query_id: str) -> None:
        """Replay one of this labeler's labelled segments; a label on it is a revision."""
        picked = next((m for m in self.presenter.mine if m.query_id == query_id), None)
        if picked is None:
            self.panels.notify("Not yours", f"segment {query_id} is not among your labels", "orange")
            return
        run = link.run(picked.run_id)
        segment = self.claims.prepare(run, link.query(picked.run_id, query_id))
        with self.tab as state:
            state.relabelling(segment)
        self.presenter.present(link, segment)
