"""Watch mode (`?watch=RUN`, the dashboard's "watch skills in 3D" link): every skill of the run's
latest evaluation replayed in 3D from the simulator states the trainer posted with it, one skill
after another. Nothing is claimed or labelled; a new evaluation replaces the skills as it arrives.

The trainer posts every `stride`-th state of each evaluation rollout (Rollout.stride), so a rollout
replays at 1/stride of the segment frame rate to keep real time.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

import numpy as np

from collie.schemas import RolloutsRead, RunRead
from labeling_ui.inset import render_inset
from labeling_ui.models import ModelError, Poser, replay_model
from labeling_ui.panels import skill_text

if TYPE_CHECKING:
    from labeling_ui.session import LabelerSession

POLL_S = 0.25  # how often the end of a skill is checked for auto-advance


class SkillWatch:
    """Runs in the tab's worker thread until the tab closes. Buttons move between skills from the
    GUI threads; a second thread long-polls the run's stream for new evaluations."""

    def __init__(self, session: LabelerSession, run_id: int) -> None:
        self.session = session
        self.run_id = run_id
        self.rollouts: RolloutsRead | None = None
        self.watched: RunRead | None = None
        self.index = 0
        self._lock = threading.Lock()
        self._fresh = threading.Event()  # a new evaluation was posted
        self._fresh.set()
        gui = session.client.gui
        with gui.add_folder("Skills") as self.folder:
            self.info = gui.add_markdown("")
            self.move = gui.add_button_group("Skill", options=["◀ previous", "next ▶"])
            self.auto = gui.add_checkbox("Next skill when one ends", initial_value=True)
        self.move.on_click(lambda _: self.show(self.index + (-1 if self.move.value.startswith("◀") else 1)))
        self.auto.on_update(lambda _: self._set_auto(bool(self.auto.value)))

    def run(self) -> None:
        session = self.session
        assert session.link is not None and session.watch_link is not None
        session.panels.title.content = f"**collie · watching run {self.run_id}**"
        watcher = threading.Thread(target=self._watch_stream, name="collie-watch-stream", daemon=True)
        watcher.start()
        while not session.closed.is_set():
            if self._fresh.is_set():
                self._fresh.clear()
                self._reload()
            elif self._finished() and self.auto.value:
                self.show(self.index + 1)
            session.closed.wait(POLL_S)

    def _reload(self) -> None:
        assert self.session.link is not None
        run = self.session.link.run(self.run_id)
        latest = self.session.link.latest_rollouts(self.run_id)
        replayable = latest is not None and any(r.qpos for r in latest.rollouts)
        if not replayable:
            self.session.player.unload()
            self.session.scene.hide()
            self.session.panels.show_message(
                f"🎥 **No evaluation to replay yet** for run {run.id} ({run.env}, {run.task}, {run.status}, "
                f"epoch {run.epoch}).  \nThe skills appear here by themselves after the next evaluation."
            )
            return
        if self.rollouts is not None and latest is not None and latest.id == self.rollouts.id:
            return
        with self._lock:
            self.rollouts, self.watched = latest, run
        self.show(self.index)

    def show(self, index: int) -> None:
        """Replay skill `index` (wrapping around) of the latest evaluation."""
        with self._lock:
            if self.rollouts is None or self.watched is None:
                return
            skills = [r for r in self.rollouts.rollouts if r.qpos]
            self.index = index % len(skills)
            rollout, run, epoch = skills[self.index], self.watched, self.rollouts.epoch
            session = self.session
            try:
                poser = Poser(replay_model(run.env), np.asarray(rollout.qpos, float))
                session.scene.load(run.env)
            except ModelError as exc:
                session.panels.show_message(f"⚠️ **Run {run.id}'s skills cannot be replayed**: {exc}")
                return
            xy = np.asarray(rollout.xy, float)
            session.player.fps = session.config.fps / rollout.stride
            session.player.loop = not self.auto.value
            session.panels.loop.value = session.player.loop  # type: ignore[misc]  # viser: settable
            with session.client.atomic():
                session.scene.set_segment(poser, None)
                session.player.load(poser.n_frames)
                session.panels.show_watch(f"Watching run {run.id}: skill **{self.index + 1} / {len(skills)}**")
                session.panels.frame.max = max(poser.n_frames - 1, 1)
                self.info.content = (
                    f"Skill **{self.index + 1} / {len(skills)}** · evaluation at epoch {epoch}  \n"
                    f"z = {skill_text(rollout.skill)}"
                )
                session.panels.segment.content = (
                    f"**run** {run.id} · {run.env} · {run.method}  \n**evaluation** epoch {epoch}  \n"
                    f"**skill** {self.index + 1} of {len(skills)}: {skill_text(rollout.skill)}  \n"
                    f"**states** {poser.n_frames}, every {rollout.stride} steps"
                )
            session.client.flush()
            task = session.task_of(run)
            session.show_floor(run, task, xy)
            if task is not None:
                session.panels.show_task(task.name, task.description, task.meaning)
            session.panels.show_inset(render_inset(task, xy, None))

    def _set_auto(self, on: bool) -> None:
        self.session.player.loop = not on
        self.session.panels.loop.value = not on  # type: ignore[misc]  # viser types .value read-only; it is settable

    def _finished(self) -> bool:
        player = self.session.player
        return player.n_frames > 1 and not player.playing and player.position >= player.n_frames - 1

    def _watch_stream(self) -> None:
        session = self.session
        after = 0
        while not session.closed.is_set():
            link = session.watch_link
            if link is None:
                return
            try:
                page = link.events(self.run_id, after, session.config.wait_s)
            except Exception:  # down or signed out: the worker reports it; try again shortly
                session.closed.wait(1.0)
                continue
            if any(e.kind == "rollouts" for e in page.events):
                self._fresh.set()
            after = page.last_id
