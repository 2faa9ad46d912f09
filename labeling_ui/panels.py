"""The labeler's on-screen panels (all client-scoped): sign-in, status, label buttons, progress,
replay controls, keymap (right), and the context a labeler judges by (left): the task, what each
label means, the top-down inset and the segment's run / epoch / skill.

Panels only draw and forward clicks; what a click does is the session's business (`Actions`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import viser

from collie.labels import Label
from labeling_ui.inset import SIZE
from labeling_ui.playback import SPEEDS
from labeling_ui.service import Progress

KEYMAP = (
    "**Keys** · **1** bad · **2** neutral · **3** good · **S** skip (not a label) · **U** undo the last "
    "label · **Space** replay · **P** play / pause · **← →** one frame"
)


class Actions(Protocol):
    """What the panels' buttons ask for; the session implements it."""

    def sign_in(self, token: str) -> None: ...
    def sign_out(self) -> None: ...
    def label(self, value: Label) -> None: ...
    def skip(self) -> None: ...
    def undo(self) -> None: ...
    def replay(self) -> None: ...
    def toggle_play(self) -> None: ...
    def step(self, frames: int) -> None: ...
    def seek(self, frame: float) -> None: ...
    def set_speed(self, speed: float) -> None: ...
    def set_loop(self, loop: bool) -> None: ...
    def set_shadows(self, on: bool) -> None: ...


@dataclass(frozen=True)
class SegmentInfo:
    """What the context panel says about the segment on screen."""

    query_id: str
    run_id: int
    env: str
    task: str
    method: str
    epoch: int
    session: int
    start: int
    skill: list[float]
    n_frames: int


def skill_text(skill: list[float]) -> str:
    values = np.asarray(skill, float)
    if len(values) > 2 and np.isin(values, (0.0, 1.0)).all() and values.sum() == 1:
        return f"{int(values.argmax())} of {len(values)} (discrete)"
    return "(" + ", ".join(f"{v:+.2f}" for v in values) + ")"


