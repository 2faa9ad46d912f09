"""What one tab draws: the panels, the hotkeys, the 3D scene and the player, and the pieces of a
screen that several states share (the task and its floor, an evaluation skill, a notice). It
decides nothing: the session says what to show."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import viser

from collie.dashboard_schemas import QueryReview
from collie.schemas import RunRead
from collie.tasks import Task
from labeling_ui.inset import render_inset
from labeling_ui.keys import bind_keys
from labeling_ui.models import Poser
from labeling_ui.panels import Actions, Panels
from labeling_ui.playback import Player
from labeling_ui.regions import tint_grid, tint_meshes
from labeling_ui.rule import run_task
from labeling_ui.scene import ReplayScene

FLOOR_HALF_WIDTH = 20.0  # the region tint on the 3D floor spans this far around the segment...
FLOOR_SNAP = 10.0  # ...whose centre snaps to this grid, so nearby segments share one tint


class TabScreen:
    def __init__(
        self, client: viser.ClientHandle, actions: Actions, fps: float, drawn: Callable[[float], None]
    ) -> None:
        """`drawn(position)` hears every frame the player draws (from the player's thread)."""
        self.client = client
        self.panels = Panels(client, actions)
        bind_keys(client, actions)
        self.scene = ReplayScene(client)
        self.player = Player(self._render, self.panels.show_frame, fps=fps)
        self._drawn = drawn
        self._tasks: dict[int, Task | None] = {}  # run id → its stored rule

    def _render(self, position: float) -> None:
        self.scene.show(position)
        self._drawn(position)

    def blank(self) -> None:
        """No robot on screen."""
        self.player.unload()
        self.scene.hide()

    def task_of(self, run: RunRead) -> Task | None:
        """The run's rule from the service's copy (fixed for the run's life, so cached by run id);
        None for a run without a rule (an instruction) or one whose rule cannot be read."""
        if run.id not in self._tasks:
            self._tasks[run.id] = run_task(run)
        return self._tasks[run.id]

    def show_floor(self, run: RunRead, task: Task | None, xy: np.ndarray) -> None:
        """The task's regions on the floor around the segment, recomputed only when the segment
        leaves the area they cover (centres snap to a coarse grid)."""
        cx, cy = np.round(xy.mean(axis=0) / FLOOR_SNAP) * FLOOR_SNAP
        key = (run.id, run.env, cx, cy)
        if key == self.scene.floor_key:
            return
        tint = tint_meshes(task, cx, cy, FLOOR_HALF_WIDTH)
        self.scene.set_floor(key, task.to_dict() if task else None, tint, tint_grid(cx, cy, FLOOR_HALF_WIDTH))

    def show_task(self, run: RunRead, task: Task | None) -> None:
        if task is not None:
            self.panels.show_task(task, run.instructions)
        elif run.instruction is not None:
            self.panels.show_instruction(run.instruction, run.instructions)
        else:
            self.panels.show_unknown_task(run.task, run.env, run.instructions)

    def show_skill(
        self, run: RunRead, poser: Poser, xy: np.ndarray, fps: float, status: str, detail: str, watching: bool
    ) -> None:
        """Replay one evaluation skill: watch mode's screen, or the waiting screen's 3D view."""
        self.scene.load(run.env)
        self.player.fps = fps
        with self.client.atomic():
            self.scene.set_segment(poser, None)
            self.player.load(poser.n_frames)
            if watching:
                self.panels.show_replay_only(status, detail, poser.n_frames)
            else:
                self.panels.show_skills_while_waiting(detail, poser.n_frames)
        self.client.flush()
        task = self.task_of(run)
        self.show_floor(run, task, xy)
        self.show_task(run, task)
        self.panels.show_inset(render_inset(task, xy, None))

    def show_review(self, run: RunRead, poser: Poser, review: QueryReview, status: str, detail: str) -> None:
        """Replay one query for an operator's review, on loop (review.py)."""
        query = review.query
        xy = np.asarray(query.xy, float)
        earlier = np.asarray(query.path_xy, float)[: query.start + 1] if query.path_xy else None
        self.scene.load(run.env)
        self.player.loop = True
        with self.client.atomic():
            self.scene.set_segment(poser, earlier)
            self.player.load(poser.n_frames)
            self.panels.show_replay_only(status, detail, poser.n_frames, rule=True)
            self.panels.loop.value = True  # type: ignore[misc]  # viser types .value read-only; it is settable
        self.client.flush()
        task = self.task_of(run)
        self.show_floor(run, task, xy)
        self.show_task(run, task)
        self.panels.show_inset(render_inset(task, xy, earlier))

    def show_alone(self, message: str) -> None:
        """Only a message: no robot, no label buttons (a review that cannot be shown)."""
        self.blank()
        self.panels.show_alone(message)

    def show_notice(self, message: str, watching: bool) -> None:
        self.blank()
        if watching:
            self.panels.show_message(message)

    def replay_finished(self) -> bool:
        p = self.player
        return p.n_frames > 1 and not p.playing and p.position >= p.n_frames - 1

    def set_replay_loop(self, loop: bool) -> None:
        self.player.loop = loop
        self.panels.loop.value = loop  # type: ignore[misc]  # viser types .value read-only; it is settable
