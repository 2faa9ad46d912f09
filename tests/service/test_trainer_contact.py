"""runs.trainer_seen_at: a run's own trainer calling the service is noted (its event poll
included); another trainer, a labeler or an operator calling about the run is not."""

from __future__ import annotations

from backend.server import BackgroundServer
from collie.client import CollieClient

from .conftest import make_run_spec


def test_only_the_runs_own_trainer_counts_as_heard(
    live: BackgroundServer, trainer: CollieClient, labeler: CollieClient, operator: CollieClient
) -> None:
    run = trainer.create_run(make_run_spec())
    assert run.trainer_seen_at is None  # creating it is not a call about it (no run id in the path yet)
    labeler.events(run.id)
    operator.events(run.id)
    assert operator.run(run.id).trainer_seen_at is None
    other = operator.create_labeler("other-trainer", role="trainer")
    with CollieClient(live.url, other.token) as stranger:
        stranger.events(run.id)  # reading a run's stream is open to every role
    assert operator.run(run.id).trainer_seen_at is None
    trainer.events(run.id, wait_s=0.0)  # the trainer's poll between epochs
    seen = operator.run(run.id).trainer_seen_at
    assert seen is not None and seen >= run.created_at
    assert any(r.id == run.id and r.trainer_seen_at == seen for r in operator.runs())
