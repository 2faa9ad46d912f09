"""Algorithm 1 of the COLLIE paper: skill discovery with online, training-free human guidance.

    for epoch e = 1 … T^e:
        roll out skills z ~ p(z) and store the trajectories in B                      (line 3)
        if it is a feedback epoch and fewer than N_total segments are labelled:          (line 4)
            select M segments by active query (Algorithm 2), ask the feedback source,  (lines 5–6)
            and add their states to D0 / D1 / D2                                       (line 7)
        for each gradient step: w_e(s) (Eq. 8 + smoothing), then φ, λ and π            (lines 9–13)

The loop talks to one `FeedbackSource` and does not know who labels. It evaluates every
`eval_every` epochs, writes metrics.jsonl, plots, TensorBoard scalars and atomic checkpoints:
networks, optimisers, RNG and labelled sets in checkpoint.pt, the replay as append-only chunks
(trainer/replay_log.py). SIGTERM or SIGINT ends the process at the end of the current epoch (at
once while it waits for labels or a pause) with a final checkpoint and status "interrupted",
which is not reported to the feedback source (the run is not over); `--resume` continues exactly:
a run stopped while it waited for a session's labels waits for that session again, at that epoch.
"""

from __future__ import annotations

import json
import math
import os
import random
import re
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from collie import early_term, startup
from collie.labels import Label
from collie.whole_files import write_whole
from trainer.acting import acting_path
from trainer.checkpoint import load_checkpoint, save_checkpoint
from trainer.config import LABEL_METHODS, RULE_METHODS, Config
from trainer.denormals import flushing_denormals
from trainer.device_replay import DeviceBatch, DeviceReplay
from trainer.dodont import dodont_weight
from trainer.encoders import deterministic_convolutions
from trainer.envs import VectorEnv
from trainer.fast_ops import fast_ops_pay
from trainer.feedback import FeedbackSource, LabelEvent, OracleFeedback, Segment, SourceRefused, StopRequested
from trainer.guidance import LabelledSets, guidance_weight, kept, smoothing_beta
from trainer.memory_ledger import reserve
from trainer.memory_plan import run_floor_bytes
from trainer.methods import build_agent, method
from trainer.metra import WeightFn
from trainer.metrics import coverage_metrics, travel_metrics
from trainer.obs_noise import NoisyObservations
from trainer.obs_stats import observation_stats
from trainer.plots import plot_curves, plot_guidance_map, plot_skill_trajectories
from trainer.query import select_queries
from trainer.replay import TrajectoryReplay
from trainer.replay_log import ReplayLog
from trainer.rollout import Normaliser, Trajectories, rollout
from trainer.run_files import ResumeError, RunFolderError, read_json_object, write_json
from trainer.skills import SkillPrior
from trainer.task_choice import TASK_JSON, RunRule, choose_rule
from trainer.telemetry import LoopStatus, MetricsReport, Reporter, RolloutsReport, StatusReport
from trainer.threads import resolve_threads

ROLLOUT_STRIDE = 2  # evaluation rollouts go out every 2nd state (the stride travels with them)
CURVE_KEYS: tuple[str, ...] = (
    "safe_coverage",
    "safe_ratio",
    "composite_coverage",
    "lambda",
    "alpha",
    "phi_loss",
    "qf_loss",
    "n_labels",
)
CURVE_KEYS += ("n_bins", "w_mean")  # rule-free: state coverage and the guidance along the evaluations
HEARTBEAT_S = 60.0  # with no bar, a line about the run's pace at least this often between other lines
CURVES_EVERY_S = 60.0  # a live run redraws curves.png at an evaluation this long after the last (a plot is slow)


def non_finite(state: Any, at: str = "agent") -> str | None:
    """The first place in a (nested) state holding a NaN or an infinity, e.g. agent.qf.net.0.weight."""
    if isinstance(state, torch.Tensor):
        return at if state.is_floating_point() and not bool(torch.isfinite(state).all()) else None
    items = state.items() if isinstance(state, dict) else enumerate(state) if isinstance(state, list | tuple) else ()
    return next((found for key, value in items if (found := non_finite(value, f"{at}.{key}"))), None)


def coverage_shown(record: dict[str, Any]) -> str:
    """An evaluation's safe coverage for the progress bar, whole (tqdm shows a float to 3 significant
    digits: "-2e+3"); "-" without a rule."""
    return f"{record['safe_coverage']:.0f}" if "safe_coverage" in record else "-"


def evaluation_line(epoch: int, epochs: int, record: dict[str, Any], labels: int) -> str:
    """An evaluation in one line, for a log where no progress bar is drawn (else hours of silence)."""
    return f"epoch {epoch}/{epochs} · safe cov {coverage_shown(record)} · bins {record['n_bins']:.0f} · labels {labels}"


def summary_wall_s(out: Path, default: float) -> float:
    """summary.json's wall_s (a finished run's, written after its last checkpoint), else `default`."""
    try:
        wall = read_json_object(out / "summary.json").get("wall_s")
    except RunFolderError:
        return default
    return float(wall) if isinstance(wall, int | float) and math.isfinite(wall) else default


class TrainingDiverged(RuntimeError):
    """A NaN/inf appeared in observations or losses; the last checkpoint is left intact."""


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)  # the name's form is checked by Config.validate
    count = torch.cuda.device_count()
    if device.type == "cuda" and device.index is not None and device.index >= count:
        others = f"cuda:0 … cuda:{count - 1}, " if count > 1 else "cuda, " if count else ""
        raise ValueError(f"--device {name}: this machine has {count} CUDA devices; use --device {others}cpu (or auto)")
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"--device {name}: torch sees no CUDA device here; use --device cpu (or auto)")
    if device.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"--device {name}: torch sees no MPS device here; use --device cpu (or auto)")
    return device


