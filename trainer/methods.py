"""Which learner each method name builds (`--method`, `--distance`). One place, so the training
loop stays the same for every method:

    metra, oracle, collie   METRA's φ with the dual λ (Eqs. 9–11); w ≡ 1, g(s′), Eq. 8
    lsd                     Lipschitz φ by spectral normalisation, no dual (trainer/lsd.py)
    diayn                   skill discriminator q(z|s′), reward log q(z|s′) − log p(z) (trainer/diayn.py)
    dodont                  METRA with w = 2ψ(s′), ψ an instruction classifier (trainer/dodont.py)
    ddg                     METRA on φ(s) = head(encoder(s)), the classifier's encoder (trainer/ddg.py)
`--distance l2` swaps METRA's temporal constraint for LSD's Euclidean one in any w-guided method
(COLLIE-L2 is `--method collie --distance l2`).
"""

from __future__ import annotations

import torch

from trainer.config import Config
from trainer.ddg import attach_projection
from trainer.diayn import Diayn
from trainer.encoders import feature_dim, is_pixels
from trainer.instruction import InstructionClassifier
from trainer.lsd import Lsd
from trainer.metra import Metra
from trainer.skills import SkillPrior

CLASSIFIER_METHODS = ("dodont", "ddg")


def build_agent(
    cfg: Config, obs_shape: int | tuple[int, ...], action_dim: int, prior: SkillPrior, device: torch.device
) -> tuple[Metra, InstructionClassifier | None]:
    """The learner for `cfg.method` and, for DoDont*/DDG*, its instruction classifier."""
    if cfg.method == "diayn":
        return Diayn(obs_shape, action_dim, prior, cfg, device), None
    if cfg.method == "ddg" and cfg.distance == "l2":
        raise ValueError("ddg runs on METRA's temporal distance only (--distance temporal)")
    lipschitz = cfg.method == "lsd" or cfg.distance == "l2"
    agent = (Lsd if lipschitz else Metra)(obs_shape, action_dim, prior, cfg, device)
    if cfg.method not in CLASSIFIER_METHODS:
        return agent, None
    if is_pixels(obs_shape):
        raise ValueError(f"{cfg.method}'s instruction classifier is an MLP: state observations only")
    classifier = InstructionClassifier(feature_dim(obs_shape), cfg, device)
    if cfg.method == "ddg":
        attach_projection(agent, classifier, cfg)
    return agent, classifier
