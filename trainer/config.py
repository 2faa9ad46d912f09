"""Run configuration: one dataclass, three named presets, per-env defaults, CLI overrides.

`paper` is Appendix E (Tables 5–6) of the COLLIE paper; `cpu` is chosen so that a point-mass run
shows the guidance effect in minutes on 2 cores, with per-env budgets for the real robots (Ant,
HalfCheetah: `ROBOT_CPU`, about an hour per run) and the pixel bodies; `smoke` finishes in seconds
for tests.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import re
import types
from dataclasses import dataclass, field
from typing import Any, Literal, get_args, get_origin, get_type_hints

from collie.env_names import ENV_NAMES, PIXEL_ENVS
from collie.tasks import default_task
from trainer.methods import METHODS
from trainer.metrics import BIN_RULES
from trainer.obs_stats import OBS_NORMS, REFERENCE_STATS
from trainer.replay import trajectories_held
from trainer.run_files import RunFolderError

LABEL_METHODS = tuple(n for n, m in METHODS.items() if m.asks_labels)  # they ask the feedback source for labels
RULE_METHODS = tuple(n for n, m in METHODS.items() if m.guidance == "task")  # they read the rule itself
DISTANCES = ("temporal", "l2")
REWARD_FORMS = ("multiplicative", "additive")
ENCODERS = ("separate", "shared")
QUERY_STRATEGIES = ("entropy", "uniform", "uncertainty", "latent")
PRESETS = ("paper", "cpu", "smoke")
INITS = ("reference", "torch")
DIAYN_VARIANTS = ("reference", "sphere")
ACTING_PATHS = ("fast", "torch")  # trainer/acting.py
DEVICE_NAMES = r"auto|cpu|mps|cuda(:\d+)?"  # whether one is present is checked where it is used (trainer/loop.py)
REFERENCE_LOG_STD_MIN = math.log(1e-6)  # garage's Gaussian modules: min_std 1e-6 (the policy's floor)


@dataclass
class Config:
    # what to run
    env: str = "point"
    task: str = "north"  # make_config gives each env its own (collie.tasks.default_task)
    task_file: str = ""  # a task rule from a file (docs/tasks.md); its task's name becomes `task`
    instruction: str = ""  # no rule: people label by this intent (task "instruction"); docs/tasks.md
    method: str = "collie"  # a name in trainer.methods.METHODS
    preset: str = "cpu"
    seed: int = 0
    device: str = "auto"  # auto → cuda when available
    threads: int = 0  # torch intra-op threads; 0 = auto (trainer/threads.py: 1 on ≤ 4 cores or small nets)
    physics_threads: int = 0  # rollout groups overlapping the policy; 0 = 1 = one group (trainer/envs/vector.py)
    compile: bool = False  # torch.compile the networks' training passes (Metra.compile); off: not faster here
    fused_adam: bool = True  # Adam's fused kernel (trainer/optim.py); false: foreach, as runs before 12-05
    flush_denormal: bool = True  # the update flushes denormals to zero (trainer/denormals.py); false: before 12-06
    # tanh as 2σ(2x) − 1, one-output Q layer as multiply-sum (networks.py); false: before 12-05;
    # None: on where they measured faster (trainer/fast_ops.py), fixed when the trainer starts
    fast_ops: bool | None = None  # tanh as 2σ(2x) − 1 and a multiply-sum one-output layer; unset: where measured faster
    acting: Literal["fast", "torch"] = "fast"  # rollouts' π path (trainer/acting.py); torch: as runs before 12-01
    # networks and optimisation (Table 5)
    hidden: int = 1024  # width of every MLP layer (φ, π, Q)
    layers: int = 2  # hidden layers per MLP
    encoder: Literal["separate", "shared"] = "separate"  # pixel envs: a CNN per network, or one for all
    init: Literal["reference", "torch"] = "reference"  # weight init: the reference's Xavier schemes, or torch's
    log_std_min: float = REFERENCE_LOG_STD_MIN  # the policy's log-std floor (the reference's; −5 before)
    obs_norm: Literal["reference", "rollout"] = "rollout"  # ant/half_cheetah default to METRA's preset
    lr: float = 1e-4  # Adam's learning rate, every network
    batch_size: int = 256  # transitions per gradient step
    gamma: float = 0.99  # discount
    tau: float = 0.005  # Polyak: target ← (1 − τ)·target + τ·online, i.e. smoothing coefficient 0.995
    alpha_init: float = 0.01  # SAC's entropy temperature at the start (learned)
    target_entropy_scale: float = -0.5  # target entropy = scale · |A|
    # METRA dual (Eq. 10)
    lambda_init: float = 30.0  # METRA's dual variable λ at the start (learned)
    epsilon: float = 1e-3  # ε of METRA's constraint slack
    # skills
    skill_dim: int = 2  # dimensions of z (one-hot count with discrete skills)
    discrete_skills: bool = False  # one-hot z (HalfCheetah), else z on the unit sphere
    # data collection
    epochs: int = 10_000  # rollouts + gradient steps; the run's length
    episodes_per_epoch: int = 8  # episodes rolled out per epoch
    episode_steps: int = 200  # steps per episode
    grad_steps: int = 50  # gradient steps per epoch
    start_transitions: int = 10_000  # no gradient step before this many transitions are stored
    replay_capacity: int = 1_000_000  # transitions
    # COLLIE feedback schedule and guidance (Table 6)
    warmup: int = 2000  # epochs before the first feedback session
    feedback_every: int = 1000  # K: epochs between feedback sessions
    queries_per_session: int = 5  # M: segments asked per feedback session
    total_queries: int = 40  # N_total: segments asked in the whole run (the label budget)
    segment_length: int = 20  # H
    k_beta: float = 5.0  # k_β: how fast guidance fades in after the first labels (smoothing β, Section 4.5)
    candidates: int = 50  # N_c: candidate segments the queries are picked from
    knn_k: int = 5  # k of the k-NN particle entropy that picks queries (Algorithm 2)
    query_strategy: Literal["entropy", "uniform", "uncertainty", "latent"] = "entropy"  # how queries are picked
    w_at: Literal["next", "current"] = "next"  # evaluate w at s′ (reference, issue) or s (paper's notation)
    noise_band: float = 0.0  # oracle teacher's R_error
    # baselines and ablations (Section 5.1, Appendix E–F; trainer/methods.py)
    distance: Literal["temporal", "l2"] = "temporal"  # DSD constraint: METRA's, or Euclidean (LSD, COLLIE-L2)
    reward_form: Literal["multiplicative", "additive"] = "multiplicative"  # Eq. 11, or Δφᵀz + w (ablation)
    obs_noise: float = 0.0  # std of x in the observed ŝ = (1 + x)·s; the paper's ablation is 0.1 (x ~ N(0, 0.01))
    classifier_steps: int = 500  # DoDont*/DDG*: Adam steps fine-tuning ψ each time the labels change
    projection_dim: int = 8  # DoDont*/DDG*: output width of ψ's encoder (DDG*: the state projection φ reads)
    diayn: Literal["reference", "sphere"] = "reference"  # DIAYN: z ~ N(0, I), α = 0.1, learned std; or ours
    # evaluation, logging, checkpoints
    eval_every: int = 500  # epochs between evaluations (metrics, maps)
    eval_trajectories: int = 48  # skills rolled out per evaluation
    bin_rule: Literal["visited", "corner"] = "visited"  # headline metric rule; both are always logged
    checkpoint_every: int = 100  # epochs between checkpoints (networks, optimisers, labels)
    out: str = "runs/latest"
    extra: dict[str, Any] = field(default_factory=dict)

    def validate(self) -> None:
        def need(cond: bool, msg: str) -> None:
            if not cond:
                raise ValueError(msg)

        need(self.env in ENV_NAMES, f"unknown env {self.env!r}; valid: {', '.join(ENV_NAMES)}")
        need(self.method in METHODS, f"unknown method {self.method!r}; valid: {', '.join(METHODS)}")
        need(not (self.instruction and self.task_file), "give --instruction (no rule) or --task-file, not both")
        need(
            not (self.instruction and self.method in RULE_METHODS),
            f"method {self.method!r} trains on a task rule, and a run with only an --instruction has none; "
            f"use one that learns from people's labels: {', '.join(LABEL_METHODS)}",
        )
        need(
            self.query_strategy in QUERY_STRATEGIES,
            f"unknown query strategy {self.query_strategy!r}; valid: {', '.join(QUERY_STRATEGIES)}",
        )
        for name in (
            "epochs",
            "episodes_per_epoch",
            "episode_steps",
            "batch_size",
            "hidden",
            "layers",
            "feedback_every",
            "queries_per_session",
            "segment_length",
            "eval_every",
            "knn_k",
            "checkpoint_every",
            "skill_dim",
            "eval_trajectories",
        ):
            need(getattr(self, name) >= 1, f"{flag(name)} must be ≥ 1, got {getattr(self, name)}")
        for f in dataclasses.fields(self):  # inf or nan: first, so that `--lr inf` is named as what it is
            value = getattr(self, f.name)
            if f.type == "float" and isinstance(value, float):
                hint = " (no smoothing: a large value such as 1e9)" if f.name == "k_beta" else ""
                need(math.isfinite(value), f"{flag(f.name)} must be a finite number, got {value}{hint}")
        need(self.seed >= 0, f"--seed must be ≥ 0, got {self.seed}")  # numpy's generators take no negative seed
        for name in ("grad_steps", "start_transitions", "warmup", "total_queries", "noise_band"):
            need(getattr(self, name) >= 0, f"{flag(name)} must be ≥ 0, got {getattr(self, name)}")
        for name in ("gamma", "tau"):  # a discount and a Polyak rate: fractions
            need(0 < getattr(self, name) <= 1, f"{flag(name)} must be in (0, 1], got {getattr(self, name)}")
        for name in ("lr", "alpha_init", "lambda_init", "epsilon", "k_beta"):
            need(getattr(self, name) > 0, f"{flag(name)} must be > 0, got {getattr(self, name)}")
        # after the sizes themselves, so that `--episode-steps 0` is named as such
        need(
            self.segment_length <= self.episode_steps + 1,
            f"--segment-length {self.segment_length} must be ≤ --episode-steps + 1 = {self.episode_steps + 1}",
        )
        need(
            self.queries_per_session <= self.candidates,
            f"--queries-per-session (M) {self.queries_per_session} must be ≤ --candidates (N_c) {self.candidates}",
        )
        need(
            self.replay_capacity >= self.episode_steps * self.episodes_per_epoch,
            f"--replay-capacity {self.replay_capacity} must hold one epoch of transitions "
            f"(--episode-steps × --episodes-per-epoch = {self.episode_steps * self.episodes_per_epoch})",
        )
        held = trajectories_held(self.replay_capacity, self.episode_steps) * self.episode_steps
        need(
            self.start_transitions <= held,
            f"--start-transitions {self.start_transitions} must be ≤ the {held} transitions --replay-capacity "
            f"{self.replay_capacity} holds (whole episodes of {self.episode_steps} steps): no gradient step would "
            "ever be taken",
        )
        need(
            self.batch_size <= self.replay_capacity,
            f"--batch-size {self.batch_size} must be ≤ --replay-capacity {self.replay_capacity} (the transitions "
            "a batch is drawn from)",
        )
        need(
            re.fullmatch(DEVICE_NAMES, self.device) is not None,
            f"unknown --device {self.device!r}; valid: auto, cpu, cuda, cuda:N, mps",
        )
        need(self.w_at in ("next", "current"), f"--w-at must be 'next' or 'current', got {self.w_at!r}")
        need(self.distance in DISTANCES, f"unknown distance {self.distance!r}; valid: {', '.join(DISTANCES)}")
        need(
            self.method != "ddg" or self.distance == "temporal",
            "ddg runs on METRA's temporal distance only (--distance temporal)",
        )
        if self.env in PIXEL_ENVS:  # else refused only once the env and the nets are built, seconds in
            lipschitz = "--distance l2 (LSD's Lipschitz φ)" if self.distance == "l2" else None
            states_only = METHODS[self.method].states_only or lipschitz
            need(
                states_only is None,
                f"{states_only} reads state vectors, and {self.env} observes 64×64 pixels: choose another "
                "method or env (docs/baselines.md)",
            )
        need(
            self.reward_form in REWARD_FORMS,
            f"unknown reward form {self.reward_form!r}; valid: {', '.join(REWARD_FORMS)}",
        )
        need(self.obs_noise >= 0, f"--obs-noise must be ≥ 0, got {self.obs_noise}")
        for name in ("classifier_steps", "projection_dim"):
            need(getattr(self, name) > 0, f"{flag(name)} must be > 0, got {getattr(self, name)}")
        need(self.physics_threads >= 0, f"--physics-threads must be ≥ 0, got {self.physics_threads}")
        need(self.threads >= 0, f"--threads must be ≥ 0 (0: chosen for this machine), got {self.threads}")
        need(self.encoder in ENCODERS, f"unknown encoder {self.encoder!r}; valid: {', '.join(ENCODERS)}")
        need(self.init in INITS, f"unknown init {self.init!r}; valid: {', '.join(INITS)}")
        need(self.acting in ACTING_PATHS, f"unknown acting path {self.acting!r}; valid: {', '.join(ACTING_PATHS)}")
        need(self.log_std_min < 2.0, f"--log-std-min must be below the cap 2, got {self.log_std_min}")
        need(self.bin_rule in BIN_RULES, f"unknown bin rule {self.bin_rule!r}; valid: {', '.join(BIN_RULES)}")
        need(self.diayn in DIAYN_VARIANTS, f"unknown diayn variant {self.diayn!r}; valid: {', '.join(DIAYN_VARIANTS)}")
        need(self.obs_norm in OBS_NORMS, f"unknown obs_norm {self.obs_norm!r}; valid: {', '.join(OBS_NORMS)}")
        need(
            self.obs_norm != "reference" or self.env in REFERENCE_STATS,
            f"obs_norm 'reference' exists only for {', '.join(REFERENCE_STATS)} (METRA's presets), not "
            f"{self.env!r}; use --obs-norm rollout",
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_stored(cls, stored: dict[str, Any], source: str = "the stored config") -> Config:
        """A run's saved config.json: keys this version does not know are dropped, and options the
        run predates take the value it ran with (`FIRST_VERSION`), not today's default. A value of
        another type than its field's (`"hidden": "64"`, edited by hand): RunFolderError naming
        `source`, the key and the value, not a TypeError deep in the trainer."""
        hints = get_type_hints(cls)
        values = {**first_version(stored), **{k: v for k, v in stored.items() if k in hints}}
        for key, value in values.items():
            kind = of_type(value, hints[key])
            if kind:
                raise RunFolderError(f"{source}: {key!r} must be {kind}, got {json.dumps(value, default=repr)}")
        return cls(**values)

    @property
    def n_sessions(self) -> int:
        return -(-self.total_queries // self.queries_per_session)


def of_type(value: Any, hint: Any) -> str | None:
    """None if `value` (as JSON gives it) fits the field type `hint`, else what it should be: an int
    is no bool and no float; a float may be written as an int."""
    if get_origin(hint) is Literal:
        return None if value in get_args(hint) else f"one of {', '.join(map(json.dumps, get_args(hint)))}"
    if isinstance(hint, types.UnionType):
        wrong = [of_type(value, h) for h in get_args(hint)]
        return None if None in wrong else " or ".join(w for w in wrong if w)
    if hint is type(None):
        return None if value is None else "null"
    if hint is bool:
        return None if isinstance(value, bool) else "true or false"
    if hint is int:
        return None if isinstance(value, int) and not isinstance(value, bool) else "an integer"
    if hint is float:
        return None if isinstance(value, int | float) and not isinstance(value, bool) else "a number"
    origin = get_origin(hint) or hint
    return None if isinstance(value, origin) else f"a {origin.__name__}"  # dict: `extra`


# What runs saved before these options existed ran with (they wrote no such key).
FIRST_VERSION: dict[str, Any] = dict(
    init="torch",
    log_std_min=-5.0,
    diayn="sphere",
    obs_norm="rollout",
    bin_rule="visited",
    fused_adam=False,
    fast_ops=False,
    flush_denormal=False,
    acting="torch",
)
# Options whose later value a saved config shows by holding a key that came after it. `acting`
# entered the config on 12-05 (5136c49), but rollouts acted through `Actor` ("fast") from 12-01
# 16:07 (18403cf); `physics_threads`, saved from 16:48 (7288454), tells the two apart. A run
# started in the 41 minutes between reads as torch.
LATER_BY_KEY: dict[str, tuple[str, Any]] = {"acting": ("physics_threads", "fast")}


def first_version(stored: dict[str, Any]) -> dict[str, Any]:
    """What a saved config ran with for the options it holds no key of (FIRST_VERSION, with
    LATER_BY_KEY's values where its own keys date it)."""
    return FIRST_VERSION | {k: later for k, (key, later) in LATER_BY_KEY.items() if key in stored}


PRESET_VALUES: dict[str, dict[str, Any]] = {
    "paper": {},  # the dataclass defaults are the paper's values
    "cpu": dict(
        hidden=256,
        lr=1e-3,
        batch_size=256,
        epochs=400,
        episodes_per_epoch=8,
        episode_steps=200,
        grad_steps=32,
        start_transitions=3200,
        replay_capacity=200_000,
        warmup=40,
        feedback_every=25,
        queries_per_session=5,
        total_queries=40,
        segment_length=20,
        candidates=50,
        knn_k=5,
        eval_every=25,
        checkpoint_every=25,
    ),
    "smoke": dict(
        hidden=64,
        lr=1e-3,
        batch_size=64,
        epochs=8,
        episodes_per_epoch=4,
        episode_steps=50,
        grad_steps=8,
        start_transitions=200,
        replay_capacity=5_000,
        warmup=2,
        feedback_every=2,
        queries_per_session=2,
        total_queries=6,
        segment_length=5,
        candidates=6,
        knn_k=2,
        eval_every=4,
        eval_trajectories=8,
        checkpoint_every=2,
        threads=1,
    ),
}

# Per-env choices of the reference (skills, observation statistics) that every preset shares
# unless overridden.
ENV_DEFAULTS: dict[str, dict[str, Any]] = {
    "ant": dict(obs_norm="reference"),
    "half_cheetah": dict(discrete_skills=True, skill_dim=16, obs_norm="reference"),
    "quadruped": dict(skill_dim=4),  # METRA's pixel Quadruped; Humanoid keeps 2
}

# The pixel robots (Quadruped, Humanoid) per preset. `paper`: Tables 5–6 and the reference
# (5000 epochs, 200 gradient steps, N_total 100, evaluation every 125 epochs, replay 300k as
# uint8). The paper keeps K = 1000 and warm-up 2000, which leave room for 15 of the 100 labels
# in 5000 epochs; we keep M = 5 and the warm-up and ask every 150 epochs, so the 20 sessions end
# at epoch 4850. `cpu` only tries the loop out (a CNN update costs ≈ 1 s on 2 cores);
# `smoke` finishes in seconds.
PIXEL_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(
        epochs=5000, grad_steps=200, total_queries=100, feedback_every=150, eval_every=125, replay_capacity=300_000
    ),
    "cpu": dict(
        hidden=256,
        batch_size=32,
        epochs=40,
        grad_steps=4,
        start_transitions=1600,
        replay_capacity=20_000,
        warmup=10,
        feedback_every=5,
        eval_every=10,
        eval_trajectories=8,
        checkpoint_every=10,
    ),
    "smoke": dict(
        hidden=32,
        batch_size=8,
        epochs=3,
        episodes_per_epoch=2,
        episode_steps=20,
        grad_steps=2,
        start_transitions=20,
        replay_capacity=400,
        warmup=1,
        feedback_every=1,
        queries_per_session=2,
        total_queries=4,
        segment_length=5,
        candidates=4,
        eval_every=3,
        eval_trajectories=2,
    ),
}


