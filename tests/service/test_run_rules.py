"""A run's rule on the service: stored as posted (or the built-in's, by name), or only an
instruction; a malformed definition is refused; a database from before definitions upgrades and
its runs are still judged by their built-in task."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from backend.db import Database
from backend.main import create_app
from backend.migrate import upgrade
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import StatusEvent
from collie.task_schemas import TaskDefinition
from collie.tasks import get_task, task_for_run, to_definition

from .conftest import TOKENS, database_at, make_run_spec, make_session, settings_for

POLYGON = {
    "name": "pit",
    "description": "Keep out of the pit.",
    "regions": [{"kind": "polygon", "desirability": 0, "vertices": [[0, 0], [2, 0], [0, 2]]}],
}


def test_a_builtin_name_stores_its_definition(trainer: CollieClient, labeler: CollieClient) -> None:
    run = trainer.create_run(make_run_spec(task="range"))
    assert run.task_definition == to_definition(get_task("range", "point"), source="builtin")
    seen = labeler.run(run.id)  # every client reads the same stored copy
    assert seen.task_definition == run.task_definition and seen.instruction is None


def test_a_run_of_no_known_env_or_task_is_refused(live: BackgroundServer) -> None:
    """Its labelers could not replay it or would have nothing to judge it by."""
    body = make_run_spec().model_dump(mode="json")
    headers = {"Authorization": f"Bearer {TOKENS['trainer']}"}
    before = httpx.get(f"{live.url}/api/runs", headers=headers).json()
    for change, said in (
        ({"env": "moon"}, "Input should be 'point', 'ant', 'half_cheetah', 'quadruped', 'humanoid' or 'car'"),
        ({"task": "no_such_task"}, "unknown task 'no_such_task'; valid tasks: north,"),
        ({"task": "not_flip"}, "task 'not_flip' is not defined for env 'point'"),
        (  # it runs on a line
            {"env": "half_cheetah", "dims": {**body["dims"], "nq": 9, "nv": 9}},
            "task 'range_north' is not defined for env 'half_cheetah'",
        ),
    ):
        answer = httpx.post(f"{live.url}/api/runs", json={**body, **change}, headers=headers)
        assert answer.status_code == 422 and said in answer.text, answer.text
    assert httpx.get(f"{live.url}/api/runs", headers=headers).json() == before  # nothing half-made


def test_a_posted_definition_or_an_instruction_is_kept_as_posted(trainer: CollieClient) -> None:
    definition = TaskDefinition.model_validate(POLYGON)
    run = trainer.create_run(make_run_spec(task="pit").model_copy(update={"task_definition": definition}))
    assert run.task_definition == definition and task_for_run(run).regions[0].kind == "polygon"  # type: ignore[union-attr]
    words = trainer.create_run(make_run_spec(task="instruction").model_copy(update={"instruction": "stay west"}))
    assert words.instruction == "stay west" and words.task_definition is None and task_for_run(words) is None
    listed = {r.id: r for r in trainer.runs()}
    assert listed[run.id].task_definition == definition and listed[words.id].instruction == "stay west"


def test_a_malformed_definition_is_refused(live: BackgroundServer) -> None:
    body = make_run_spec().model_dump(mode="json")
    headers = {"Authorization": f"Bearer {TOKENS['trainer']}"}
    for broken in (
        {**POLYGON, "regions": [{"kind": "circle", "desirability": 0}]},
        {**POLYGON, "regions": [{"kind": "polygon", "desirability": 0, "vertices": [[0, 0], [1, 1], [2, 2]]}]},
        {"name": "x", "regions": []},
    ):
        response = httpx.post(f"{live.url}/api/runs", json={**body, "task_definition": broken}, headers=headers)
        assert response.status_code == 422, response.text
    both = {**body, "task_definition": POLYGON, "instruction": "stay west"}
    assert httpx.post(f"{live.url}/api/runs", json=both, headers=headers).status_code == 422


def test_a_definition_of_another_name_than_the_task_is_refused(live: BackgroundServer) -> None:
    """Was 201: the run read as task north but was judged by the rule named pit."""
    headers = {"Authorization": f"Bearer {TOKENS['trainer']}"}
    before = httpx.get(f"{live.url}/api/runs", headers=headers).json()
    body = {**make_run_spec(task="north").model_dump(mode="json"), "task_definition": POLYGON}
    answer = httpx.post(f"{live.url}/api/runs", json=body, headers=headers)
    assert answer.status_code == 422 and "task 'north' and its task_definition (named 'pit')" in answer.text
    assert httpx.get(f"{live.url}/api/runs", headers=headers).json() == before


def test_a_0002_database_upgrades_and_its_runs_keep_their_builtin_rule(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    database_at(path, "0002", "hole")
    db = Database(f"sqlite:///{path}")
    upgrade(db.engine)
    db.dispose()
    with (
        BackgroundServer(create_app(settings_for(path))) as server,
        CollieClient(server.url, TOKENS["labeler"]) as c,
        CollieClient(server.url, TOKENS["operator"]) as operator,
    ):
        old = c.run(1)
        operator.post_session(1, make_session(0, 1))
        c.claim(1)
        with pytest.raises(ApiError, match="run 1's task 'hole' never calls a state good"):  # judged by its name
            c.submit(1, "0-0", 2)
    assert old.task_definition is None and old.instruction is None
    assert task_for_run(old).to_dict() == get_task("hole", "point").to_dict()  # type: ignore[union-attr]


def test_a_good_label_is_refused_where_the_rule_never_calls_a_state_good(
    live: BackgroundServer, trainer: CollieClient
) -> None:
    """North has no good state (the labeling UI refuses the key); a run whose rule has one, or a run
    with an instruction and no rule, takes all three classes."""
    north = trainer.create_run(make_run_spec(task="north"))
    ranged = trainer.create_run(make_run_spec(task="range_north"))
    words = trainer.create_run(make_run_spec(task="instruction").model_copy(update={"instruction": "stay west"}))
    for run in (north, ranged, words):
        trainer.post_session(run.id, make_session(0, 2))
    headers = {"Authorization": f"Bearer {TOKENS['labeler']}"}
    with CollieClient(live.url, TOKENS["labeler"]) as labeler:
        labeler.claim(north.id)
        answer = httpx.post(
            f"{live.url}/api/runs/{north.id}/labels",
            json={"query_id": "0-0", "value": 2, "client_request_id": "good-on-north"},
            headers=headers,
        )
        assert answer.status_code == 422, answer.text
        assert answer.json()["detail"] == (
            f"run {north.id}'s task 'north' never calls a state good: label the segment 0 (bad) or 1 (neutral)"
        )
        assert labeler.submit(north.id, "0-0", 0).query_status == "labelled"  # the claim stands: nothing half-written
        assert [e.value for e in trainer.label_events(north.id)] == [0]
        for run in (ranged, words):
            labeler.claim(run.id)
            assert labeler.submit(run.id, "0-0", 2).label == 2


def test_a_run_is_extended_only_while_it_may_train_again(trainer: CollieClient, operator: CollieClient) -> None:
    """A finished run reopens for more epochs; a running one only takes the new total; fewer epochs,
    a run an operator stopped and a failed run are refused (409)."""
    finished = trainer.create_run(make_run_spec().model_copy(update={"epochs_total": 6}))
    trainer.set_status(finished.id, "finished", epoch=6)
    reopened = trainer.extend(finished.id, 10)
    assert (reopened.status, reopened.epoch, reopened.epochs_total) == ("training", 6, 10)
    status = [e.data for e in trainer.events(finished.id).events if isinstance(e, StatusEvent)][-1]
    assert (status.status, status.message) == ("training", "extended to 10 epochs")
    running = trainer.create_run(make_run_spec().model_copy(update={"epochs_total": 6}))
    trainer.set_status(running.id, "training", epoch=3)
    last = trainer.events(running.id).last_id
    assert (trainer.extend(running.id, 8).status, trainer.run(running.id).epochs_total) == ("training", 8)
    assert trainer.events(running.id, after=last).events == []  # nothing to tell the stream
    with pytest.raises(ApiError, match="extending means more, not 7"):
        trainer.extend(running.id, 7)
    stopped = trainer.create_run(make_run_spec().model_copy(update={"epochs_total": 6}))
    operator.stop(stopped.id)
    trainer.set_status(stopped.id, "finished", epoch=2, message="stopped by an operator")
    with pytest.raises(ApiError, match="was stopped by an operator: it is not extended"):
        trainer.extend(stopped.id, 10)
    failed = trainer.create_run(make_run_spec().model_copy(update={"epochs_total": 6}))
    trainer.set_status(failed.id, "failed", epoch=2)
    with pytest.raises(ApiError, match="failed: it is not extended"):
        trainer.extend(failed.id, 10)
    assert [trainer.run(r.id).status for r in (stopped, failed)] == ["finished", "failed"]
    untold = trainer.create_run(make_run_spec())  # no epochs_total: fewer than it has done are still fewer
    trainer.set_status(untold.id, "finished", epoch=5)
    with pytest.raises(ApiError, match="has done 5 epochs: extending means more, not 2"):
        trainer.extend(untold.id, 2)
    assert (trainer.run(untold.id).status, trainer.run(untold.id).epochs_total) == ("finished", None)
