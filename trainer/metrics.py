"""Coverage metrics over evaluation trajectories (Appendix E, "Metrics"; composite metrics §5).

States are binned by floor(position / bin_size) (x-y bins, or x only for 1-D envs such as
HalfCheetah). Each visited bin gets a class by one of two rules (`--bin-rule`):

- `visited` (ours): decided from the visited states that fell in the bin — bad if any of them is
  bad, good if all of them are good, else neutral (the teacher's segment rule). Exact for bins
  inside one region, conservative (bad wins) for bins a boundary cuts.
- `corner` (the reference code's): the task rule evaluated at the bin's lower-left corner
  (x, y) = bin index · bin_size, whatever the agent did inside the bin. A point in space cannot
  decide a rule on pitch (Not-Flip), so for such tasks the reference counts, and so do we, every
  bin holding any bad state as bad and every bin holding any safe state as safe — one bin can be
  both. The paper's tables were computed this way, so every comparison with them uses it.

Both rules are always computed: the headline keys follow the chosen rule, and every key is also
written with a `visited_` and a `corner_` prefix. Numpy only.

Scores: safe coverage +1 per safe (good or neutral) bin, −1 per bad bin; safe ratio = safe bins /
visited bins; composite +1 good, +1 neutral, −1 bad (equal to safe coverage by definition, kept
under the paper's name); weighted composite +2 good, +1 neutral, −1 bad.

A run without a rule (only an instruction) gets only what needs none: the visited bins (state
coverage, n_bins) and n_states; the rule's scores are left out, not zeroed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from collie.tasks import BAD, GOOD, NEUTRAL, Task

BIN_RULES = ("visited", "corner")


def _positions(traj: np.ndarray) -> np.ndarray:
    """(T, 2) x-y; a 1-D trajectory ((T,) or (T, 1)) gets y = 0."""
    traj = np.asarray(traj, dtype=float)
    if traj.ndim == 1:
        traj = traj[:, None]
    if traj.shape[1] == 1:
        traj = np.concatenate([traj, np.zeros_like(traj)], axis=1)
    return traj[:, :2]


def _unique_bins(xy: np.ndarray, bin_size: float, position_dims: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique bin indices (n_bins, position_dims) int64 and, per state, the row of its bin."""
    if position_dims not in (1, 2):
        raise ValueError(f"position_dims must be 1 or 2, got {position_dims}")
    if len(xy) == 0:
        return np.zeros((0, position_dims), dtype=np.int64), np.zeros(0, dtype=np.int64)
    index = np.floor(xy[:, :position_dims] / bin_size).astype(np.int64)
    bins, inverse = np.unique(index, axis=0, return_inverse=True)
    return bins, inverse.reshape(-1)


