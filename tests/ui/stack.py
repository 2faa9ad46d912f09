"""A real stack for the labeling-UI tests and benchmark: the labeling service (uvicorn on an
ephemeral port over a SQLite file), runs whose segments are rolled out in the real envs, and the
labeling UI's viser server on port 0."""

from __future__ import annotations

import math
import sqlite3
from collections.abc import Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from service.conftest import TOKENS, settings_for

from backend.main import create_app
from backend.server import BackgroundServer
from collie.client import CollieClient
from collie.frames import pack_frames
from collie.schemas import EnvDims, QueryIn, RunCreate, RunRead, SessionPost
from labeling_ui.app import LabelingApp
from labeling_ui.session import UiConfig
from trainer.envs import make_env

HORIZON = 20
SKILL_DIM = 2


def rollout_queries(env_name: str, session: int, n: int, seed: int = 0, episode: int = 60) -> list[QueryIn]:
    """n segments of HORIZON states, each from its own episode, walking with a steady random
    direction so the robot visibly moves; path_xy holds the whole episode for context."""
    env = make_env(env_name, seed=seed, episode_steps=episode)
    rng = np.random.default_rng(seed + 1000 * session)
    queries = []
    for i in range(n):
        obs, info = env.reset(seed=seed + 100 * session + i)
        bias = rng.uniform(-1, 1, env.action_dim)
        rows = [(obs, info)]
        for _ in range(episode):
            action = np.clip(bias + 0.3 * rng.normal(size=env.action_dim), -1, 1)
            obs, _, _, _, info = env.step(action)
            rows.append((obs, info))
        start = int(rng.integers(0, episode + 1 - HORIZON))
        window = rows[start : start + HORIZON]
        angle = rng.uniform(0, 2 * math.pi)
        pitch = [None if math.isnan(r[1]["pitch"]) else float(r[1]["pitch"]) for r in window]
        queries.append(
            QueryIn(
                query_id=f"{session}-{i}",
                start=start,
                skill=[math.cos(angle), math.sin(angle)],
                obs=[] if window[0][0].ndim > 1 else [r[0].astype(float).tolist() for r in window],
                obs_packed=pack_frames(np.stack([r[0] for r in window])) if window[0][0].ndim > 1 else None,
                xy=[r[1]["xy"].tolist() for r in window],
                pitch=pitch,
                qpos=[r[1]["qpos"].tolist() for r in window],
                qvel=[r[1]["qvel"].tolist() for r in window],
                path_xy=[r[1]["xy"].tolist() for r in rows],
            )
        )
    return queries


def dims_of(env_name: str) -> EnvDims:
    env = make_env(env_name, seed=0, episode_steps=1)
    return EnvDims(obs_dim=env.obs_dim, nq=env.nq, nv=env.nv, horizon=HORIZON, skill_dim=SKILL_DIM)


@dataclass
class Stack:
    service: BackgroundServer
    trainer: CollieClient
    operator: CollieClient
    apps: list[LabelingApp] = field(default_factory=list)
    db: Path | None = None  # the service's SQLite file

    @property
    def api(self) -> str:
        return self.service.url

    def new_labeler(self, name: str) -> str:
        """A labeler token of their own (each browser labels as a different person)."""
        return self.operator.create_labeler(name).token

    def post_run(
        self,
        env: str,
        n_queries: int,
        task: str = "north",
        seed: int = 0,
        rollout_env: str | None = None,
        redundancy: int | None = None,
        n_total: int | None = None,
    ) -> RunRead:
        """A run waiting for labels with one session of n_queries segments, rolled out in `env`
        (or in `rollout_env`, to make a run whose model cannot pose its segments); `redundancy`: labels
        per query, where the service has that run setting (RunCreate.redundancy); `n_total`: its
        budget, the most queries the service stores for it (default: 100, or n_queries if more)."""
        rollout_env = rollout_env or env
        extra: dict[str, object] = {}
        if redundancy is not None:
            if "redundancy" not in RunCreate.model_fields:
                raise ValueError("this service has no redundancy run setting (RunCreate.redundancy)")
            extra["redundancy"] = redundancy
        budget = max(100, n_queries) if n_total is None else n_total
        spec = RunCreate(
            env=rollout_env, task=task, method="collie", dims=dims_of(rollout_env), n_total=budget, **extra
        )
        run = self.trainer.create_run(spec)
        if rollout_env != env:  # the service takes no such run now: one stored before it checked dims
            assert self.db is not None
            with closing(sqlite3.connect(self.db)) as conn, conn:
                conn.execute("UPDATE runs SET env = ? WHERE id = ?", (env, run.id))
        if n_queries:
            self.post_session(run.id, rollout_env, 0, n_queries, seed)
        self.trainer.set_status(run.id, "waiting_for_labels", epoch=3)
        return self.trainer.run(run.id)

    def post_session(self, run_id: int, env: str, session: int, n: int, seed: int = 0) -> None:
        queries = rollout_queries(env, session, n, seed)
        self.trainer.post_session(run_id, SessionPost(session=session, epoch=3, queries=queries))

    def ui(self, run_id: int | None = None, **config: object) -> LabelingApp:
        """A labeling UI on a free port, pinned to one run so tests do not see each other's runs."""
        app = LabelingApp(UiConfig(api=self.api, run_id=run_id, **config), port=0)  # type: ignore[arg-type]
        self.apps.append(app)
        return app


@contextmanager
def real_stack(db: Path) -> Iterator[Stack]:
    with (
        BackgroundServer(create_app(settings_for(db))) as service,
        CollieClient(service.url, TOKENS["trainer"]) as trainer,
        CollieClient(service.url, TOKENS["operator"]) as operator,
    ):
        stack = Stack(service, trainer, operator, db=db)
        try:
            yield stack
        finally:
            for app in stack.apps:
                app.stop()
