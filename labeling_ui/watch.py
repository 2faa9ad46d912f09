"""The skills of a run's latest evaluation replayed in 3D from the simulator states the trainer
posted with it, one after another: watch mode (`?watch=RUN`, the dashboard's "watch skills in 3D"
link), and the waiting screen's 3D view while nothing is claimable. Nothing is claimed or labelled;
a newer evaluation replaces the skills as it arrives.

Driven by the tab's worker (reload on a stream wake-up, tick while idle) and, in watch mode, by
its own buttons (viser's threads: hence its lock); it draws through the tab's screen methods
(show_skill, show_notice, replay_finished, set_replay_loop), never touches the session's state,
and reaches the session only through the `watch_stream` method it is given. The trainer posts every
`stride`-th state of each evaluation rollout (Rollout.stride), so a rollout replays at 1/stride of
the segment frame rate to keep real time.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from collie.schemas import RolloutsRead, RunRead
from labeling_ui.models import ModelError, Poser, replay_model
from labeling_ui.panels import skill_text
from labeling_ui.service import Rejected, ServiceLink

if TYPE_CHECKING:
    from labeling_ui.screen import TabScreen


class SkillShow:
    def __init__(
        self, screen: TabScreen, run_id: int, fps: float, watch_stream: Callable[[int, int], None] | None
    ) -> None:
        """`watch_stream(run, after)`: watch mode (its own controls; the tab wakes on the run's
        stream); None: the waiting screen's view (the tab already waits on that stream)."""
        self.screen = screen
        self.run_id = run_id
        self.fps = fps  # of segments; a rollout plays at fps / its stride
        self.watch_stream = watch_stream
        self.watch = watch_stream is not None
        self.rollouts: RolloutsRead | None = None
        self.run: RunRead | None = None
        self.index = 0
        self.auto = True  # the next skill when one ends
        self._lock = threading.Lock()  # the worker and the skill buttons (watch mode) both move it
        self._controls = False  # watch mode's skill buttons, added once the run is known

    def reload(self, link: ServiceLink) -> None:
        """Fetch the latest evaluation; show it if it is new. Watch mode of a run the service does not
        have (or this token may not see) says so alone on screen: no label controls, no skill buttons."""
        try:
            run = link.run(self.run_id)
        except Rejected as exc:
            if not self.watch:
                raise
            self.screen.show_alone(f"⚠️ **Cannot watch run {self.run_id}**: {exc}.")
            return
        if self.watch and not self._controls:
            self.screen.panels.add_skill_controls(self)
            self._controls = True
        if self.watch_stream is not None:
            self.watch_stream(run.id, run.last_event_id)
        latest = link.latest_rollouts(self.run_id)
        if latest is None or not any(r.qpos for r in latest.rollouts):
            self.screen.show_notice(
                f"🎥 **No evaluation to replay yet** for run {run.id} ({run.env}, {run.task}, {run.status}, "
                f"epoch {run.epoch}).  \nThe skills appear here by themselves after the next evaluation.",
                self.watch,
            )
            return
        with self._lock:
            self.run = run
            if self.rollouts is not None and latest.id == self.rollouts.id:
                return
            self.rollouts = latest
            self._show(self.index)

    def tick(self) -> None:
        with self._lock:
            if self.auto and self.rollouts is not None and self.screen.replay_finished():
                self._show(self.index + 1)

    def set_auto(self, on: bool) -> None:
        with self._lock:
            self.auto = on
            self.screen.set_replay_loop(not on)

    def step(self, by: int) -> None:
        """The previous (-1) or next (+1) skill: watch mode's buttons."""
        with self._lock:
            self._show(self.index + by)

    def _show(self, index: int) -> None:
        """Replay skill `index` (wrapping around) of the latest evaluation (the lock held)."""
        if self.rollouts is None or self.run is None:
            return
        skills = [r for r in self.rollouts.rollouts if r.qpos]
        self.index = index % len(skills)
        rollout, run, epoch = skills[self.index], self.run, self.rollouts.epoch
        try:
            poser = Poser(replay_model(run.env), np.asarray(rollout.qpos, float))
        except ModelError as exc:
            self.screen.show_notice(f"⚠️ **Run {run.id}'s skills cannot be replayed**: {exc}", self.watch)
            return
        self.screen.set_replay_loop(not self.auto)
        where = f"**{self.index + 1} / {len(skills)}** · evaluation at epoch {epoch}"
        self.screen.show_skill(
            run,
            poser,
            np.asarray(rollout.xy, float),
            self.fps / rollout.stride,
            f"Watching run {run.id}: skill **{self.index + 1} / {len(skills)}**",
            f"Skill {where}  \nz = {skill_text(rollout.skill)}  \n"
            f"**run** {run.id} · {run.env} · {run.method} · **states** {poser.n_frames}, every {rollout.stride} steps",
            self.watch,
        )
