"""The method registry: one table, name → whether it asks for labels, how its learner is built and
how its w is computed. Adding a method is one row here (and its learner's module):

    metra, oracle, collie   METRA's φ with the dual λ (Eqs. 9–11); w ≡ 1, g(s′), Eq. 8
    lsd                     Lipschitz φ by spectral normalisation, no dual (trainer/lsd.py)
    diayn                   skill discriminator q(z|s′), reward log q(z|s′) − log p(z) (trainer/diayn.py)
    dodont                  METRA with w = 2ψ(s′), ψ an instruction classifier (trainer/dodont.py)
    ddg                     METRA on φ(s) = head(encoder(s)), the classifier's encoder (trainer/ddg.py)
`--distance l2` swaps METRA's temporal constraint for LSD's Euclidean one in any w-guided method
(COLLIE-L2 is `--method collie --distance l2`).

Which config keys matter to a method (`specific_keys`) follows from its row: the feedback schedule to
those that ask for labels, `--w-at` to those with a w to evaluate, `--k-beta` to COLLIE's smoothed
w, and its learner's own options (`learner_keys`: `--diayn`, ψ's `--classifier-steps`); every other key
matters to every method.

The learners are imported when built, not here: the table is read by light commands too
(`collie sweep`, the config's validation), which must not load torch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import torch

    from trainer.config import Config
    from trainer.instruction import InstructionClassifier
    from trainer.metra import Metra
    from trainer.skills import SkillPrior

# How w(s) is computed (trainer/loop.py applies it): "one" w ≡ 1; "task" the task rule g(s′) (the
# Oracle baseline); "instruction" 2ψ(s′) (trainer/dodont.py); "labels" Eq. 8 from D0/D1/D2, smoothed.
Guidance = Literal["one", "task", "instruction", "labels"]
Learner = tuple["Metra", "InstructionClassifier | None"]
Builder = Callable[["Config", "int | tuple[int, ...]", int, "SkillPrior", "torch.device"], Learner]


# Config keys only some methods read (trainer/loop.py): the feedback schedule, read only when the
# loop opens a session (is_feedback_epoch); w's, by the guidance that makes a w (weight_fn)
FEEDBACK_KEYS = (
    "warmup",
    "feedback_every",
    "queries_per_session",
    "total_queries",
    "segment_length",
    "candidates",
    "knn_k",
    "query_strategy",
    "noise_band",
)
GUIDANCE_KEYS: dict[Guidance, tuple[str, ...]] = {
    "one": (),
    "task": ("w_at",),
    "instruction": ("w_at",),
    "labels": ("w_at", "k_beta"),  # β smooths Eq. 8's w alone
}
CLASSIFIER_KEYS = ("classifier_steps", "projection_dim")  # ψ, the instruction classifier (trainer/instruction.py)


@dataclass(frozen=True)
class Method:
    name: str
    asks_labels: bool  # does the loop open feedback sessions (Algorithm 1, lines 4–7)?
    guidance: Guidance
    build: Builder
    learner_keys: tuple[str, ...] = ()  # its learner's own config keys: no learner of a method without them reads them
    states_only: str | None = None  # what of it reads state vectors only (refused on pixel envs), if anything

    @property
    def specific_keys(self) -> frozenset[str]:
        """Of the config keys only some methods read, those this one reads (every other key, all do)."""
        return frozenset(
            (*(FEEDBACK_KEYS if self.asks_labels else ()), *GUIDANCE_KEYS[self.guidance], *self.learner_keys)
        )


def _metra(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> Metra:
    """METRA, or LSD's Lipschitz φ with `--distance l2`."""
    from trainer.lsd import Lsd
    from trainer.metra import Metra

    return (Lsd if cfg.distance == "l2" else Metra)(obs_shape, action_dim, prior, cfg, device)


def _plain(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> Learner:
    return _metra(cfg, obs_shape, action_dim, prior, device), None


def _lsd(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> Learner:
    from trainer.lsd import Lsd

    return Lsd(obs_shape, action_dim, prior, cfg, device), None


def _diayn(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> Learner:
    from trainer.diayn import Diayn

    return Diayn(obs_shape, action_dim, prior, cfg, device), None


def _dodont(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> tuple[Metra, InstructionClassifier]:
    """The learner and ψ, the instruction classifier (an MLP: state observations only)."""
    from trainer.encoders import feature_dim, is_pixels
    from trainer.instruction import InstructionClassifier

    if is_pixels(obs_shape):
        raise ValueError(f"{cfg.method}'s instruction classifier is an MLP: state observations only")
    agent = _metra(cfg, obs_shape, action_dim, prior, device)
    return agent, InstructionClassifier(feature_dim(obs_shape), cfg, device)


def _ddg(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> Learner:
    """DoDont*'s pair, with φ reading ψ's encoder (trainer/ddg.py)."""
    from trainer.ddg import attach_projection

    if cfg.distance == "l2":
        raise ValueError("ddg runs on METRA's temporal distance only (--distance temporal)")
    agent, classifier = _dodont(cfg, obs_shape, action_dim, prior, device)
    attach_projection(agent, classifier, cfg)
    return agent, classifier


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("collie", asks_labels=True, guidance="labels", build=_plain),
        Method("metra", asks_labels=False, guidance="one", build=_plain),
        Method("oracle", asks_labels=False, guidance="task", build=_plain),
        Method(
            "dodont",
            asks_labels=True,
            guidance="instruction",
            build=_dodont,
            learner_keys=CLASSIFIER_KEYS,
            states_only="dodont's instruction classifier (an MLP)",
        ),
        Method(
            "ddg",
            asks_labels=True,
            guidance="one",
            build=_ddg,
            learner_keys=CLASSIFIER_KEYS,
            states_only="ddg's instruction classifier (an MLP)",
        ),
        Method("lsd", asks_labels=False, guidance="one", build=_lsd, states_only="LSD's Lipschitz φ"),
        Method("diayn", asks_labels=False, guidance="one", build=_diayn, learner_keys=("diayn",)),
    )
}
# the config keys that matter only to the methods that read them
METHOD_SPECIFIC_KEYS = frozenset(key for m in METHODS.values() for key in m.specific_keys)


def method(name: str) -> Method:
    """The registry's row for `name`; a clear error listing the valid names otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"unknown method {name!r}; valid: {', '.join(METHODS)}") from None


def matters(key: str, name: str) -> bool:
    """Whether config `key` changes what method `name` learns: a key only other methods read does not
    (`--diayn` to a METRA run)."""
    return key not in METHOD_SPECIFIC_KEYS or key in method(name).specific_keys


def build_agent(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> Learner:
    """The learner for `cfg.method` and, for DoDont*/DDG*, its instruction classifier; with
    `cfg.compile` its networks compiled once every learner has put its own in place."""
    agent, classifier = method(cfg.method).build(cfg, obs_shape, action_dim, prior, device)
    if cfg.compile:
        agent.compile()
    return agent, classifier
