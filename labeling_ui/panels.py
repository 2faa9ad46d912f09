"""The labeler's on-screen panels (all client-scoped): sign-in, status, label buttons, progress,
replay controls, keymap (right), and the context a labeler judges by (left): the task, what each
label means, the top-down inset and the segment's run / epoch / skill.

Panels only draw and forward clicks; what a click does is the session's business (`Actions`).
"""

from __future__ import annotations

import html
import json
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING, Protocol

import numpy as np
import viser

from collie.labels import Label
from collie.tasks import Task
from labeling_ui.browser import run_script
from labeling_ui.colours import EARLIER_RGB, PLAYED_RGB, TO_COME_RGB, css
from labeling_ui.inset import SIZE
from labeling_ui.playback import SPEEDS
from labeling_ui.rule import INSTRUCTION_MEANING
from labeling_ui.service import MyLabel, Progress

if TYPE_CHECKING:
    from labeling_ui.watch import SkillShow

KEYMAP = (
    "**Keys** · **1** bad · **2** neutral · **3** good · **X** skip (not a label) · **U** undo the last "
    "label · **Space** replay · **P** play / pause · **J L** one frame back / forward · **V** reset the view"
)
LABEL_NAMES = {int(label): label.word for label in Label}
MIXED_RULE = (
    "**A segment with states of different kinds:** it is **bad** if any state is bad, **good** only if "
    "every state is good, else neutral."
)
LEGEND = (
    f"**Path colours** (3D and inset): <span style='color:{css(PLAYED_RGB)}'>■</span> played so far "
    f"(3D only) · <span style='color:{css(TO_COME_RGB)}'>■</span> to come (the inset: the whole segment, "
    "● its start, ○ its end) · "
    f"<span style='color:{css(EARLIER_RGB)}'>■</span> the trajectory before the segment. Floor and inset: "
    "red bad area, yellow good area (inset: neutral ground green), as on the dashboard; none in a run "
    "with only an instruction. The "
    "blue **N** arrow points north (up in the inset)."
)
CONTROLS_PX, CONTEXT_PX = 360, 300  # the docked columns' widths: controls (right), context (left)
NARROW_WINDOW_PX = 960  # below this the context column starts minimized: the 3D view would be < 300 px
PHONE_WINDOW_PX = 600  # below this (a phone) viser's controls sheet covers most of the 3D view
APP_TITLE = "collie labeling"  # the browser tab's title, after what the tab shows
SIGN_IN = "Sign in"  # the button's words, which Enter in the token field presses (keys.py)
MINE_SHOWN = 12  # rows of "my labels" listed (the newest); every one can be picked


def plain(text: str) -> str:
    """People's free text (an operator's instructions, a task file's words) for a markdown element:
    HTML shown as the characters typed, never run (viser's markdown renders HTML)."""
    return html.escape(text)


