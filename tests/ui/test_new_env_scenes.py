"""The labeling UI builds a replay scene for each of the newer robots (pixel DMC and the car):
the labeler watches a 3D replay from physics state, not the 64×64 frames the agent sees."""

import time

import numpy as np
import pytest
import viser
from chromium import chromium

from labeling_ui.models import Poser, replay_model
from labeling_ui.scene import ReplayScene
from trainer.envs import make_env


@pytest.mark.parametrize("env_name", ["quadruped", "humanoid", "car"])
def test_replay_scene_builds_and_poses_each_new_env(env_name: str) -> None:
    env = make_env(env_name, seed=0, episode_steps=5)
    _, info = env.reset(seed=0)
    frames = [info["qpos"]]
    for _ in range(4):
        _, _, _, _, info = env.step(np.zeros(env.action_dim))
        frames.append(info["qpos"])
    env.close()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    with chromium() as browser:
        try:
            page = browser.new_page()
            page.goto(f"http://127.0.0.1:{server.get_port()}")
            deadline = time.monotonic() + 60
            while not server.get_clients() and time.monotonic() < deadline:
                time.sleep(0.1)
            client = next(iter(server.get_clients().values()))
            build_and_pose(client, env_name, frames)
        finally:
            server.stop()


def build_and_pose(client: viser.ClientHandle, env_name: str, frames: list[np.ndarray]) -> None:
    scene = ReplayScene(client)
    model = scene.load(env_name)
    assert scene.env == env_name and model.nq == len(frames[0])
    poser = Poser(model, np.array(frames))
    scene.set_segment(poser, earlier_xy=None)
    scene.show(2.5)  # between frames: interpolated pose
    assert poser.n_frames == 5
    assert replay_model(env_name) is model  # compiled once, reused for every segment
