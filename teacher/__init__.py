"""The oracle teacher as a labeler: claims queries and labels them through the service's API, with
the same kind of labeler token a person uses, by the task rule (collie.teacher.OracleTeacher)."""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable
from typing import TypeVar

import numpy as np

from collie.client import CollieClient, Conflict, new_request_id, retrying
from collie.labels import Label
from collie.schemas import FINISHED, QueryRead
from collie.tasks import task_for_run
from collie.teacher import OracleTeacher

log = logging.getLogger(__name__)
T = TypeVar("T")


class NoRule(ValueError):
    """The run has no task rule (only a person's instruction): there is nothing to label it by."""


def oracle_for(client: CollieClient, run_id: int, noise_band: float, seed: int) -> OracleTeacher:
    """The teacher for the run's rule as the service holds it (never a local file or registry)."""
    run = client.run(run_id)
    task = task_for_run(run)
    if task is None:
        raise NoRule(
            f"run {run_id} has no task rule, only an instruction ({run.instruction!r}): the oracle labels by a rule, "
            "so people must label this run"
        )
    return OracleTeacher(task, noise_band=noise_band, seed=seed)


def segment_label(oracle: OracleTeacher, query: QueryRead) -> Label:
    xy = np.asarray(query.xy, dtype=np.float64)
    pitch = None if query.pitch is None else np.array([np.nan if p is None else p for p in query.pitch], np.float64)
    return oracle.label(xy, pitch)


class TeacherLoop:
    """Claim → label → submit, at most `rate` labels per second. `run` returns the number labelled."""

    def __init__(
        self,
        client: CollieClient,
        run_id: int,
        oracle: OracleTeacher,
        rate: float | None = None,
        stop: threading.Event | None = None,
        idle_wait_s: float = 10.0,
    ) -> None:
        self.client = client
        self.run_id = run_id
        self.oracle = oracle
        self.min_gap_s = 0.0 if not rate else 1.0 / rate
        self.stop = stop or threading.Event()
        self.idle_wait_s = idle_wait_s
        self.labelled = 0
        self._last_submit = 0.0
        self.interrupted = False  # set by a signal handler (teacher/cli.py): the loop ends at its next look

    def run(self, until_done: bool = False) -> int:
        """Label what is claimable; with until_done, keep waiting for new sessions until the run
        is finished, failed or stopped."""
        after = self._retry(lambda: self.client.run(self.run_id)).last_event_id
        held: QueryRead | None = None
        while not (self.stop.is_set() or self.interrupted):
            if held is None:
                try:
                    claim = self._retry(lambda: self.client.claim(self.run_id))
                except Conflict as exc:  # finished, failed or stopping: nothing more to do
                    log.info("run %s takes no more labels: %s", self.run_id, exc.detail)
                    break
                held = claim.query if claim is not None else None
            if held is not None:
                held = self._label(held)
                continue
            if not until_done or self._retry(lambda: self.client.run(self.run_id)).status in FINISHED:
                break
            # Sleep until something happens on the run (new queries, a status change).
            page = functools.partial(self.client.events, self.run_id, after=after, wait_s=self.idle_wait_s)
            after = self._retry(page).last_id
        return self.labelled

    def _label(self, query: QueryRead) -> QueryRead | None:
        """Label `query`; returns the next query, claimed in the same round trip (or None)."""
        started = time.monotonic()
        value = segment_label(self.oracle, query)
        wait = self._last_submit + self.min_gap_s - time.monotonic()
        if wait > 0:
            self.stop.wait(wait)
        request_id = new_request_id()  # one id for every retry: the label is stored once
        seconds = time.monotonic() - started
        try:
            ack = self._retry(
                lambda: self.client.submit(self.run_id, query.query_id, value, seconds, request_id, next=True)
            )
        except Conflict as exc:  # lost the lease (expired and taken) or the run ended: move on
            log.info("label for %s not taken: %s", query.query_id, exc.detail)
            return None
        self._last_submit = time.monotonic()
        self.labelled += 1
        log.info("labelled %s → %d", query.query_id, value)
        return ack.next.query if ack.next is not None else None

    def _retry(self, call: Callable[[], T]) -> T:
        """Wait out an unavailable service (the shared backoff), until it answers or we stop."""
        return retrying(call, stop=self.stop)