class Actions(Protocol):
    """What the panels' buttons ask for; the session implements it."""

    def sign_in(self, token: str) -> None: ...
    def sign_out(self) -> None: ...
    def label(self, value: Label) -> None: ...
    def skip(self) -> None: ...
    def undo(self) -> None: ...
    def relabel(self, query_id: str) -> None: ...
    def replay(self) -> None: ...
    def toggle_play(self) -> None: ...
    def step(self, frames: int) -> None: ...
    def seek(self, frame: float) -> None: ...
    def set_speed(self, speed: float) -> None: ...
    def set_loop(self, loop: bool) -> None: ...
    def set_shadows(self, on: bool) -> None: ...
    def reset_view(self) -> None: ...


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
    revising: bool = False


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
        main.set_width(CONTROLS_PX)

        self.title = gui.add_markdown("**collie · labeling** — not signed in")
        self.status = gui.add_markdown("Connecting…")
        self._page_title: str | None = None
        self.page_title(APP_TITLE)

        with gui.add_folder("Sign in", visible=False) as self.login:
            self.token = gui.add_text("Labeler token", initial_value="", hint="the token your operator gave you")
            sign_in = gui.add_button(SIGN_IN, icon=viser.Icon.LOGIN)
        sign_in.on_click(lambda _: actions.sign_in(self.token.value.strip()))

        with gui.add_folder("Label", visible=False) as self.labeling:
            self.query = gui.add_markdown("")
            bad = gui.add_button("1 · Bad", color="red", hint="key 1")
            neutral = gui.add_button("2 · Neutral", color="gray", hint="key 2")
            good = gui.add_button("3 · Good", color="yellow", hint="key 3")  # the class colours of every screen
            skip = gui.add_button("X · Skip", color="dark", hint="key X: not a label; someone else gets it")
            self.undo_button = undo = gui.add_button("U · Undo last label", color="dark", hint="key U")
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
            steps = gui.add_button_group("Step", options=["◀ frame", "frame ▶"], hint="keys J L")
            self.frame = gui.add_slider("Frame", min=0, max=1, step=1, initial_value=0)
            self.speed = gui.add_button_group("Speed", options=[f"{s:g}×" for s in SPEEDS])
            self.speed_now = gui.add_markdown("Speed **1×**")
            self.loop = gui.add_checkbox("Loop", initial_value=True)
            self.shadows = gui.add_checkbox("Shadows", initial_value=False, hint="off: faster on slow graphics")
            reset = gui.add_button("Reset view (north up)", icon=viser.Icon.COMPASS, hint="key V")
        reset.on_click(lambda _: actions.reset_view())
        self.play.on_click(lambda _: actions.toggle_play())
        again.on_click(lambda _: actions.replay())
        steps.on_click(lambda _: actions.step(-1 if steps.value.startswith("◀") else 1))
        self.frame.on_update(lambda e: None if e.client is None else actions.seek(float(self.frame.value)))
        self.speed.on_click(lambda _: actions.set_speed(float(self.speed.value.rstrip("×"))))
        self.loop.on_update(lambda e: None if e.client is None else actions.set_loop(bool(self.loop.value)))
        self.shadows.on_update(lambda e: None if e.client is None else actions.set_shadows(bool(self.shadows.value)))

        with gui.add_folder("My labels", expand_by_default=False, visible=False) as self.mine_folder:
            self.mine_list = gui.add_markdown("")
            self.mine_pick = gui.add_dropdown("Segment", options=["—"], initial_value="—")
            self.mine_inset = gui.add_image(np.full((SIZE // 2, SIZE // 2, 3), 255, np.uint8), label="its path")
            replay_mine = gui.add_button("Replay and relabel", icon=viser.Icon.REPEAT, hint="a new label revises yours")
        replay_mine.on_click(lambda _: self._relabel_picked(actions))
        self.mine_pick.on_update(lambda _: self._show_mine_inset())
        self._mine: Sequence[MyLabel] = ()  # replaced whole by the worker, read by the GUI threads
        self._mine_inset: Callable[[MyLabel], np.ndarray] | None = None

        with gui.add_folder("Account", expand_by_default=False, visible=False) as self.account:
            sign_out = gui.add_button("Sign out", color="gray")
        sign_out.on_click(lambda _: actions.sign_out())

        self.context_panel = gui.add_panel(visible=False)
        with self.context_panel.add_tab("Context", viser.Icon.INFO_CIRCLE):
            self.task = gui.add_markdown("")
            self.rule = gui.add_markdown(MIXED_RULE)
            self.instructions = gui.add_markdown("")
            self.inset = gui.add_image(
                np.full((SIZE, SIZE, 3), 255, np.uint8), label="top-down, north up", format="png"
            )
            self.inset_caption = gui.add_markdown("")
            gui.add_markdown(LEGEND)
            self.segment = gui.add_markdown("")
        self.context_panel.dock_left()
        self.context_panel.set_width(CONTEXT_PX)

    def fit_window(self, width: int | None) -> None:
        """In a window narrower than NARROW_WINDOW_PX the context column opens minimized (a rail
        the labeler can open), so the 3D view is more than a strip between the two columns. Once,
        as the tab opens: never against the labeler's own choice later."""
        if width is not None and width < NARROW_WINDOW_PX:
            self.context_panel.minimize()
        if width is not None and width < PHONE_WINDOW_PX:  # said, not hidden: the page still works
            self.client.add_notification(
                "Made for a computer screen",
                "On a screen this narrow the controls cover the robot and the task's picture: open this "
                "link on a desktop or laptop browser to label.",
                with_close_button=True,
                auto_close_seconds=None,
                color="yellow",
            )

    # ---------------------------------------------------------------- screens

    def _screen(self, status: str, *, login: bool = False, labeling: bool = False, replay: bool = False) -> None:
        with self.client.atomic():
            self.status.content = status
            self.login.visible = login
            self.labeling.visible = labeling
            self.replay.visible = replay
            self.account.visible = not login
            self.mine_folder.visible = not login and bool(self._mine)
            self.context_panel.visible = replay

    def page_title(self, title: str) -> None:
        """The browser tab's title (viser's page says "Viser"): which of a labeler's tabs labels, and
        whether a segment waits in it. Sent only when it changes."""
        if title != self._page_title:
            self._page_title = title
            run_script(self.client, f"document.title = {json.dumps(title)};")

    def show_login(self, message: str) -> None:
        """The sign-in field: this tab is nobody until a token is accepted (the title says so)."""
        with self.client.atomic():
            self._screen(message, login=True)
            self.title.content = "**collie · labeling** — not signed in"
        self.page_title(f"Sign in · {APP_TITLE}")

    def show_checking(self, message: str) -> None:
        """Signing in (the token not yet accepted): no labeling control, not even undo, until the
        service says whose token it is."""
        self._screen(message)

    def show_message(self, message: str, keep_replay: bool = False, title: str = APP_TITLE, undo: bool = True) -> None:
        """A state with no segment (connecting, unreachable, waiting): only undo stays offered
        (`undo`: not for a run that ended, which takes no undo either); `keep_replay`: the
        evaluation's skills keep playing beside it."""
        with self.client.atomic():
            self._screen(message, labeling=True, replay=keep_replay)
            self.query.content = ""
            for element in self.segment_only:
                element.visible = False
            self.undo_button.visible = undo
        self.page_title(title)

    def show_replay_only(self, status: str, detail: str, n_frames: int, rule: bool = False) -> None:
        """Watch or review mode: the replay and its context, nothing to label; `rule`: the task's
        mixed-segment rule stays on screen (a review judges one segment, watch mode none)."""
        with self.client.atomic():
            self._screen(status, replay=True)
            self.rule.visible = rule
            self.frame.max = max(n_frames - 1, 1)
            self.segment.content = detail
        self.page_title(f"Replay · {APP_TITLE}")

    def show_alone(self, message: str) -> None:
        """Only the status line (and the account): no label buttons, no replay."""
        self._screen(message)

    def show_skills_while_waiting(self, detail: str, n_frames: int) -> None:
        """The waiting screen keeps its status; the 3D view plays the latest evaluation's skills."""
        with self.client.atomic():
            self.replay.visible = True
            self.context_panel.visible = True
            self.rule.visible = False
            self.frame.max = max(n_frames - 1, 1)
            self.segment.content = "**The run's latest evaluation**  \n" + detail

    def add_skill_controls(self, show: SkillShow) -> None:
        gui = self.client.gui
        with gui.add_folder("Skills"):
            move = gui.add_button_group("Skill", options=["◀ previous", "next ▶"])
            auto = gui.add_checkbox("Next skill when one ends", initial_value=True)
        move.on_click(lambda _: show.step(-1 if move.value.startswith("◀") else 1))
        auto.on_update(lambda _: show.set_auto(bool(auto.value)))

    def show_segment(self, info: SegmentInfo, error: str | None = None) -> None:
        status = f"⚠️ **This segment cannot be replayed** — {error}  \nPress **X** to skip it." if error else ""
        with self.client.atomic():
            self._screen(status, labeling=True, replay=error is None)
            again = " — **relabel**: a new label revises yours" if info.revising else ""
            self.query.content = f"Segment `{info.query_id}`{again}"
            self.rule.visible = True
            for element in (*self.segment_only, self.undo_button):
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
        self.page_title(f"Label · run {info.run_id} · {APP_TITLE}")

    def show_task(self, task: Task, instructions: str) -> None:
        """The task, what each label means, the mixed-segment rule, the run's own instructions; a
        class the task cannot give is disabled, with a note why."""
        meaning = task.meaning
        lines = "\n".join(f"- **{LABEL_NAMES[k]}**: {meaning[k]}" for k in sorted(meaning) if k in LABEL_NAMES)
        self.task.content = f"### {plain(task.name)}\n{plain(task.description)}\n\n{lines}"
        good = self.label_buttons[2]
        good.disabled = good.disabled or not task.can_be_good
        good.label = "3 · Good" if task.can_be_good else "3 · Good (not in this task)"
        self.show_instructions(instructions)

    def show_instruction(self, instruction: str, instructions: str) -> None:
        """A run without a rule: the person's instruction stands where the task's words would."""
        lines = "\n".join(f"- **{LABEL_NAMES[k]}**: {v}" for k, v in sorted(INSTRUCTION_MEANING.items()))
        self.task.content = f"### Instruction\n{plain(instruction)}\n\n{lines}"
        self.label_buttons[2].label = "3 · Good"
        self.show_instructions(instructions)

    def show_unknown_task(self, name: str, env: str, instructions: str) -> None:
        self.task.content = f"### {plain(name)}\nUnknown task '{plain(name)}' for {env}: judge by its name."
        self.show_instructions(instructions)

    def show_instructions(self, text: str) -> None:
        self.instructions.content = f"**From your operator:** {plain(text)}" if text else ""
        self.instructions.visible = bool(text)

    def show_speed(self, speed: float) -> None:
        self.speed_now.content = f"Speed **{speed:g}×**"

    def show_mine(self, mine: Sequence[MyLabel], inset: Callable[[MyLabel], np.ndarray]) -> None:
        """This labeler's labels in the run, newest first, as the service keeps them."""
        self._mine, self._mine_inset = mine, inset
        rows = [
            f"| `{m.query_id}` | {LABEL_NAMES[m.label]}{'' if m.in_effect else ' (undone)'} | {_clock(m.labelled_at)} |"
            for m in mine[:MINE_SHOWN]
        ]
        more = f"  \n… and {len(mine) - MINE_SHOWN} older" if len(mine) > MINE_SHOWN else ""
        undone = sum(not m.in_effect for m in mine)  # they are no label now: the total counts without them
        counted = f"{len(mine) - undone} labelled in this run" + (f" ({undone} more undone)" if undone else "")
        with self.client.atomic():
            self.mine_folder.visible = bool(mine)
            self.mine_list.content = (
                f"{counted}, newest first  \n\n| segment | label | when |\n|---|---|---|\n" + "\n".join(rows) + more
            )
            options = [m.query_id for m in mine] or ["—"]
            keep = self.mine_pick.value if self.mine_pick.value in options else options[0]
            self.mine_pick.options = options
            self.mine_pick.value = keep  # type: ignore[misc]  # viser types .value read-only; it is settable
        self._show_mine_inset()

    def _relabel_picked(self, actions: Actions) -> None:
        if self.mine_pick.value != "—":
            actions.relabel(self.mine_pick.value)

    def _show_mine_inset(self) -> None:
        picked = next((m for m in self._mine if m.query_id == self.mine_pick.value), None)
        if picked is not None and self._mine_inset is not None and picked.xy:
            self.mine_inset.image = self._mine_inset(picked)[::2, ::2]

    def show_inset(self, image: np.ndarray, caption: str = "") -> None:
        self.inset.image = image
        self.inset_caption.content = caption

    def show_progress(self, p: Progress, yours: int) -> None:
        """`yours`: this labeler's labels in effect in the session. With redundancy r a query counts
        once r labelers agree, so a lone labeler's count would stay at 0: theirs is said beside it."""
        total = f"{p.total_done} / {p.total_planned}" if p.total_planned else f"{p.total_done}"
        session = f"This session **{p.session_done} / {p.session_size}**"
        if p.redundancy > 1:
            session += f" settled ({p.redundancy} labelers each) · yours **{yours}**"
        paused = "  \n⏸ **The run is paused by an operator**: your labels still count." if p.paused else ""
        self.progress.content = f"{session} · total **{total}**{paused}"
        self.session_bar.value = 100.0 * p.session_done / max(p.session_size, 1)  # type: ignore[misc]  # settable

    def show_frame(self, frame: int, playing: bool) -> None:
        with self.client.atomic():
            self.frame.value = frame  # type: ignore[misc]  # viser types .value read-only; its setter exists
            self.play.label = "Pause" if playing else "Play"
            self.play.icon = viser.Icon.PLAYER_PAUSE if playing else viser.Icon.PLAYER_PLAY

    def greet(self, name: str, role: str, before: str | None = None, labels: bool = True) -> None:
        """Who this tab is, always on screen; an operator is marked, a change of identity is loud.
        `labels`: this tab may label (not watch or review mode)."""
        marker = ""
        if role == "operator" and labels:
            marker = " · ⚠️ **operator**: your labels count as the operator's"
        elif role == "operator":
            marker = " · operator (labels nothing here)"
        changed = f"  \n🔴 **This tab was signed in as {before}**: it is now {name}." if before else ""
        self.title.content = f"**collie · labeling** — signed in as **{name}**{marker}{changed}"

    def notify(self, title: str, body: str, color: str = "blue") -> None:
        # color: one of viser's Mantine colour names, which callers pass as plain strings
        self.client.add_notification(title, body, auto_close_seconds=4.0, color=color)  # type: ignore[call-overload]  # see above

    @contextmanager
    def notice_if_slow(self, title: str, body: str, after_s: float) -> Iterator[None]:
        """A notice with a spinner while the block runs, if it runs longer than `after_s`: a key is
        answered in milliseconds, so a slow answer would otherwise look like a key not taken."""
        lock, shown, done = threading.Lock(), [], [False]

        def show() -> None:
            with lock:
                if not done[0]:
                    shown.append(self.client.add_notification(title, body, loading=True, with_close_button=False))

        timer = threading.Timer(after_s, show)
        timer.daemon = True
        timer.start()
        try:
            yield
        finally:
            timer.cancel()
            with lock:
                done[0] = True
            for handle in shown:
                handle.remove()


def _clock(when: datetime) -> str:
    return when.astimezone().strftime("%H:%M:%S")
