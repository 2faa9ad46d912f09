"""Runs whose rule comes from a file, and runs with no rule at all, end to end with the real parts:
`collie up` (service, trainer, oracle teacher, labeling UI as processes) with a polygon spec file,
and a trainer on a live service labelled by a scripted person (not the oracle) by an instruction.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
import torch
from service.conftest import TOKENS, settings_for

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import ApiError, CollieClient
from collie.schemas import FINISHED
from collie.task_schemas import TaskDefinition
from collie.tasks import BAD, from_definition
from collie.teacher import segment_label
from labeling_ui.regions import TINT_RGB, region_outline, tint_meshes
from labeling_ui.rule import rule_text, run_task
from trainer.downstream.__main__ import run_downstream
from trainer.metrics import coverage_metrics

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

RULE_METRICS = (
    "safe_coverage",
    "safe_ratio",
    "composite_coverage",
    "weighted_composite_coverage",
    "n_bad_bins",
    "n_neutral_bins",
    "n_good_bins",
)
# a wedge east of the start (|y| < x, up to x = 40): bad; elsewhere neutral
EAST_WEDGE = [[0.0, 0.0], [40.0, -40.0], [40.0, 40.0]]
SPEC = f"""\
name = "east_wedge"
description = "Keep out of the wedge east of the start."
background = "neutral"

[meaning]
bad = "inside the east wedge"
neutral = "anywhere else"