class Trainer:
    def __init__(
        self,
        cfg: Config,
        feedback: FeedbackSource | None = None,
        progress: bool = True,
        reporter: Reporter | None = None,
        rule: RunRule | None = None,
    ) -> None:
        cfg.validate()
        self.cfg, self.progress = cfg, progress
        self.out = Path(cfg.out)
        # The rule (None with only an instruction): fails early with the list of task names; the
        # seed places random scenery (car hazards). A run on the service passes the one it holds.
        self.rule = rule or choose_rule(cfg)
        self.task = self.rule.task
        if self.task is None and cfg.method in RULE_METHODS:  # e.g. a service run that holds only an instruction
            raise ValueError(f"method {cfg.method!r} trains on a task rule, and this run has none (an instruction)")
        if self.task is None and feedback is None and cfg.method in LABEL_METHODS:
            raise ValueError("a run without a task rule learns from people's labels: give --api (no oracle here)")
        self.device = pick_device(cfg.device)
        if self.device.type == "cuda":
            deterministic_convolutions()
        if cfg.fast_ops is None:  # fixed now, so config.json and a resume carry this machine's choice
            cfg.fast_ops = fast_ops_pay(self.device)
        torch.set_num_threads(resolve_threads(cfg.threads, cfg.hidden))  # fair share on a busy machine
        self.rng = np.random.default_rng(cfg.seed)
        random.seed(cfg.seed)
        torch.manual_seed(cfg.seed)
        vec: dict[str, Any] = dict(
            episode_steps=cfg.episode_steps, layout_seed=cfg.seed, physics_threads=cfg.physics_threads or None
        )
        self.env = VectorEnv(cfg.env, cfg.episodes_per_epoch, **vec)
        self.eval_env = VectorEnv(cfg.env, cfg.eval_trajectories, **vec)
        if cfg.obs_noise > 0:  # the noisy-observation ablation: the agent sees ŝ = (1 + x)·s
            # NoisyObservations wraps a VectorEnv and offers its interface (duck-typed)
            noisy = (NoisyObservations(e, cfg.obs_noise) for e in (self.env, self.eval_env))
            self.env, self.eval_env = noisy  # type: ignore[assignment]  # see above
        self.normalise = Normaliser(*observation_stats(cfg.env, self.env.obs_mean, self.env.obs_std, cfg.obs_norm))
        self.prior = SkillPrior.for_config(cfg)
        self.method = method(cfg.method)
        # before torch and np.zeros lend it all: the kernel would kill the run once it was touched
        on_cpu = self.device.type == "cpu"
        reserve(  # and promised, so that a run started beside this one does not count it as free
            "the networks, a gradient step and the replay" if on_cpu else "the replay",
            run_floor_bytes(cfg, self.env, on_cpu),
        )
        self.agent, self.instruction = build_agent(
            cfg, self.env.obs_shape, self.env.action_dim, self.prior, self.device
        )  # the method's learner (+ ψ for DoDont*/DDG*)
        self.replay = TrajectoryReplay(
            cfg.replay_capacity,
            cfg.episode_steps,
            self.env.obs_shape,
            self.env.action_dim,
            cfg.skill_dim,
            self.env.nq,
            self.env.nv,
            self.env.obs_dtype,
        )
        self.replay_log = ReplayLog(self.out / "replay", self.replay)
        task = self.task

        def oracle_rule(xy: np.ndarray, pitch: np.ndarray) -> np.ndarray:  # g(s) per stored state, for the Oracle
            assert task is not None, "only a rule method reads g(s), and it refuses a run without a rule"
            return task.classify(xy.reshape(-1, 2), pitch.reshape(-1)).reshape(pitch.shape)

        self.device_replay = DeviceReplay(
            self.replay,
            self.normalise,
            self.prior.reward_direction,
            self.device,
            rule=oracle_rule if self.method.guidance == "task" else None,
        )
        self.labelled = LabelledSets(self.normalise, self.device)
        self.feedback = feedback or OracleFeedback(self.task, cfg.noise_band, cfg.seed)
        self.reporter = reporter or Reporter()  # telemetry for live views (none by default)
        self.asked: dict[str, np.ndarray] = {}  # query id → raw states, for revisions after the fact
        self.segment_xy: dict[str, np.ndarray] = {}  # query id → x-y, to draw labelled states
        self.epoch, self.env_steps, self.session = 0, 0, 0
        self.first_feedback_epoch: int | None = None
        self.wall_before = 0.0  # wall seconds spent in earlier processes of this run (resume)
        self._t0: float | None = None  # when this process's share began; None: it trains nothing
        self._curves_at = time.monotonic()  # curves.png last drawn (none before the first minute)
        self.checkpointed_at: int | None = None  # the epoch of checkpoint.pt (written or resumed from)
        self._collecting = False  # the epochs so far gathered start transitions only (no update yet)
        self._said = (time.monotonic(), 0)  # when the last line went to the log (no bar), at which epoch
        self._postfix: dict[str, Any] = {}  # what the bar shows after its rate: the last evaluation's, the labels
        self.last_info: dict[str, float] = {}
        self._writer: Any = None
        self._signalled: int | None = None  # SIGTERM/SIGINT received: stop at the epoch's end
        self._waiting = False  # blocked on labels or a pause: a signal stops at once
        self._asking: list[Segment] | None = None  # the session being waited on (checkpointed)

    # ---- guidance -------------------------------------------------------------------------
    def beta(self) -> float:
        span = self.cfg.n_sessions * self.cfg.feedback_every
        return smoothing_beta(self.epoch, self.first_feedback_epoch, span, self.cfg.k_beta)

    def weight_fn(self, sampled: DeviceBatch) -> WeightFn | None:
        """w for this batch: METRA/LSD/DIAYN/DDG* 1, Oracle the task rule g(s), DoDont* 2ψ(s),
        COLLIE Eq. 8 smoothed. Everything stays on the device."""
        at_next = self.cfg.w_at == "next"
        guidance = self.method.guidance
        if guidance == "one":
            return None
        b = sampled.batch
        if guidance == "instruction":  # ψ reads the batch's own normalised tensors
            assert self.instruction is not None, "an instruction-guided method is built with its classifier"
            return dodont_weight(self.instruction, b.next_obs if at_next else b.obs, self.device)
        if guidance == "task":
            g = sampled.next_rule if at_next else sampled.rule
            assert g is not None, "a rule method's batches carry g(s)"
            return lambda _s, _n: g
        beta = self.beta()
        if len(self.labelled) == 0 or beta >= 1.0:
            return None  # w_e ≡ 1 until guidance starts

        def collie_w(phi_s: torch.Tensor, phi_next: torch.Tensor) -> torch.Tensor:
            emb = self.labelled.embeddings(self.agent.phi, self.agent.phi_version)
            w = guidance_weight(phi_next if at_next else phi_s, emb)
            return (1.0 - beta) * w + beta

        return collie_w

    # ---- feedback (Algorithm 1, lines 4–7) --------------------------------------------------
    def is_feedback_epoch(self) -> bool:
        c = self.cfg
        return (
            self.method.asks_labels
            and self.epoch >= c.warmup
            and (self.epoch - c.warmup) % c.feedback_every == 0
            and self.queries_asked < c.total_queries
            and self.replay.count > 0
        )

    @property
    def queries_asked(self) -> int:
        """Segments asked so far, labelled or not: N_total counts what was asked, so a session whose
        labels are late (past --feedback-timeout) is not asked again (its labels still count)."""
        return len(self.asked)

    def make_segments(self) -> list[Segment]:
        c, r = self.cfg, self.replay
        m = min(c.queries_per_session, c.total_queries - self.queries_asked)
        slots, starts = r.sample_windows(c.candidates, c.segment_length, self.rng)
        span = starts[:, None] + np.arange(c.segment_length)
        windows = r.obs[slots[:, None], span]
        dev = self.device

        def phi(x: torch.Tensor) -> torch.Tensor:  # query scoring works on flat states: unflatten images
            return self.agent.phi(x.reshape(-1, *self.env.obs_shape).to(dev)).cpu()

        labelled = self.labelled.all_obs()
        d = self.env.obs_dim
        labelled = self.normalise(labelled).reshape(-1, d) if len(labelled) else np.zeros((0, d), np.float32)
        windows = windows.reshape(len(windows), c.segment_length, d)
        emb = self.labelled.embeddings(self.agent.phi, self.agent.phi_version) if len(self.labelled) else None
        chosen, scores = select_queries(
            self.normalise(windows), m, c.query_strategy, labelled, c.knn_k, self.rng, phi=phi, labelled_emb=emb
        )
        segs = []
        for j, idx in enumerate(chosen):
            i, t = slots[idx], starts[idx]
            sl = slice(t, t + c.segment_length)
            segs.append(
                Segment(
                    query_id=f"s{self.session}-q{j}",
                    session=self.session,
                    epoch=self.epoch,
                    skill=r.skill[i].copy(),
                    start=int(t),
                    obs=r.obs[i, sl].copy(),
                    xy=r.xy[i, sl].astype(np.float64),
                    pitch=r.pitch[i, sl].astype(np.float64),
                    qpos=r.qpos[i, sl].astype(np.float64),
                    qvel=r.qvel[i, sl].astype(np.float64),
                    score=float(scores[idx]),
                    path_xy=r.xy[i].astype(np.float64),
                )
            )
        return segs

    def apply_labels(self, events: list[LabelEvent]) -> None:
        for ev in events:
            if ev.query_id in self.asked:
                self.labelled.set(ev.query_id, self.asked[ev.query_id], ev.label)

    def feedback_session(self, asking: list[Segment] | None = None) -> None:
        """Lines 5–7. `asking`: the segments a stopped run was waiting on, asked again as they were."""
        if asking is None:
            asking = self.make_segments()
            startup.mark("query selection", self.epoch)
        segments = self._asking = asking  # a stop during the wait checkpoints them
        self._waiting = True  # a signal now stops at once
        try:
            events = self.feedback.collect(self.session, self.epoch, segments)  # may swap in a session posted before
        finally:
            self._waiting = False
        self._asking = None
        self.remember_asked(segments)
        self.apply_labels(events)
        if self.first_feedback_epoch is None:
            self.first_feedback_epoch = self.epoch
        self.session += 1

    def rebuild_from_source(self) -> None:
        """The service is the source of truth for labels: rebuild D0/D1/D2 from its history."""
        history = self.feedback.history(held=list(self.asked))  # the checkpoint's segments, labelled or not
        if history is None:
            return
        applied = set(self.labelled.segments)
        self.labelled.load_state_dict({})
        for seg, label in history:
            self.asked[seg.query_id] = kept(seg.obs)  # one array for both: a checkpoint holds it once
            self.segment_xy[seg.query_id] = np.asarray(seg.xy)
            self.labelled.set(seg.query_id, self.asked[seg.query_id], label)
        gone = sorted(applied - set(self.labelled.segments))
        if gone:  # said, not refused: labels undone while the trainer was down go too
            shown = ", ".join(gone[:3]) + (", …" if len(gone) > 3 else "")
            print(
                f"collie train: warning: the labeling service holds no label for {len(gone)} segment(s) this "
                f"checkpoint had applied ({shown}): undone while the trainer was down, or its database is "
                "older than the checkpoint (restored from a backup?); the run goes on with the service's labels",
                file=sys.stderr,
            )
        # self.session stays the checkpoint's: the replay reuses the sessions posted since (by position).
        if history and self.first_feedback_epoch is None:
            self.first_feedback_epoch = min(seg.epoch for seg, _ in history)

    # ---- learning (Algorithm 1, lines 9–13) -----------------------------------------------
    def train_epoch(self) -> None:
        if self.replay.transitions < self.cfg.start_transitions:
            return
        if self.instruction is not None:  # DoDont*/DDG*: fine-tune ψ when the labelled set changed
            self.instruction.refresh(self.labelled)
        sums: dict[str, torch.Tensor] = {}
        i, t = self.replay.sample_indices(self.cfg.grad_steps, self.cfg.batch_size, self.rng)
        # one thread only: the mode is the calling thread's, and a pool's workers keep the one they started with
        with flushing_denormals(self.cfg.flush_denormal and torch.get_num_threads() == 1):
            for sampled in self.device_replay.batches(i, t):  # no host sync inside the loop
                info = self.agent.update(sampled.batch, self.weight_fn(sampled))
                for k, v in info.items():
                    sums[k] = sums.get(k, 0.0) + v
        means = {k: float(v) / self.cfg.grad_steps for k, v in sums.items()}  # read once per epoch
        bad = [k for k, v in means.items() if not math.isfinite(v)]
        if bad:
            self.diverged(f"non-finite {', '.join(bad)}")
        self.last_info = means

    def diverged(self, what: str) -> None:
        ckpt = self.out / "checkpoint.pt"
        where = f"last checkpoint kept at {ckpt}" if ckpt.exists() else "no checkpoint was written yet"
        raise TrainingDiverged(f"{what} at epoch {self.epoch}; {where}")  # run() reports "failed", once

    # ---- evaluation ----------------------------------------------------------------------
    def evaluate(self) -> dict[str, Any]:
        c = self.cfg
        skills = self.prior.evaluation_skills(c.eval_trajectories, seed=c.seed)
        seeds = [c.seed * 1000 + i for i in range(c.eval_trajectories)]
        traj = rollout(self.eval_env, self.agent, skills, seeds, self.normalise, True, acting_path(c.acting))
        xy = list(traj.xy.astype(np.float64))
        metrics = coverage_metrics(  # with no rule: only the rule-free ones (visited bins, states)
            xy,
            list(traj.pitch.astype(np.float64)),
            self.task,
            bin_size=self.env.metric_bin_size,
            position_dims=self.env.position_dims,
            bin_rule=c.bin_rule,
        ) | travel_metrics(xy)
        d0, d1, d2 = self.labelled.counts()
        w = self.guidance_along(traj.obs[:, ::ROLLOUT_STRIDE])  # the dashboard colours the paths by w(s)
        record: dict[str, Any] = {
            "epoch": self.epoch,
            "env_steps": self.env_steps,
            **{k: float(v) for k, v in metrics.items()},
            "n_labels": len(self.labelled),
            "n_labelled_states": [d0, d1, d2],
            **self.labels_per_class(),
            "lambda": float(self.agent.log_lambda.detach().exp()),
            "alpha": float(self.agent.log_alpha.detach().exp()),
            "beta": self.beta(),
            "wall_s": round(self.wall_s(), 2),
            **{k: v for k, v in self.last_info.items() if k not in ("lam", "alpha")},
            # after the update's diagnostics, whose w_mean is the epoch's batches': once guidance is on,
            # w_mean is the evaluations', as w_min and w_max (before, both are 1)
            **self.guidance_summary(w),
        }
        with open(self.out / "metrics.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        self.plot(traj, record, w)
        if time.monotonic() - self._curves_at >= CURVES_EVERY_S:  # a live run's curves, not only a finished one's
            self.plot_curves()
        write_whole(  # the final skills' paths, for `collie report` figures
            self.out / "eval_latest.npz",
            lambda f: np.savez_compressed(f, epoch=self.epoch, xy=traj.xy, pitch=traj.pitch, skill=traj.skill),
        )
        self.reporter.metrics(MetricsReport(self.epoch, record))
        every = slice(None, None, ROLLOUT_STRIDE)
        rollouts = RolloutsReport(
            self.epoch,
            skills=traj.skill,
            xy=traj.xy[:, every],
            stride=ROLLOUT_STRIDE,
            qpos=traj.qpos[:, every],  # the labeling UI's watch mode replays these
            w=w,  # the dashboard colours the paths by w(s)
        )
        self.reporter.rollouts(rollouts)
        return record

    def labels_per_class(self) -> dict[str, int]:
        """Labelled segments per class (a rule-free metric, as is n_labels)."""
        counts = dict.fromkeys(Label, 0)
        for segment in self.labelled.segments.values():
            counts[Label(int(segment.label))] += 1
        return {f"n_labels_{label.word}": n for label, n in counts.items()}

    def guidance_summary(self, w: np.ndarray | None) -> dict[str, float]:
        """w(s) over the evaluation rollouts (rule-free): mean, min, max; nothing while w ≡ 1."""
        if w is None or w.size == 0:
            return {}
        return {"w_mean": float(w.mean()), "w_min": float(w.min()), "w_max": float(w.max())}

    def guidance_along(self, obs: np.ndarray) -> np.ndarray | None:
        """w_e(s) = (1 − β_e)·w(s) + β_e (Eq. 8, smoothed as in Section 4.5) at states `obs`
        (n, T, *obs_shape), as COLLIE's weight_fn applies it; None while w_e ≡ 1 or for methods
        without this guidance."""
        if self.method.guidance != "labels":
            return None
        beta = self.beta()
        if len(self.labelled) == 0 or beta >= 1.0:
            return None
        raw = obs.reshape(-1, *obs.shape[2:])  # normalised a part at a time on the device, as the batches
        emb = self.labelled.embeddings(self.agent.phi, self.agent.phi_version)  # (no float copy of all frames)
        normalised = self.device_replay.normalised
        with torch.no_grad():
            w = torch.cat(
                [
                    guidance_weight(self.agent.phi(normalised(torch.as_tensor(part, device=self.device))), emb)
                    for part in np.array_split(raw, -(-len(raw) // 4096))
                ]
            )
        return ((1.0 - beta) * w + beta).cpu().numpy().astype(np.float64).reshape(obs.shape[:2])

    def plot(self, traj: Trajectories, record: dict[str, Any], w: np.ndarray | None = None) -> None:
        labelled = [(self.segment_xy[q], s.label) for q, s in self.labelled.segments.items() if q in self.segment_xy]
        title = f"{self.cfg.method} · {self.cfg.env} {self.cfg.task} · epoch {self.epoch} · "
        if "safe_coverage" in record:
            title += f"safe cov {record['safe_coverage']:.0f} · ratio {record['safe_ratio']:.2f}"
        else:  # no rule: what needs none
            title += f"{record['n_bins']} bins visited · {record['n_labels']} labels"
        path = self.out / "plots" / f"skills_epoch{self.epoch:05d}.png"
        plot_skill_trajectories(
            list(traj.xy),
            self.task,
            path,
            skills=traj.skill,
            position_dims=self.env.position_dims,
            title=title,
            labelled=labelled,
        )
        (self.out / "skills_latest.png").write_bytes(path.read_bytes())
        if w is not None and self.env.position_dims == 2:  # the map coloured by w(s) (needs no rule)
            guidance = f"{self.cfg.method} · {self.cfg.env} {self.cfg.task} · epoch {self.epoch} · w(s)"
            xy = list(traj.xy[:, ::ROLLOUT_STRIDE])  # the states w was computed at
            out = self.out / "guidance_latest.png"
            plot_guidance_map(xy, w, out, task=self.task, title=guidance, labelled=labelled)

    def plot_curves(self, records: list[dict[str, Any]] | None = None) -> None:
        """curves.png from metrics.jsonl's evaluations (or `records`, read from it already)."""
        if records is None:
            records = [json.loads(ln) for ln in (self.out / "metrics.jsonl").read_text().splitlines() if ln]
        if records:
            title = f"{self.cfg.method} · {self.cfg.env} {self.cfg.task} · seed {self.cfg.seed} · {self.out.name}"
            plot_curves(records, [k for k in CURVE_KEYS if k in records[-1]], self.out / "curves.png", title)
        self._curves_at = time.monotonic()

    # ---- persistence ---------------------------------------------------------------------
    @property
    def trains_nothing(self) -> bool:
        """A finished run resumed with no more epochs: its wall time, and what the service holds, stay."""
        return self._t0 is None

    def wall_s(self) -> float:
        return self.wall_before + (time.perf_counter() - self._t0 if self._t0 is not None else 0.0)

    def state_dict(self) -> dict[str, Any]:
        return {
            "config": self.cfg.to_dict(),
            "epoch": self.epoch,
            "env_steps": self.env_steps,
            "session": self.session,
            "first_feedback_epoch": self.first_feedback_epoch,
            "wall_s": self.wall_s(),
            "agent": self.agent.state_dict(),
            "labelled": self.labelled.state_dict(),
            "asked": self.asked,
            "segment_xy": self.segment_xy,
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "cuda_rng": torch.cuda.get_rng_state(self.device) if self.device.type == "cuda" else None,  # its GPU's only
            "python_rng": random.getstate(),
            "feedback": self.feedback.state_dict(),
            "last_info": self.last_info,
            "instruction": self.instruction.state_dict() if self.instruction is not None else None,
            "asking": self._asking,  # set only when a stop came during a feedback wait
        }

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.epoch, self.env_steps, self.session = s["epoch"], s["env_steps"], s["session"]
        self.checkpointed_at = self.epoch
        self.first_feedback_epoch, self.wall_before = s["first_feedback_epoch"], s["wall_s"]
        self.agent.load_state_dict(s["agent"])
        if "chunks" in s["replay"]:
            self.replay_log.restore(s["replay"])
        else:  # a checkpoint from before the replay log held the whole replay
            self.replay.load_state_dict(s["replay"])
        self.device_replay.sync(np.arange(self.replay.count))
        self.labelled.load_state_dict(s["labelled"])
        self.asked, self.segment_xy, self.last_info = s["asked"], s["segment_xy"], s["last_info"]
        if self.instruction is not None and s.get("instruction") is not None:
            self.instruction.load_state_dict(s["instruction"])
        self.rng.bit_generator.state = s["rng"]
        torch.set_rng_state(s["torch_rng"])
        cuda_rng, gpu = s["cuda_rng"], self.device.index or 0
        if isinstance(cuda_rng, list):  # before 12-07 every visible GPU's: this run's
            cuda_rng = cuda_rng[gpu] if gpu < len(cuda_rng) else None
        if cuda_rng is not None and self.device.type == "cuda":  # not when the run moved off its GPU
            torch.cuda.set_rng_state(cuda_rng, self.device)
        random.setstate(s["python_rng"])
        self._asking = s.get("asking")  # this epoch's rollouts are in; its feedback, update, … are not
        # checkpoints from before the source kept its own state stored the oracle's RNG as teacher_rng
        self.feedback.load_state_dict(s.get("feedback", {"rng": s.get("teacher_rng")}))

    def checkpoint(self) -> None:
        """checkpoint.pt without the replay, whose new trajectories go to one more chunk first."""
        state = self.state_dict()
        state["replay"] = self.replay_log.flush()
        save_checkpoint(self.out / "checkpoint.pt", state)
        self.checkpointed_at = self.epoch
        self.replay_log.prune()

    def _on_signal(self, signum: int, _frame: Any) -> None:
        if self._signalled is not None:  # a second signal: stop now, without a checkpoint
            raise KeyboardInterrupt
        self._signalled = signum
        reason = f"stopped by signal {signal.Signals(signum).name}"
        self.feedback.interrupt(reason)  # the waits check it too: a raise from here can be dropped
        if self._waiting:
            raise StopRequested(reason)
        # said at once (a pixel epoch on a CPU takes many minutes); os.write: a print here could land
        # inside the progress bar's own write to stderr and raise "reentrant call"
        below_bar = "\n" if self.progress else ""
        said = f"collie train: {signal.Signals(signum).name}: stopping at the end of epoch {self.epoch}, with a "
        os.write(2, f"{below_bar}{said}checkpoint; again to stop at once, without one\n".encode())

    def name_the_phase(self, bar: Any) -> None:
        """The bar says the epochs before `start_transitions` are rollouts alone; at the first epoch
        with updates its rate starts again, so its ETA is not theirs (a pixel paper epoch's
        rollouts take seconds, its updates many minutes on a CPU: the ETA said hours for weeks)."""
        collecting = self.replay.transitions < self.cfg.start_transitions
        if self._collecting and not collecting:
            bar.reset(total=self.cfg.epochs)  # elapsed and rate from now: "?" until this epoch ends
            bar.n = bar.last_print_n = bar.initial = self.epoch - 1
        self._collecting = collecting
        bar.set_description(self.phase())

    def phase(self) -> str:
        return f"collecting {self.cfg.start_transitions} start transitions" if self._collecting else "training"

    def _install_signal_handlers(self) -> dict[int, Any]:
        if threading.current_thread() is not threading.main_thread():
            return {}  # signals reach only the main thread; an embedded trainer keeps its host's handlers
        before: dict[int, Any] = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGTERM, signal.SIGINT)}
        if early_term.ASKED.is_set():  # a SIGTERM while the run resumed, rebuilt or evaluated: stop at once
            self._signalled = signal.SIGTERM
        return before

    def check_checkpoint_config(self, path: Path, saved: Any) -> None:
        """Refuse a checkpoint whose own config is another run's (one copied from a run of the same
        network shapes would load, and continue that run under this one's name). Its epochs may be
        fewer (--resume --epochs extends a run); where and how it ran do not count (same_run)."""
        from trainer.same_run import differing_keys

        if not isinstance(saved, dict):  # a checkpoint from before it carried its config
            return
        try:
            theirs = Config.from_stored(saved, f"{path}'s config").to_dict()
        except ValueError as exc:
            raise ResumeError(str(exc)) from None
        keys = differing_keys(theirs, self.cfg.to_dict(), besides=("epochs",))
        if keys:
            raise ResumeError(
                f"{path} does not fit this run's config.json (copied from another run?): its config differs in "
                + ", ".join(f"{k} ({theirs.get(k)!r} there, {getattr(self.cfg, k, None)!r} here)" for k in keys[:6])
                + (f" and {len(keys) - 6} more" if len(keys) > 6 else "")
            )

    def resume(self) -> None:
        path = self.out / "checkpoint.pt"
        state = load_checkpoint(path)
        self.check_checkpoint_config(path, state.get("config"))
        try:
            self.load_state_dict(state)
        except ResumeError:  # a file of the run named already (a replay chunk missing)
            raise
        except (RuntimeError, ValueError, KeyError) as exc:  # networks or optimisers of another run's shape
            if not isinstance(exc, KeyError) and not re.search(r"state[ _]dict", str(exc)):
                raise  # not a mismatch (out of memory, say): as it is
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ResumeError(
                f"{path} does not fit this run's config.json (copied from another run?): {first[:200]}"
            ) from None
        damaged = non_finite(self.agent.state_dict())
        if damaged:  # a flipped bit reads as NaN: training would only fail an epoch later, as if it diverged
            raise ResumeError(f"{path} holds non-finite values ({damaged}): it is damaged; resume an intact copy")
        metrics = self.out / "metrics.jsonl"  # drop evaluations written after that checkpoint
        if metrics.exists():
            lines = [ln for ln in metrics.read_text(errors="replace").splitlines() if ln]
            keep = []
            for i, ln in enumerate(lines):
                try:
                    record = json.loads(ln)
                except json.JSONDecodeError as exc:
                    if i == len(lines) - 1:  # a crash while appending tears only the last line
                        break
                    raise ResumeError(f"{metrics} line {i + 1} is not valid JSON ({exc.msg})") from None
                epoch = record.get("epoch") if isinstance(record, dict) else None
                if not isinstance(epoch, int) or isinstance(epoch, bool):  # written by hand, or another file's
                    raise ResumeError(f'{metrics} line {i + 1} is no evaluation (no integer "epoch"): {ln[:80]}')
                if epoch <= self.epoch:
                    keep.append(ln)
            text = "".join(ln + "\n" for ln in keep).encode()
            write_whole(metrics, lambda f: f.write(text))  # a kill here leaves the history whole

    # ---- the loop ------------------------------------------------------------------------
    def collect_epoch(self) -> None:
        n = self.cfg.episodes_per_epoch
        skills = self.prior.sample(n, self.rng)
        seeds = [int(x) for x in self.rng.integers(0, 2**31 - 1, size=n)]
        traj = rollout(self.env, self.agent, skills, seeds, self.normalise, False, acting_path(self.cfg.acting))
        if not np.isfinite(traj.action).all():  # MuJoCo would silently reset on a NaN control
            self.diverged("non-finite action")
        if not np.isfinite(traj.obs).all():
            self.diverged("non-finite observation")
        slots = self.replay.add(
            traj.obs, traj.action, traj.skill, traj.xy, traj.pitch, traj.qpos, traj.qvel, self.epoch
        )
        self.device_replay.sync(slots)
        self.env_steps += n * self.cfg.episode_steps

    def say(self, what: str) -> None:
        """A line for a log where no progress bar is drawn (a sweep's run, collie up's trainer): else
        a wait for people, or for an operator's resume, is silence as long as it lasts."""
        if not self.progress:
            print(f"epoch {self.epoch}/{self.cfg.epochs} · {what}", file=sys.stderr, flush=True)
            self._said = (time.monotonic(), self.epoch)

    def heartbeat(self) -> None:
        """With no bar (a log), a line at most every HEARTBEAT_S: the run's pace and time left, so a
        log between evaluations (minutes apart for a robot's cpu preset) shows the run going."""
        when, epoch = self._said
        elapsed = time.monotonic() - when
        if self.progress or elapsed < HEARTBEAT_S or self.epoch in (epoch, self.cfg.epochs):
            return
        if self._collecting:
            self.say(f"collecting {self.cfg.start_transitions} start transitions")
            return
        rate = (self.epoch - epoch) / elapsed  # since the last line (a wait for labels has lines of its own)
        left = (self.cfg.epochs - self.epoch) / rate if rate > 0 else math.inf
        shown = f"{left / 60:.0f} min" if left < 7200 else f"{left / 3600:.1f} h"
        shown = "under a minute" if left < 60 else "?" if not math.isfinite(left) else shown
        self.say(f"{rate * 60:.1f} epochs/min · about {shown} left at this pace")

    def wait_while_paused(self, bar: Any) -> bool:
        """Honour the operator: returns False when the run must stop."""
        wish = self.feedback.control(self.epoch)
        if wish == "pause":
            self.reporter.status(StatusReport("paused", self.epoch))
            bar.set_description("paused")
            self.say("paused by an operator")
            self._waiting = True
            try:
                while wish == "pause":
                    if self.feedback.interrupted is not None:
                        raise StopRequested(self.feedback.interrupted)
                    time.sleep(0.5)
                    wish = self.feedback.control(self.epoch)
            finally:
                self._waiting = False
            if wish != "stop":
                self.reporter.status(StatusReport("training", self.epoch))
                self.say("resumed")
        return wish != "stop"

    def run(self, resume: bool = False) -> dict[str, Any]:
        from tqdm import tqdm

        self.out.mkdir(parents=True, exist_ok=True)
        self._t0 = time.perf_counter()
        if resume:
            self.resume()
            if self.epoch >= self.cfg.epochs and self._asking is None:  # a finished run: its wall time stays
                self._t0, self.wall_before = None, summary_wall_s(self.out, self.wall_before)
        else:
            (self.out / "metrics.jsonl").write_text("")
        write_json(self.out / "config.json", self.cfg.to_dict())
        write_json(self.out / TASK_JSON, self.rule.to_json())
        self.rebuild_from_source()
        if not self.method.asks_labels or self.queries_asked >= self.cfg.total_queries:
            startup.done()  # no feedback session will come: no first segment to time
        try:
            if self.epoch < self.cfg.epochs or self._asking is not None:  # else no event file with nothing in it
                self._writer = self._tensorboard()
            # a finished run resumed is not announced, nor one paused or stopped meanwhile
            if not self.trains_nothing and self.feedback.control(self.epoch) == "run":
                self.reporter.status(StatusReport("training", self.epoch))
            startup.mark("run files, tensorboard")
            if self.epoch == 0:
                self.evaluate()  # epoch-0 baseline of every metric
                startup.mark("evaluate", 0)
        except BaseException:  # e.g. Ctrl-C before the loop's handlers: its writer thread ends before the caller
            self.close_tensorboard()  # removes what a fresh start wrote (tb/ included)
            raise
        asking = self._asking
        self._collecting = self.replay.transitions < self.cfg.start_transitions
        self._said = (time.monotonic(), self.epoch)  # the pace is this process's
        bar = tqdm(
            total=self.cfg.epochs,
            initial=self.epoch - (asking is not None),
            disable=not self.progress,
            unit="epoch",
            dynamic_ncols=True,
            desc=self.phase(),
        )
        status: LoopStatus = "finished"
        record: dict[str, Any] | None = None
        refused: SourceRefused | None = None
        diverged: TrainingDiverged | None = None
        previous_handlers = self._install_signal_handlers()
        try:
            if asking is not None:  # resumed in the feedback wait of epoch self.epoch: its rest first
                record = self.rest_of_epoch(bar, asking) or record
            while self.epoch < self.cfg.epochs and self._signalled is None:
                if not self.wait_while_paused(bar):
                    status = "stopped"
                    break
                self.epoch += 1
                self.collect_epoch()
                self.name_the_phase(bar)
                startup.mark("collect", self.epoch)
                record = self.rest_of_epoch(bar) or record
                self.heartbeat()
            if self._signalled is not None:
                status = "stopped"
        except StopRequested:
            status = "stopped"
        except SourceRefused as exc:  # no label can come: end resumable, as after a signal
            status, refused = "interrupted", exc
        except TrainingDiverged as exc:  # the run failed: its summary says so (the checkpoint stays the last good one)
            status, diverged = "failed", exc
        finally:
            for sig, handler in previous_handlers.items():
                signal.signal(sig, handler)
            bar.close()
            self.close_tensorboard()
        if status == "stopped" and self._signalled is not None:
            status = "interrupted"  # the process was told to end, not the run: `--resume` continues it
        if status == "stopped" and self._asking is not None:  # an operator's stop, in a feedback wait
            self.end_the_wait()
        if status in ("stopped", "interrupted"):
            self.checkpoint()
        summary = self.finish(status, record, error=None if diverged is None else str(diverged))
        if diverged is not None:
            raise diverged
        if refused is not None:  # the caller says why, now that the run is saved
            raise SourceRefused(f"{refused}; the run is checkpointed at epoch {self.epoch}", refused.advice)
        if self.feedback.refusal is not None:  # met in the last epoch, after its last control()
            refusal = self.feedback.refusal
            raise SourceRefused(f"{refusal}; the run finished, but the service was not told", refusal.advice)
        return summary

    def end_the_wait(self) -> None:
        """An operator stopped the run while it waited for a session's labels: the run ends there and
        is never resumed, so the session's segments join those asked, for finish() to apply the
        labels that came for them, as the service counts them."""
        assert self._asking is not None
        self.remember_asked(self._asking)
        self._asking = None

    def remember_asked(self, segments: list[Segment]) -> None:
        """A session's segments, asked: kept for their labels (late ones too) and the maps."""
        for s in segments:
            self.asked[s.query_id], self.segment_xy[s.query_id] = s.obs, s.xy

    def rest_of_epoch(self, bar: Any, asking: list[Segment] | None = None) -> dict[str, Any] | None:
        """The epoch after its rollouts: the feedback session (`asking`: the one a stopped run was
        waiting on), revisions, the update, and the evaluation (returned, if due) and checkpoint."""
        record = None
        if asking is not None or self.is_feedback_epoch():
            bar.set_description("waiting for labels")
            people = not isinstance(self.feedback, OracleFeedback)  # the oracle answers at once
            if people:
                self.say(f"waiting for labels (feedback session {self.session})")
            self.feedback_session(asking)
            if people:
                self.say(f"labels in · labels {len(self.labelled)}")
            bar.set_description(self.phase())
            self._postfix["labels"] = len(self.labelled)  # the bar's count: not only at the next evaluation
            bar.set_postfix(self._postfix)
        self.apply_labels(self.feedback.revisions())
        self.train_epoch()
        self.log_scalars()
        startup.mark("update", self.epoch)
        if self.epoch % self.cfg.eval_every == 0 or self.epoch == self.cfg.epochs:
            record = self.evaluate()
            startup.mark("evaluate", self.epoch)
            if not self.progress:  # a log, not a terminal: a line each
                print(
                    evaluation_line(self.epoch, self.cfg.epochs, record, len(self.labelled)),
                    file=sys.stderr,
                    flush=True,
                )
                self._said = (time.monotonic(), self.epoch)
            self._postfix = {
                "labels": len(self.labelled),
                "safe_cov": coverage_shown(record),
                "bins": f"{record['n_bins']:.0f}",  # a float: tqdm would show 1,340 bins as 1.34e+03
                "lam": f"{record['lambda']:.1f}",
            }
            bar.set_postfix(self._postfix)
        if self.epoch % self.cfg.checkpoint_every == 0 or self.epoch == self.cfg.epochs:
            self.checkpoint()
            startup.mark("checkpoint", self.epoch)
        bar.update(1)
        self.report_progress()
        return record

    def report_progress(self) -> None:
        """The current epoch for live views, at most once a second (best effort, skipped while the
        service is unreachable)."""
        now = time.monotonic()
        if now - getattr(self, "_last_progress", 0.0) >= 1.0:
            self._last_progress = now
            self.reporter.status(StatusReport("training", self.epoch, progress=True))

    def finish(self, status: LoopStatus, record: dict[str, Any] | None, error: str | None = None) -> dict[str, Any]:
        records = [json.loads(ln) for ln in (self.out / "metrics.jsonl").read_text().splitlines() if ln]
        last = record or (records[-1] if records else {})
        # the last evaluation's metrics (its `epoch`), and the run's own epochs and wall time: an
        # interrupted run's last evaluation may lie many epochs back
        summary = {
            **last,
            "status": status,
            **({"error": error} if error else {}),
            "epochs_done": self.epoch,
            "wall_s": round(self.wall_s(), 2),
            "config": self.cfg.to_dict(),
        }
        write_json(self.out / "summary.json", summary)
        self.plot_curves(records)
        # an interrupted run is not over for the service; a finished one resumed told it so before
        if status != "interrupted" and not self.trains_nothing:
            self.reporter.status(StatusReport(status, self.epoch, error=error))
            # labels given until the service closed the run just now (after a feedback timeout, or
            # an operator's stop: the service counts them, and no later epoch will apply them)
            if status != "failed" and (late := self.feedback.revisions()):
                self.apply_labels(late)
                self.checkpoint()
        return summary

    def close_tensorboard(self) -> None:
        if self._writer is not None:
            self._writer.close()  # flushes, and ends its writer thread
            self._writer = None

    def _tensorboard(self) -> Any:
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:  # TensorBoard is optional at run time
            return None
        return SummaryWriter(str(self.out / "tb"), purge_step=self.epoch + 1)

    def log_scalars(self) -> None:
        if self._writer is None or not self.last_info:
            return
        for k, v in self.last_info.items():
            self._writer.add_scalar(f"train/{k}", v, self.epoch)
        self._writer.add_scalar("train/n_labels", len(self.labelled), self.epoch)
        self._writer.add_scalar("train/beta", self.beta(), self.epoch)
