"""runs.trainer_seen_at: a trainer process's calls about its run are noted (its event poll
included), with the run's own trainer token or an operator's (which may drive a resumed trainer);
other callers, and the same tokens outside a trainer process, are not."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from backend.db import Database
from backend.migrate import upgrade
from backend.server import BackgroundServer
from backend.services.auth import Caller
from backend.services.trainer_contact import TrainerContact
from collie.client import CollieClient

from .conftest import TOKENS, make_run_spec


def test_only_a_trainer_process_of_the_run_counts_as_heard(
    live: BackgroundServer, trainer: CollieClient, labeler: CollieClient, operator: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec())
    again = trainer.create_run(make_run_spec())
    assert run.trainer_seen_at is None  # creating it is not a call about it (no run id in the path yet)
    trainer.events(run.id)  # the trainer's token, but not a trainer process (no part header)
    labeler.events(run.id)
    operator.events(run.id)  # the dashboard, the labeling UI's watch mode
    other = operator.create_labeler("other-trainer", role="trainer")
    with CollieClient(live.url, other.token, part="trainer") as stranger:
        stranger.events(run.id)  # reading a run's stream is open to every role: not its trainer
    assert operator.run(run.id).trainer_seen_at is None
    with CollieClient(live.url, TOKENS["trainer"], part="trainer") as process:
        process.events(run.id, wait_s=0.0)  # its poll between epochs
    seen = operator.run(run.id).trainer_seen_at
    assert seen is not None and seen >= run.created_at
    assert any(r.id == run.id and r.trainer_seen_at == seen for r in operator.runs())
    with CollieClient(live.url, TOKENS["operator"], part="trainer") as resumed:  # a trainer resumed by an operator
        resumed.events(again.id)
    assert operator.run(again.id).trainer_seen_at is not None


def test_turns_of_runs_that_do_not_exist_do_not_pile_up(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every GET a trainer process sends about a run noted a turn, kept for good. Was: one entry per
    run id ever named, so a loop over ids that exist nowhere grew the service without end."""
    monkeypatch.setattr(TrainerContact, "KEPT", 16, raising=False)
    db = Database(f"sqlite:///{tmp_path / 'contact.db'}", synchronous="NORMAL")
    upgrade(db.engine)
    contact = TrainerContact(every_s=0.05)
    caller = Caller(id=1, name="t", role="trainer")
    for run_id in range(1, 200):
        contact.heard(db, run_id, caller)
        if run_id % 20 == 0:
            time.sleep(0.06)  # the turns noted so far are over
    assert len(contact._written) <= 16 + 20