def bin_classes(
    xy: np.ndarray, classes: np.ndarray, bin_size: float = 1.0, position_dims: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """The `visited` rule: unique visited bins (n_bins, position_dims) int64 and each bin's class
    (n_bins,) int8 from the classes of the states inside it."""
    bins, inverse = _unique_bins(xy, bin_size, position_dims)
    if len(bins) == 0:
        return bins, np.zeros(0, dtype=np.int8)
    visits = np.bincount(inverse, minlength=len(bins))
    bad = np.bincount(inverse, weights=classes == BAD, minlength=len(bins)) > 0
    good = np.bincount(inverse, weights=classes == GOOD, minlength=len(bins)) == visits
    return bins, np.where(bad, BAD, np.where(good, GOOD, NEUTRAL)).astype(np.int8)


def corner_points(bins: np.ndarray, bin_size: float = 1.0) -> np.ndarray:
    """(n_bins, 2) lower-left corners of the bins; y = 0 for 1-D bins."""
    corners = np.zeros((len(bins), 2))
    corners[:, : bins.shape[1]] = bins * bin_size
    return corners


def _counts(n_bins: int, n_good: int, n_neutral: int, n_bad: int, n_safe: int) -> dict[str, float]:
    return {
        "safe_coverage": float(n_safe - n_bad),
        "safe_ratio": n_safe / n_bins if n_bins else 0.0,
        "composite_coverage": float(n_good + n_neutral - n_bad),
        "weighted_composite_coverage": float(2 * n_good + n_neutral - n_bad),
        "n_bins": n_bins,
        "n_bad_bins": n_bad,
        "n_neutral_bins": n_neutral,
        "n_good_bins": n_good,
    }


def _visited_scores(per_bin: np.ndarray) -> dict[str, float]:
    n_bad, n_good = int((per_bin == BAD).sum()), int((per_bin == GOOD).sum())
    n_neutral = len(per_bin) - n_bad - n_good
    return _counts(len(per_bin), n_good, n_neutral, n_bad, n_good + n_neutral)


def _corner_scores(
    bins: np.ndarray, inverse: np.ndarray, classes: np.ndarray, task: Task, bin_size: float
) -> dict[str, float]:
    n = len(bins)
    if n == 0:
        return _counts(0, 0, 0, 0, 0)
    if not task.uses_pitch:
        per_bin = task.classify(corner_points(bins, bin_size))
        return _visited_scores(per_bin)

    # A pitch rule: any-state counts per class (the reference's Not-Flip metric; bins may overlap).
    def any_of(cls: int) -> int:
        return int((np.bincount(inverse, weights=classes == cls, minlength=n) > 0).sum())

    n_safe = int((np.bincount(inverse, weights=classes != BAD, minlength=n) > 0).sum())
    return _counts(n, any_of(GOOD), any_of(NEUTRAL), any_of(BAD), n_safe)


def coverage_metrics(
    xy_trajs: Sequence[np.ndarray],
    pitch_trajs: Sequence[np.ndarray] | None,
    task: Task | None,
    bin_size: float = 1.0,
    position_dims: int = 2,
    bin_rule: str = "visited",
) -> dict[str, float]:
    """Safe / composite state coverage and safe ratio of the visited bins (Appendix E), by
    `bin_rule`, plus both rules' figures under `visited_*` and `corner_*`; with no rule (`task`
    None), only the visited bins and states."""
    if bin_rule not in BIN_RULES:
        raise ValueError(f"unknown bin rule {bin_rule!r}; valid: {', '.join(BIN_RULES)}")
    positions = [_positions(t) for t in xy_trajs]
    xy = np.concatenate(positions) if positions else np.zeros((0, 2))
    pitch = None
    if pitch_trajs is not None:
        pitch = np.concatenate([np.asarray(p, dtype=float).reshape(-1) for p in pitch_trajs] or [np.zeros(0)])
    if task is None:
        bins, _ = _unique_bins(xy, bin_size, position_dims)
        return {"n_bins": len(bins), "n_states": len(xy)}
    classes = task.classify(xy, pitch)
    bins, inverse = _unique_bins(xy, bin_size, position_dims)
    _, per_bin = bin_classes(xy, classes, bin_size, position_dims)
    by_rule = {
        "visited": _visited_scores(per_bin),
        "corner": _corner_scores(bins, inverse, classes, task, bin_size),
    }
    out: dict[str, float] = {**by_rule[bin_rule], "n_states": len(xy)}
    for rule, scores in by_rule.items():
        out.update({f"{rule}_{k}": v for k, v in scores.items()})
    return out


def final_distances(xy_trajs: Sequence[np.ndarray]) -> np.ndarray:
    """(n,) each trajectory's distance from its first state to its last."""
    return np.linalg.norm(np.stack([_positions(t)[-1] - _positions(t)[0] for t in xy_trajs]), axis=1)


def travel_metrics(xy_trajs: Sequence[np.ndarray]) -> dict[str, float]:
    """How far the skills go: median and max distance from each trajectory's start to its end, and
    the spread (max − min) of the final x over skills — the robot targets of issue 12."""
    if len(xy_trajs) == 0:
        return {"median_final_distance": 0.0, "max_final_distance": 0.0, "final_x_spread": 0.0}
    final_x = np.array([_positions(t)[-1, 0] for t in xy_trajs])
    distance = final_distances(xy_trajs)
    return {
        "median_final_distance": float(np.median(distance)),
        "max_final_distance": float(distance.max()),
        "final_x_spread": float(final_x.max() - final_x.min()),
    }


def start_block(xy_trajs: Sequence[np.ndarray], bin_size: float = 1.0) -> np.ndarray:
    """(n, 2) int64: for each skill's start, the 2×2 bins around the grid corner nearest it (all
    skills of one body start in the same four). Reset noise puts a robot that stands still in all
    four, and the corner rule judges three of them at a corner south or west of the start, which
    for a wedge whose apex is the start lies outside it."""
    corners = {tuple(np.round(_positions(t)[0] / bin_size).astype(np.int64)) for t in xy_trajs}
    block = {(cx + dx, cy + dy) for cx, cy in corners for dx in (-1, 0) for dy in (-1, 0)}
    return np.array(sorted(block), dtype=np.int64).reshape(-1, 2)


def off_start_safe_ratio(xy_trajs: Sequence[np.ndarray], task: Task, bin_size: float = 1.0) -> float:
    """A diagnostic, not the paper's metric: the corner rule's safe ratio over the visited 2-D bins
    outside `start_block`. At a few dozen bins those 4 move the ratio by up to 3/n; at the paper's
    ~1300 they do not (nan when no bin lies outside them, or for a pitch rule)."""
    if len(xy_trajs) == 0 or task.uses_pitch:
        return math.nan
    xy = np.concatenate([_positions(t) for t in xy_trajs])
    bins, _ = _unique_bins(xy, bin_size, 2)
    block = start_block(xy_trajs, bin_size)
    away = ~(bins[:, None, :] == block[None, :, :]).all(axis=2).any(axis=1)
    if not away.any():
        return math.nan
    per_bin = task.classify(corner_points(bins[away], bin_size))
    return float((per_bin != BAD).mean())


def standing_share(xy_trajs: Sequence[np.ndarray], radius: float = 1.0) -> float:
    """A diagnostic: the share of skills whose last state lies within `radius` of their first."""
    if len(xy_trajs) == 0:
        return math.nan
    return float((final_distances(xy_trajs) < radius).mean())
