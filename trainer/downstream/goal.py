"""HalfCheetah Goal (Appendix E, "Hierarchical control performance") as a decision process over
frozen skills: every `option_steps` (25) control steps a high-level controller picks one of the
run's discrete skills, which then acts alone (its π frozen, deterministic). Per control step
    r_t = 1[|x_{t+1} − goal| < 3]  −  20·1[the cheetah is flipped at s_{t+1}]
with goals drawn uniformly from [−100, 100] for every episode. The high level observes the
normalised state and the goal's offset (goal − x)/100.
"""

from __future__ import annotations

import numpy as np
import torch

from collie.tasks import BAD, get_task
from trainer.envs import VectorEnv
from trainer.pretrained import TrainedSkills

GOAL_RANGE, GOAL_RADIUS, FLIP_PENALTY, OPTION_STEPS = 100.0, 3.0, 20.0, 25


def goal_reward(x: np.ndarray, goal: np.ndarray, flipped: np.ndarray) -> np.ndarray:
    """Per-step reward: +1 within GOAL_RADIUS of the goal, −20 when flipped."""
    return (np.abs(x - goal) < GOAL_RADIUS).astype(np.float64) - FLIP_PENALTY * flipped


class GoalOptions:
    """n HalfCheetah episodes stepped together; one high-level step = one option of frozen skill."""

    def __init__(self, skills: TrainedSkills, n: int, option_steps: int = OPTION_STEPS) -> None:
        cfg = skills.cfg
        if not skills.prior.discrete:
            raise ValueError("the hierarchical goal task picks among discrete skills (HalfCheetah: 16 one-hot)")
        if cfg.episode_steps % option_steps:
            raise ValueError(f"episode_steps {cfg.episode_steps} must be a multiple of option_steps {option_steps}")
        self.skills, self.n, self.option_steps = skills, n, option_steps
        self.env = VectorEnv(cfg.env, n, episode_steps=cfg.episode_steps)
        self.flip = get_task("not_flip", cfg.env)  # bad ⇔ |pitch| > 90°, the same rule as the Not-Flip task
        self.n_skills = skills.prior.dim
        self.options_per_episode = cfg.episode_steps // option_steps
        self.obs_dim = self.env.obs_dim + 1
        self.goal = np.zeros(n)

    def observe(self) -> np.ndarray:
        goal_offset = (self.goal - self.state.xy[:, 0]) / GOAL_RANGE
        return np.concatenate([self.skills.normalise(self.state.obs), goal_offset[:, None]], axis=1).astype(np.float32)

    def reset(self, rng: np.random.Generator) -> np.ndarray:
        self.goal = rng.uniform(-GOAL_RANGE, GOAL_RANGE, size=self.n)
        self.state = self.env.reset([int(s) for s in rng.integers(0, 2**31 - 1, size=self.n)])
        return self.observe()

    def step(self, skill_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Run the chosen skills for one option; returns (next high-level obs, summed reward)."""
        z = torch.as_tensor(np.eye(self.n_skills, dtype=np.float32)[skill_index], device=self.skills.agent.device)
        reward = np.zeros(self.n)
        for _ in range(self.option_steps):
            obs = torch.as_tensor(self.skills.normalise(self.state.obs), device=self.skills.agent.device)
            action = self.skills.agent.act(obs, z, deterministic=True).cpu().numpy()
            self.state = self.env.step(action)
            flipped = self.flip.classify(self.state.xy, self.state.pitch) == BAD
            reward += goal_reward(self.state.xy[:, 0], self.goal, flipped)
        return self.observe(), reward

    def close(self) -> None:
        self.env.close()
