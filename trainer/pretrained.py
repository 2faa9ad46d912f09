"""Skills of a finished run, loaded back for downstream tasks and report figures: the run's config,
its learner (π, φ, Q) from `checkpoint.pt`, the skill prior and the observation normaliser."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import torch

from trainer.checkpoint import load_checkpoint
from trainer.config import Config
from trainer.envs import make_env
from trainer.methods import build_agent
from trainer.metra import Metra
from trainer.obs_stats import observation_stats
from trainer.rollout import Normaliser
from trainer.run_files import has_checkpoint
from trainer.skills import SkillPrior


@dataclass
class TrainedSkills:
    cfg: Config
    agent: Metra
    prior: SkillPrior
    normalise: Normaliser
    epoch: int


def run_config(run_dir: str | Path) -> Config:
    """The run's own config.json (keys this version does not know are ignored, options the run
    predates take the value it ran with)."""
    return Config.from_stored(json.loads((Path(run_dir) / "config.json").read_text()))


def load_skills(run_dir: str | Path, device: str = "cpu") -> TrainedSkills:
    """Rebuild the run's learner from its checkpoint, on `device`, ready to act."""
    if not Path(run_dir).is_dir():
        raise FileNotFoundError(f"{run_dir} is not a folder: give a run folder")
    if not has_checkpoint(run_dir):
        if has_checkpoint(Path(run_dir) / "trainer"):  # a `collie up` folder: its run is in trainer/
            raise FileNotFoundError(f"{run_dir} is a collie up folder: give its run, {Path(run_dir) / 'trainer'}")
        raise FileNotFoundError(
            f"{run_dir} has no checkpoint.pt: its networks are not kept (an archived run holds results only)"
        )
    cfg = run_config(run_dir)
    state = load_checkpoint(Path(run_dir) / "checkpoint.pt")
    env = make_env(cfg.env, episode_steps=cfg.episode_steps)
    obs_shape, action_dim, mean, std = env.obs_shape, env.action_dim, env.obs_mean, env.obs_std
    env.close()
    prior = SkillPrior.for_config(cfg)
    mean, std = observation_stats(cfg.env, mean, std, cfg.obs_norm)
    agent, _ = build_agent(cfg, obs_shape, action_dim, prior, torch.device(device))
    agent.load_state_dict(state["agent"])
    return TrainedSkills(cfg, agent, prior, Normaliser(mean, std), int(state["epoch"]))
