"""The pixel robots (dm_control Quadruped, Humanoid) with real MuJoCo and real offscreen rendering:
frame stacks, the position-coloured floor, physics x-y, models a viewer can rebuild, the CNN
encoders and a smoke training run."""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from collie.mjmodels.floor import HALF_EXTENT, floor_colour, floor_texture
from trainer.config import make_config
from trainer.encoders import PixelEncoder
from trainer.envs import VectorEnv, load_model, make_env, model_path, model_xml
from trainer.loop import Trainer
from trainer.metra import Metra, TorchBatch
from trainer.skills import SkillPrior

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from probe_quadruped_gait import distance_after  # the bench folder is not a package

pytestmark = pytest.mark.slow  # run first under `make test`'s two workers (tests/conftest.py)

PIXEL_ENVS = {"quadruped": (12, 23), "humanoid": (21, 28)}  # action_dim, nq
OBS_SHAPE = (9, 64, 64)


@pytest.fixture
def one_thread():
    """Small CNN batches: a second torch thread only adds contention on a shared 2-core machine."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module", params=sorted(PIXEL_ENVS))
def env(request: pytest.FixtureRequest):
    env = make_env(request.param, seed=0)
    yield env
    env.close()


def test_observations_are_stacked_uint8_frames(env) -> None:
    action_dim, nq = PIXEL_ENVS[env.name]
    assert (env.obs_shape, env.obs_dtype, env.action_dim, env.nq) == (OBS_SHAPE, np.uint8, action_dim, nq)
    obs, info = env.reset(seed=1)
    assert obs.shape == OBS_SHAPE and obs.dtype == np.uint8
    assert np.array_equal(obs[:3], obs[3:6]) and np.array_equal(obs[:3], obs[6:])  # reset fills the stack
    assert info["qpos"].shape == (nq,) and info["qvel"].shape == (env.nv,)
    rng = np.random.default_rng(0)
    frames = [obs]
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, action_dim))
        frames.append(obs)
    assert (reward, terminated, truncated) == (0.0, False, False)
    assert np.array_equal(frames[2][3:6], frames[1][6:]) and np.array_equal(frames[3][:3], frames[1][6:])
    assert not np.array_equal(frames[3][6:], frames[0][6:])  # the robot moved in view
    np.testing.assert_array_equal(info["xy"], env.data.qpos[:2])  # x-y from physics (root joint)
    assert -np.pi <= info["pitch"] <= np.pi


def test_same_seed_same_frames(env) -> None:
    first = env.reset(seed=5)[0]
    assert np.array_equal(env.reset(seed=5)[0], first)
    assert not np.array_equal(env.reset(seed=6)[0], first)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_periodic_gait_walks_the_quadruped_away(seed: int) -> None:
    """The actuators can carry the robot far in one episode, so skills that stay put (docs/results.md,
    the pixel Quadruped) are the learner's, not the env's: standing still drifts only as it settles."""
    env = make_env("quadruped", seed=0)
    phases = np.arange(env.action_dim)
    gait = distance_after(env, seed, lambda t: np.sin(0.5 * t + phases))
    still = distance_after(env, seed, lambda t: np.zeros(env.action_dim))
    env.close()
    assert gait > 4.0 and still < 1.0, (gait, still)


def _frame_at(env, x: float, y: float) -> np.ndarray:
    env.reset(seed=0)
    env.data.qpos[:2] = x, y
    mujoco.mj_forward(env.model, env.data)
    return env.render().reshape(3, -1).mean(axis=1)


def test_floor_colour_encodes_position(env) -> None:
    west, east, north = _frame_at(env, -10, 0), _frame_at(env, 10, 0), _frame_at(env, 0, 10)
    assert np.abs(east - west).max() > 20  # the two places look different
    assert east[0] > west[0] + 20 and abs(east[1] - west[1]) < 10  # red grows with x
    assert north[1] > west[1] + 10 and north[1] > east[1] + 10  # green grows with y


def test_floor_texture_layout() -> None:
    tex = floor_texture(64)
    assert tex.shape == (64, 64, 3) and tex.dtype == np.uint8
    assert tex[0, -1, 0] > tex[0, 0, 0] and tex[0, 0, 1] > tex[-1, 0, 1]  # row 0 is north (+y), column → x
    np.testing.assert_array_equal(floor_colour(np.array([HALF_EXTENT]), np.array([-HALF_EXTENT]))[0, :2], [225, 30])


@pytest.mark.parametrize("name", sorted(PIXEL_ENVS))
def test_model_xml_rebuilds_the_scene(name: str) -> None:
    model = mujoco.MjModel.from_xml_string(model_xml(name))
    painted = load_model(name)
    action_dim, nq = PIXEL_ENVS[name]
    assert (model.nq, model.nu, painted.nq, painted.nu) == (nq, action_dim, nq, action_dim)
    assert model.camera("pixels").mode == mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM
    tex = painted.texture("position_floor")
    texels = painted.tex_data[tex.adr[0] : tex.adr[0] + 3 * tex.width[0] * tex.height[0]]
    assert np.array_equal(texels, floor_texture(int(tex.width[0])).reshape(-1))
    with pytest.raises(ValueError, match="model_xml"):
        model_path(name)


def test_vector_env_batches_pixels() -> None:
    vec = VectorEnv("quadruped", num_envs=2, episode_steps=2)
    batch = vec.reset([0, 1])
    batch = vec.step(np.zeros((2, 12)), out=batch)
    assert batch.obs.shape == (2, *OBS_SHAPE) and batch.obs.dtype == np.uint8
    assert batch.qpos.shape == (2, 23) and batch.qvel.shape == (2, 22) and vec.metric_bin_size == 1.0
    assert not np.array_equal(batch.obs[0], batch.obs[1])


def test_twin_encoder_is_two_independent_cnns(one_thread: None) -> None:
    torch.manual_seed(0)
    twin, single = PixelEncoder(OBS_SHAPE, copies=2), PixelEncoder(OBS_SHAPE)
    obs = torch.rand(5, *OBS_SHAPE)
    for copy in (0, 1):
        for mine, theirs in zip(single.net, twin.net, strict=True):
            if isinstance(mine, torch.nn.Conv2d):
                out = mine.out_channels
                mine.weight.data.copy_(theirs.weight.data[copy * out : (copy + 1) * out])
                mine.bias.data.copy_(theirs.bias.data[copy * out : (copy + 1) * out])
        assert single(obs).shape == (5, 1536)
        torch.testing.assert_close(twin(obs)[copy], single(obs))


@pytest.mark.parametrize("encoder", ["separate", "shared"])
def test_pixel_update_trains_the_right_encoders(encoder: str, one_thread: None) -> None:
    torch.manual_seed(0)
    cfg = make_config("smoke", "quadruped", encoder=encoder)
    prior = SkillPrior(cfg.skill_dim, False)
    agent = Metra(OBS_SHAPE, 12, prior, cfg, torch.device("cpu"))
    shared = agent.phi.encoder is agent.qf.encoder is agent.policy.encoder
    assert shared == (encoder == "shared") and agent.qf_target.encoder is not agent.qf.encoder
    obs = torch.rand(4, *OBS_SHAPE)
    z = torch.as_tensor(prior.sample(4, np.random.default_rng(0)))
    before = [p.clone() for p in agent.policy.encoder.parameters()]
    info = agent.update(TorchBatch(obs, torch.rand_like(obs), torch.zeros(4, 12), z, z), None)
    assert all(torch.isfinite(v) for v in info.values())
    moved = any(not torch.equal(p, q) for p, q in zip(before, agent.policy.encoder.parameters(), strict=True))
    assert moved  # separate: by the policy loss; shared: by φ's and the critics' losses


@pytest.mark.parametrize(("name", "task"), [("quadruped", "north"), ("humanoid", "hole")])
def test_smoke_training_on_pixels(tmp_path, name: str, task: str) -> None:
    trainer = Trainer(make_config("smoke", name, task=task, out=str(tmp_path)), progress=False)
    summary = trainer.run()
    assert summary["status"] == "finished" and summary["n_labels"] == 4 and np.isfinite(summary["safe_coverage"])
    assert trainer.replay.obs.dtype == np.uint8 and trainer.replay.obs.shape[2:] == OBS_SHAPE
    # labelled frames stay uint8, one array with the segment asked: a checkpoint holds them once (was:
    # a float32 copy beside the uint8 one, ≈ 3 MB more per label in every checkpoint and in memory)
    ckpt = torch.load(tmp_path / "checkpoint.pt", weights_only=False)
    assert len(ckpt["labelled"]) == 4
    for query_id, segment in ckpt["labelled"].items():
        assert segment["obs"].dtype == np.uint8 and segment["obs"] is ckpt["asked"][query_id]
