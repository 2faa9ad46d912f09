"""A tab's configuration, and what its GUI threads and its stream waiter ask the worker to do:
one typed action each (session.py matches on them)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal

from collie.client import new_request_id
from labeling_ui.tab import Submit, Withdraw


@dataclass(frozen=True)
class UiConfig:
    api: str
    run_id: int | None = None  # pin one run; else the newest open run with work
    lease_s: float = 60.0  # renewed while the tab is open; a crashed UI frees its claim this fast
    fps: float = 20.0  # segment frames per second at 1× (env steps are 0.05 s)
    min_dwell_s: float = 0.3  # label keys are ignored this long after a segment appears
    min_played: float = 1.0  # share of a segment that must have played before a label key counts
    prefetch: bool = True  # claim and prepare the next segment while one is on screen
    wait_s: float = 10.0  # long-poll length while waiting for work
    release_grace_s: float = 5.0  # a closed tab's claims wait this long for a reload of it
    retry_max_s: float = 5.0


# ---------------------------------------------------------------- what the worker is asked to do


@dataclass(frozen=True)
class SignIn:
    token: str


@dataclass(frozen=True)
class SignOut:
    pass


@dataclass(frozen=True)
class Send:
    decision: Submit | Withdraw
    at: float = field(default_factory=time.perf_counter)


@dataclass(frozen=True)
class UndoKey:
    request_id: str = field(default_factory=new_request_id)


@dataclass(frozen=True)
class Relabel:
    query_id: str


@dataclass(frozen=True)
class Wake:
    kinds: frozenset[str] = frozenset()  # what the run's stream carried


@dataclass(frozen=True)
class Moved:
    """The segment on screen went to another tab of the labeler: it shows it, or `done` it there."""

    query_id: str
    done: Literal["labelled", "skipped"] | None = None


@dataclass(frozen=True)
class Close:
    pass


Action = SignIn | SignOut | Send | UndoKey | Relabel | Wake | Moved | Close
