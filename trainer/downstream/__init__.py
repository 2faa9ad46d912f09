"""Downstream tasks that measure how useful the learned skills are (Section 5.4, Appendix E):

- `zero_shot`: the Ant motion task, every sampled skill rolled out as is (Table 3);
- `hierarchical`: HalfCheetah Goal, a PPO controller choosing frozen skills (Table 4).

`python -m trainer.downstream RUN_DIR` evaluates a finished run and writes RUN_DIR/downstream.json.
"""

from trainer.downstream.goal import GoalOptions, goal_reward
from trainer.downstream.zero_shot import motion_returns, zero_shot

__all__ = ["GoalOptions", "goal_reward", "motion_returns", "zero_shot"]