def feedback_schedule(epochs: int, sessions: int = 8, first: int | None = None) -> dict[str, int]:
    """The paper's feedback proportions (Table 6: warm-up 2000 and K = 1000 of 10 000 epochs) scaled
    to `epochs`: warm-up 20 % of training, then a session every 10 %, so 8 sessions end at 90 %.
    `first` brings the first session forward (`people_schedule`); the others then spread evenly so
    the last still comes at 90 %."""
    if first is None:
        warmup, every = max(1, epochs // 5), max(1, epochs // 10)
    else:
        warmup, every = first, max(1, (epochs * 9 // 10 - first) // max(1, sessions - 1))
    if warmup < 1 or warmup + (sessions - 1) * every >= epochs:
        raise ValueError(f"{sessions} sessions do not fit in {epochs} epochs")
    return dict(warmup=warmup, feedback_every=every)


# Ant and HalfCheetah on 2 cores (`cpu` preset), chosen by experiment (docs/results.md, "Real robots
# at CPU scale"): each gets the most epochs that fit an hour per run with two runs sharing the
# machine, at the paper's 50 gradient steps per epoch and 2×256 nets. Ant: 2000 epochs (3.2 M env
# steps, 100 k gradient steps), 53–59 min per guided run two at a time; at the former 1200 METRA's
# skills travelled on 2 seeds of 3 and COLLIE's North safe ratio was 0.74 ± 0.12, at 2000 on 3 of 3
# and 0.96 ± 0.03. HalfCheetah's final-x spread passed 20 m by epoch 400 (49 m); 1600 epochs (2.6 M
# env steps, 80 k gradient steps) fit the hour. Both keep lr 1e-3 and batch 256; the paper's are
# 2×1024 and 1e-4 over 10 000 epochs (16 M env steps, 500 k gradient steps).
ROBOT_CPU: dict[str, dict[str, Any]] = {
    env: dict(
        epochs=epochs,
        grad_steps=50,
        start_transitions=10_000,
        replay_capacity=500_000,
        eval_every=100,
        checkpoint_every=100,
        **feedback_schedule(epochs),
    )
    for env, epochs in (("ant", 2000), ("half_cheetah", 1600))
}
PRESET_ENV_VALUES: dict[str, dict[str, dict[str, Any]]] = {
    preset: {"quadruped": values, "humanoid": values} for preset, values in PIXEL_PRESETS.items()
}
PRESET_ENV_VALUES["cpu"].update(ROBOT_CPU)


def field_notes() -> dict[str, str]:
    """Each Config field's inline comment (what `collie train --help` says of its flag)."""
    note = re.compile(r"^    (\w+): [^#]*#\s*(.+)$")
    try:
        source = inspect.getsource(Config)
    except OSError:  # installed without its sources: flags without words, not a failing --help
        return {}
    return {m[1]: m[2] for line in source.splitlines() if (m := note.match(line))}


def flag(name: str) -> str:
    """The command-line flag of a config key (`collie train --help`), for messages."""
    return "--" + name.replace("_", "-")


def make_config(preset: str = "cpu", env: str = "point", **overrides: Any) -> Config:
    """Preset values, then per-env defaults, then the preset's per-env values, then explicit
    overrides (None values ignored)."""
    if preset not in PRESET_VALUES:
        raise ValueError(f"unknown preset {preset!r}; valid: {', '.join(PRESETS)}")
    values: dict[str, Any] = {"preset": preset, "env": env, "task": default_task(env)}
    values.update(PRESET_VALUES[preset])
    values.update(ENV_DEFAULTS.get(env, {}))
    values.update(PRESET_ENV_VALUES[preset].get(env, {}))
    values.update({k: v for k, v in overrides.items() if v is not None})
    known = {f.name for f in dataclasses.fields(Config)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown config keys: {', '.join(unknown)}")
    cfg = Config(**values)
    cfg.validate()
    return cfg


# When people label (`collie up` without a teacher), the epoch of the first session where the
# preset's 20 % warm-up would keep them waiting past ten minutes on this machine: Ant's epoch 240
# was ready 8.8 min after start (docs/results.md); the preset's epoch 400 would take ≈ 14 min.
PEOPLE_FIRST_SESSION: dict[tuple[str, str], int] = {("cpu", "ant"): 240}


def people_schedule(preset: str, env: str) -> dict[str, int]:
    """The feedback schedule of a run people label: the preset's, or where PEOPLE_FIRST_SESSION is
    earlier than its warm-up, a first session there and the last still at 90 % (empty: the preset's)."""
    cfg = make_config(preset, env)
    first = PEOPLE_FIRST_SESSION.get((preset, env))
    if first is None or first >= cfg.warmup:
        return {}
    return feedback_schedule(cfg.epochs, cfg.n_sessions, first)
