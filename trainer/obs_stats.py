"""Observation statistics: METRA's fixed presets for Ant and HalfCheetah (`--obs-norm reference`) or the env's own.

Source: `get_normalizer_preset` in seohongpark/METRA `iod/utils.py` (commit e08e762; the COLLIE
fork iiiiii11/COLLIE carries the same numbers), which the reference runs select with
`--normalizer_type preset`. Its comment says they are the mean and std of every state of 10 000
random-action rollouts of 50 steps without early termination, in METRA's gym/mujoco-py envs, whose
observations are laid out as ours: [qpos, qvel] with the root x (and y) kept — Ant 29-D, HalfCheetah
18-D. The numbers are data, transcribed here; `python -m trainer.envs.normalizer --env ant` prints
our own random-rollout statistics (`--obs-norm rollout`) for comparison. The short rollouts are
why METRA's x/y std (≈ 0.62) is smaller than ours (≈ 1.6 over 200 steps): with the reference's
statistics a unit of distance in x-y weighs more against the joint angles in φ's input and in the
query entropy (Eq. 12), which is computed in normalised space.
"""

from __future__ import annotations

import numpy as np

REFERENCE_STATS: dict[str, tuple[np.ndarray, np.ndarray]] = {
    "ant": (
        np.array(
            [
                0.00486117,
                0.011312,
                0.7022248,
                0.8454677,
                -0.00102548,
                -0.00300276,
                0.00311523,
                -0.00139029,
                0.8607109,
                -0.00185301,
                -0.8556998,
                0.00343217,
                -0.8585605,
                -0.00109082,
                0.8558013,
                0.00278213,
                0.00618173,
                -0.02584622,
                -0.00599026,
                -0.00379596,
                0.00526138,
                -0.0059213,
                0.27686235,
                0.00512205,
                -0.27617684,
                -0.0033233,
                -0.2766923,
                0.00268359,
                0.27756855,
            ],
            dtype=np.float32,
        ),
        np.array(
            [
                0.62473416,
                0.61958003,
                0.1717569,
                0.28629342,
                0.20020866,
                0.20572574,
                0.34922406,
                0.40098143,
                0.3114514,
                0.4024826,
                0.31057045,
                0.40343934,
                0.3110796,
                0.40245822,
                0.31100526,
                0.81786263,
                0.8166509,
                0.9870919,
                1.7525449,
                1.7468817,
                1.8596431,
                4.502961,
                4.4070187,
                4.522444,
                4.3518476,
                4.5105968,
                4.3704205,
                4.5175962,
                4.3704395,
            ],
            dtype=np.float32,
        ),
    ),
    "half_cheetah": (
        np.array(
            [
                -0.07861924,
                -0.08627162,
                0.08968642,
                0.00960849,
                0.02950368,
                -0.00948337,
                0.01661406,
                -0.05476654,
                -0.04932635,
                -0.08061652,
                -0.05205841,
                0.04500197,
                0.02638421,
                -0.04570961,
                0.03183838,
                0.01736591,
                0.0091929,
                -0.0115027,
            ],
            dtype=np.float32,
        ),
        np.array(
            [
                0.4039283,
                0.07610687,
                0.23817,
                0.2515473,
                0.2698137,
                0.26374814,
                0.32229397,
                0.2896734,
                0.2774097,
                0.73060024,
                0.77360505,
                1.5871304,
                5.5405455,
                6.7097645,
                6.8253727,
                6.3142195,
                6.417641,
                5.9759197,
            ],
            dtype=np.float32,
        ),
    ),
}
for _mean, _std in REFERENCE_STATS.values():
    _mean.setflags(write=False)
    _std.setflags(write=False)

OBS_NORMS = ("reference", "rollout")


def observation_stats(
    env_name: str, env_mean: np.ndarray, env_std: np.ndarray, obs_norm: str
) -> tuple[np.ndarray, np.ndarray]:
    """(mean, std) that normalise φ's, π's and Q's input: METRA's preset for `reference`, the env's
    own fixed statistics for `rollout` (random rollouts for Ant/HalfCheetah, hand-chosen for point
    and car, 0/255 for pixels)."""
    if obs_norm == "rollout":
        return env_mean, env_std
    if obs_norm != "reference":
        raise ValueError(f"unknown obs_norm {obs_norm!r}; valid: {', '.join(OBS_NORMS)}")
    if env_name not in REFERENCE_STATS:
        raise ValueError(
            f"--obs-norm reference: the reference has fixed statistics only for {', '.join(REFERENCE_STATS)}, "
            f"not {env_name!r}; use --obs-norm rollout"
        )
    mean, std = REFERENCE_STATS[env_name]
    if mean.shape != np.shape(env_mean):
        raise ValueError(f"{env_name}: reference statistics are {mean.shape}-D, observations {np.shape(env_mean)}")
    return mean, std