[[regions]]
kind = "polygon"
name = "wedge"
desirability = "bad"
vertices = {json.dumps(EAST_WEDGE)}
"""


def cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "collie.cli", *args], capture_output=True, text=True, timeout=timeout)


def test_a_polygon_spec_file_runs_through_collie_up_with_the_oracle(tmp_path: Path) -> None:
    spec = tmp_path / "east_wedge.toml"
    spec.write_text(SPEC)
    proc = cli(
        "up", "--env", "point", "--task-file", str(spec), "--teacher", "oracle", "--preset", "smoke",
        "--port", "0", "--ui-port", "0", "--out", str(tmp_path / "up"), "--info-json", str(tmp_path / "info.json"),
        "--exit-when-done",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    spec.write_text(SPEC.replace("40.0", "1.0"))  # edited after the run started: changes nothing below
    out = tmp_path / "up" / "trainer"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["n_labels"] == summary["config"]["total_queries"]
    assert summary["config"]["task"] == "east_wedge"

    # The oracle labelled by the polygon: every applied label is the rule's verdict on the segment.
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    wedge = from_definition(TaskDefinition.model_validate(json.loads((out / "task.json").read_text())["definition"]))
    applied = {q: s["label"] for q, s in ckpt["labelled"].items()}
    verdicts = {q: segment_label(wedge.classify(np.asarray(ckpt["segment_xy"][q]))) for q in applied}
    assert applied == verdicts and len(applied) == summary["config"]["total_queries"]

    # The metrics used it: recomputed from the final evaluation's paths with the stored rule.
    last = json.loads((out / "metrics.jsonl").read_text().splitlines()[-1])
    final = np.load(out / "eval_latest.npz")
    again = coverage_metrics(list(final["xy"]), list(final["pitch"]), wedge)
    assert {k: last[k] for k in RULE_METRICS} == pytest.approx({k: again[k] for k in RULE_METRICS})

    # The service holds the definition; the labeling UI and the dashboard draw from that copy.
    with BackgroundServer(create_app(settings_for(tmp_path / "up" / "collie.db"))) as server:
        with CollieClient(server.url, TOKENS["labeler"]) as labeler:
            run = labeler.run(json.loads((tmp_path / "info.json").read_text())["run_id"])
        page = httpx.get(
            f"{server.url}/api/dashboard/runs/{run.id}", headers={"Authorization": f"Bearer {TOKENS['operator']}"}
        ).json()
    assert run.task_definition is not None and run.task_definition.source == "east_wedge.toml"
    task = run_task(run)
    assert task is not None and rule_text(run, task)[:2] == ("east_wedge", "Keep out of the wedge east of the start.")
    outline = region_outline(task.to_dict()["regions"][0])
    assert outline is not None
    assert {tuple(p) for p in outline[:, :2].round(6).tolist()} >= {tuple(v) for v in EAST_WEDGE}
    tinted = {rgb for rgb, _, _ in tint_meshes(task, 10.0, 0.0, 20.0)}
    assert TINT_RGB[BAD] in tinted  # the bad wedge is tinted on the floor
    assert page["task"]["regions"] == [{"kind": "polygon", "desirability": 0, "vertices": EAST_WEDGE}]
    assert page["labeling"]["judged"] == summary["n_labels"] and page["labeling"]["agreement"] == 1.0


def person_label(xy: list[list[float]]) -> int:
    """A scripted person with an intent of their own ("stay west"): bad when the segment ends east."""
    return 0 if xy[-1][0] > 0.0 else 1


def test_an_instruction_only_run_learns_from_people_and_shows_only_rule_free_metrics(tmp_path: Path) -> None:
    instruction = "Keep the robot away from the east side"
    with BackgroundServer(create_app(settings_for(tmp_path / "collie.db"))) as server:
        out = tmp_path / "trainer"
        trainer = subprocess.Popen(
            [sys.executable, "-m", "collie.cli", "train", "--env", "point", "--instruction", instruction,
             "--preset", "smoke", "--out", str(out), "--api", server.url, "--token", TOKENS["trainer"],
             "--no-progress"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        given: dict[str, int] = {}
        with CollieClient(server.url, TOKENS["labeler"]) as person:
            while not (out / "service_run.json").exists():
                assert trainer.poll() is None, trainer.stdout.read()  # type: ignore[union-attr]
                time.sleep(0.1)
            run_id = json.loads((out / "service_run.json").read_text())["run_id"]
            refused = cli("teacher", "--api", server.url, "--token", TOKENS["labeler"], "--run", str(run_id))
            while trainer.poll() is None:
                try:
                    claim = person.claim(run_id)
                except ApiError as exc:  # the run finished between the poll and the claim
                    assert exc.status == 409
                    trainer.wait(60)
                    break
                if claim is None:
                    time.sleep(0.1)
                    continue
                given[claim.query.query_id] = person_label(claim.query.xy)
                person.submit(run_id, claim.query.query_id, given[claim.query.query_id])  # type: ignore[arg-type]
            log = trainer.stdout.read()  # type: ignore[union-attr]
            assert trainer.returncode == 0, log[-3000:]
            memo = out / "service_run.json"
            assert f"collie train: created run {run_id} on {server.url} (remembered in {memo})" in log
            # --no-progress: the wait for people is said, not silence (was: nothing until the next evaluation)
            waits = re.findall(r"^epoch (\d+)/\d+ · waiting for labels \(feedback session (\d+)\)$", log, re.M)
            assert (
                waits
                and waits[0][1] == "0"
                and len(re.findall(r"^epoch \d+/\d+ · labels in · ", log, re.M)) == len(waits)
            )
            run = person.run(run_id)
        page = httpx.get(
            f"{server.url}/api/dashboard/runs/{run_id}", headers={"Authorization": f"Bearer {TOKENS['operator']}"}
        ).json()

    # The oracle teacher refuses a run without a rule, clearly.
    assert refused.returncode == 2 and "has no task rule" in refused.stderr and instruction in refused.stderr

    # The run holds the instruction and no rule; the trainer applied the person's labels.
    assert run.status in FINISHED and run.instruction == instruction and run.task_definition is None
    assert run.task == "instruction"
    saved = json.loads((out / "config.json").read_text())  # a default fixed for this machine, in both copies
    assert isinstance(saved["fast_ops"], bool) and run.config["fast_ops"] is saved["fast_ops"]
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    applied = {q: s["label"] for q, s in ckpt["labelled"].items()}
    assert applied == given and len(given) == ckpt["config"]["total_queries"]

    # Rule-free metrics are there; no rule-based one appears anywhere (metrics.jsonl, summary, service).
    records = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    summary = json.loads((out / "summary.json").read_text())
    last = records[-1]
    assert last["n_bins"] > 0 and last["n_states"] > 0 and last["n_labels"] == len(given)
    counts = [sum(v == c for v in given.values()) for c in (0, 1, 2)]
    assert [last["n_labels_bad"], last["n_labels_neutral"], last["n_labels_good"]] == counts
    assert 0.0 <= last["w_min"] <= last["w_mean"] <= last["w_max"]  # w(s) over the evaluation rollouts
    series = page["metrics"]["series"]
    assert {"n_bins", "n_labels_bad", "w_mean"} <= set(series)
    for key in RULE_METRICS:
        assert all(key not in r for r in records) and key not in summary and key not in series, key
    assert json.loads((out / "task.json").read_text()) == {"definition": None, "instruction": instruction}
    assert (out / "skills_latest.png").stat().st_size and (out / "guidance_latest.png").stat().st_size  # the maps

    # The dashboard: the instruction, no regions, no oracle verdicts, and the map's labelled states.
    assert page["task"] is None and page["task_error"] is None and page["run"]["instruction"] == instruction
    assert page["labeling"]["judged"] == 0 and page["labeling"]["agreement"] is None
    assert page["labelled"] and all(s["oracle"] is None for s in page["labelled"])
    assert {s["query_id"]: s["label"] for s in page["labelled"]} == given
    assert any("w" in r["extra"] for r in page["rollouts"]["rollouts"])  # the map can colour by w(s)
    if page["rollouts"]["epoch"] == last["epoch"]:  # w_mean is the mean of the same w(s) (sent to 2 decimals)
        shown = [x for r in page["rollouts"]["rollouts"] for x in r["extra"]["w"]]
        assert abs(sum(shown) / len(shown) - last["w_mean"]) < 0.006, (sum(shown) / len(shown), last["w_mean"])
    assert run_task(run) is None and rule_text(run, None)[:2] == ("Instruction", instruction)
    with pytest.raises(ValueError, match="instruction alone: zero-shot motion needs a rule"):
        run_downstream(out, trajectories=2)


def test_a_resumed_run_keeps_its_rule_when_the_file_was_edited(tmp_path: Path) -> None:
    spec, out = tmp_path / "east_wedge.toml", tmp_path / "run"
    spec.write_text(SPEC)
    common = ("train", "--task-file", str(spec), "--preset", "smoke", "--out", str(out), "--no-progress")
    first = cli(*common, "--epochs", "4")
    assert first.returncode == 0, first.stderr[-2000:]
    spec.write_text(SPEC.replace('desirability = "bad"', 'desirability = "good"'))
    again = cli(*common, "--resume", "--epochs", "6")
    assert again.returncode == 0, again.stderr[-2000:]
    stored = TaskDefinition.model_validate(json.loads((out / "task.json").read_text())["definition"])
    assert stored.regions[0].desirability == 0  # still the rule the run started with
    last = json.loads((out / "metrics.jsonl").read_text().splitlines()[-1])
    final = np.load(out / "eval_latest.npz")
    assert last["epoch"] == 6
    again_metrics = coverage_metrics(list(final["xy"]), list(final["pitch"]), from_definition(stored))
    assert last["safe_coverage"] == again_metrics["safe_coverage"] and last["n_good_bins"] == 0
    zero_shot = run_downstream(out, trajectories=4)["zero_shot"]  # judged by the saved rule, not a built-in
    assert zero_shot["trajectories"] == 4 and np.isfinite(zero_shot["mean"])


def test_collie_up_refuses_a_bad_task_file_and_an_oracle_for_an_instruction_before_starting(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('description = "d"\n[[regions]]\nkind = "circle"\ndesirability = 0\n')
    proc = cli("up", "--task-file", str(bad), "--out", str(tmp_path / "a"), "--port", "0", timeout=60)
    assert proc.returncode == 2 and f"task file {bad}: regions[0].kind: unknown region kind 'circle'" in proc.stderr
    proc = cli("up", "--instruction", "stay west", "--teacher", "oracle", "--out", str(tmp_path / "b"), timeout=60)
    assert proc.returncode == 2 and "--teacher oracle labels by a task rule" in proc.stderr
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()  # nothing was started
