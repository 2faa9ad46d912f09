"""runs.trainer_seen_at: a trainer process's calls about its run are noted (its event poll
included), with the run's own trainer token or an operator's (which may drive a resumed trainer);
other callers, and the same tokens outside a trainer process, are not."""

from __future__ import annotations

from backend.server import BackgroundServer
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