class Panels:
    def __init__(self, client: viser.ClientHandle, actions: Actions) -> None:
        self.client = client
        gui = client.gui
        gui.configure_theme(control_width="large", show_logo=False, show_share_button=False, brand_color=(230, 120, 20))
        main = gui.main_panel
        main.dock_right()
        main.set_width(360)

        self.title = gui.add_markdown("**collie · labeling**")
        self.status = gui.add_markdown("Connecting…")

        with gui.add_folder("Sign in", visible=False) as self.login:
            self.token = gui.add_text("Labeler token", initial_value="", hint="the token your operator gave you")
            sign_in = gui.add_button("Sign in", icon=viser.Icon.LOGIN)
        sign_in.on_click(lambda _: actions.sign_in(self.token.value.strip()))

        with gui.add_folder("Label", visible=False) as self.labeling:
            self.query = gui.add_markdown("")
            bad = gui.add_button("1 · Bad", color="red", hint="key 1")
            neutral = gui.add_button("2 · Neutral", color="gray", hint="key 2")
            good = gui.add_button("3 · Good", color="green", hint="key 3")
            skip = gui.add_button("S · Skip", color="dark", hint="key S: not a label; someone else gets it")
            undo = gui.add_button("U · Undo last label", color="dark", hint="key U")
            gui.add_markdown(KEYMAP)
            self.progress = gui.add_markdown("")
            self.session_bar = gui.add_progress_bar(0.0, color="orange")
        bad.on_click(lambda _: actions.label(Label.BAD))
        neutral.on_click(lambda _: actions.label(Label.NEUTRAL))
        good.on_click(lambda _: actions.label(Label.GOOD))
        skip.on_click(lambda _: actions.skip())
        undo.on_click(lambda _: actions.undo())
        self.label_buttons = (bad, neutral, good)
        self.segment_only = (bad, neutral, good, skip, self.progress, self.session_bar)

        with gui.add_folder("Replay", visible=False) as self.replay:
            self.play = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE, hint="key P")
            again = gui.add_button("Replay from start", icon=viser.Icon.REPEAT, hint="key Space")
            steps = gui.add_button_group("Step", options=["◀ frame", "frame ▶"], hint="keys ← →")
            self.frame = gui.add_slider("Frame", min=0, max=1, step=1, initial_value=0)
            self.speed = gui.add_button_group("Speed", options=[f"{s:g}×" for s in SPEEDS])
            self.loop = gui.add_checkbox("Loop", initial_value=True)
            self.shadows = gui.add_checkbox("Shadows", initial_value=False, hint="off: faster on slow graphics")
        self.play.on_click(lambda _: actions.toggle_play())
        again.on_click(lambda _: actions.replay())
        steps.on_click(lambda _: actions.step(-1 if steps.value.startswith("◀") else 1))
        self.frame.on_update(lambda e: None if e.client is None else actions.seek(float(self.frame.value)))
        self.speed.on_click(lambda _: actions.set_speed(float(self.speed.value.rstrip("×"))))
        self.loop.on_update(lambda e: None if e.client is None else actions.set_loop(bool(self.loop.value)))
        self.shadows.on_update(lambda e: None if e.client is None else actions.set_shadows(bool(self.shadows.value)))

        with gui.add_folder("Account", expand_by_default=False, visible=False) as self.account:
            sign_out = gui.add_button("Sign out", color="gray")
        sign_out.on_click(lambda _: actions.sign_out())

        self.context_panel = gui.add_panel(visible=False)
        with self.context_panel.add_tab("Context", viser.Icon.INFO_CIRCLE):
            self.task = gui.add_markdown("")
            self.inset = gui.add_image(
                np.full((SIZE, SIZE, 3), 255, np.uint8), label="top-down, north up", format="png"
            )
            self.segment = gui.add_markdown("")
        self.context_panel.dock_left()
        self.context_panel.set_width(300)

    # ---------------------------------------------------------------- screens

    def _screen(self, status: str, *, login: bool = False, labeling: bool = False, replay: bool = False) -> None:
        with self.client.atomic():
            self.status.content = status
            self.login.visible = login
            self.labeling.visible = labeling
            self.replay.visible = replay
            self.account.visible = not login
            self.context_panel.visible = replay

    def show_login(self, message: str) -> None:
        self._screen(message, login=True)

    def show_message(self, message: str) -> None:
        """A state with no segment (connecting, unreachable, waiting): only undo stays offered."""
        with self.client.atomic():
            self._screen(message, labeling=True)
            self.query.content = ""
            for element in self.segment_only:
                element.visible = False

    def show_watch(self, status: str) -> None:
        """Watch mode: the replay and its context, nothing to label."""
        self._screen(status, replay=True)

    def show_segment(self, info: SegmentInfo, error: str | None = None) -> None:
        status = f"⚠️ **This segment cannot be replayed** — {error}  \nPress **S** to skip it." if error else ""
        with self.client.atomic():
            self._screen(status, labeling=True, replay=error is None)
            self.query.content = f"Segment `{info.query_id}`"
            for element in self.segment_only:
                element.visible = True
            for button in self.label_buttons:
                button.disabled = error is not None
            self.frame.max = max(info.n_frames - 1, 1)
            self.segment.content = (
                f"**run** {info.run_id} · {info.env} · {info.method}  \n"
                f"**epoch** {info.epoch} · **feedback session** {info.session}  \n"
                f"**skill** {skill_text(info.skill)}  \n"
                f"**frames** {info.n_frames} from step {info.start}"
            )

    def show_task(self, title: str, description: str, meaning: dict[int, str]) -> None:
        lines = "\n".join(f"- **{label.word}**: {meaning[label]}" for label in Label if label in meaning)
        self.task.content = f"### {title}\n{description}\n\n{lines}"

    def show_inset(self, image: np.ndarray) -> None:
        self.inset.image = image

    def show_progress(self, p: Progress) -> None:
        total = f"{p.total_done} / {p.total_planned}" if p.total_planned else f"{p.total_done}"
        self.progress.content = f"This session **{p.session_done} / {p.session_size}** · total **{total}**"
        self.session_bar.value = 100.0 * p.session_done / max(p.session_size, 1)  # type: ignore[misc]  # settable

    def show_frame(self, frame: int, playing: bool) -> None:
        with self.client.atomic():
            self.frame.value = frame  # type: ignore[misc]  # viser types .value read-only; its setter exists
            self.play.label = "Pause" if playing else "Play"
            self.play.icon = viser.Icon.PLAYER_PAUSE if playing else viser.Icon.PLAYER_PLAY

    def greet(self, name: str) -> None:
        self.title.content = f"**collie · labeling** — signed in as **{name}**"

    def notify(self, title: str, body: str, color: str = "blue") -> None:
        # color: one of viser's Mantine colour names, which callers pass as plain strings
        self.client.add_notification(title, body, auto_close_seconds=4.0, color=color)  # type: ignore[call-overload]  # see above
