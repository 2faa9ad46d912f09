"""Pixel-env segments through the service: image observations travel packed (PackedFrames) and come
back to a restarted trainer bit for bit; malformed packs are refused with a reason."""

from __future__ import annotations

import base64
import zlib

import httpx
import numpy as np
import pytest
from pydantic import ValidationError

from collie.client import ApiError, CollieClient
from collie.frames import pack_frames, unpack_frames
from collie.schemas import EnvDims, PackedFrames, RunCreate, SessionPost
from trainer.envs import make_env
from trainer.feedback.base import Segment
from trainer.feedback.http import HttpFeedback, to_wire

from .conftest import TOKENS

H = 20


def quadruped_segment(query_id: str) -> tuple[Segment, EnvDims]:
    env = make_env("quadruped", seed=0, episode_steps=H)
    obs, info = env.reset(seed=0)
    rows = []
    for _ in range(H):
        rows.append((obs, info))
        obs, _, _, _, info = env.step(np.zeros(env.action_dim))
    dims = EnvDims(obs_dim=env.obs_dim, nq=env.nq, nv=env.nv, horizon=H, skill_dim=4)
    env.close()
    segment = Segment(
        query_id=query_id, session=0, epoch=1, skill=np.ones(4) / 2, start=0,
        obs=np.stack([o for o, _ in rows]), xy=np.stack([i["xy"] for _, i in rows]),
        pitch=np.full(H, np.nan), qpos=np.stack([i["qpos"] for _, i in rows]),
        qvel=np.stack([i["qvel"] for _, i in rows]),
    )  # fmt: skip
    return segment, dims


def test_pixel_segment_round_trips_through_the_service(live: object, trainer: CollieClient) -> None:
    segment, dims = quadruped_segment("0-0")
    assert segment.obs.dtype == np.uint8 and segment.obs.ndim == 4
    wire = to_wire(segment)
    assert wire.obs == [] and wire.obs_packed is not None
    assert len(wire.model_dump_json()) < segment.obs.size  # smaller than one byte per pixel value
    run = trainer.create_run(RunCreate(env="quadruped", task="north", method="collie", dims=dims, n_total=5))
    trainer.post_session(run.id, SessionPost(session=0, epoch=1, queries=[wire]))
    with CollieClient(live.url, TOKENS["labeler"]) as labeler:  # type: ignore[attr-defined]
        labeler.claim(run.id)
        labeler.submit(run.id, "0-0", 0)
    source = HttpFeedback(live.url, TOKENS["trainer"], run.id)  # type: ignore[attr-defined]
    ((restored, label),) = source.history()
    source.close()
    assert label == 0 and np.array_equal(restored.obs, segment.obs) and restored.obs.dtype == np.uint8
    assert np.allclose(restored.qpos, segment.qpos)


def test_a_pack_that_does_not_fit_the_run_is_refused(trainer: CollieClient) -> None:
    segment, dims = quadruped_segment("0-0")
    run = trainer.create_run(RunCreate(env="quadruped", task="north", method="collie", dims=dims, n_total=5))
    wire = to_wire(segment)
    small = wire.model_copy(update={"obs_packed": pack_frames(np.zeros((H, 3, 8, 8), np.uint8))})
    with pytest.raises(ApiError) as err:
        trainer.post_session(run.id, SessionPost(session=0, epoch=1, queries=[small]))
    assert err.value.status == 422 and "packed obs" in str(err.value.detail)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ("not base64!", "not base64"),
        (base64.b64encode(b"plain bytes").decode(), "not base64 of zlib"),
        (base64.b64encode(zlib.compress(bytes(10))).decode(), "needs 12"),
        (base64.b64encode(zlib.compress(bytes(10**6))).decode(), "more than"),  # inflates no further than needed
    ],
)
def test_malformed_packs_name_the_problem(data: str, message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        PackedFrames(dtype="uint8", n=2, shape=[2, 3], zlib_b64=data)


def test_a_pack_claiming_absurd_sizes_is_refused_not_a_crash(live: object, trainer: CollieClient) -> None:
    """n × prod(shape) beyond what any segment holds (here beyond a C size) is a 422 naming it."""
    tiny = base64.b64encode(zlib.compress(bytes(1))).decode()
    with pytest.raises(ValidationError, match="more than"):
        PackedFrames(dtype="uint8", n=2**31 - 1, shape=[4096] * 4, zlib_b64=tiny)
    segment, dims = quadruped_segment("0-0")
    run = trainer.create_run(RunCreate(env="quadruped", task="north", method="collie", dims=dims, n_total=5))
    body = SessionPost(session=0, epoch=1, queries=[to_wire(segment)]).model_dump(mode="json")
    body["queries"][0]["obs_packed"].update(n=2**31 - 1, shape=[4096] * 4, zlib_b64=tiny)
    url = f"{live.url}/api/runs/{run.id}/sessions"  # type: ignore[attr-defined]
    response = httpx.post(url, json=body, headers={"Authorization": f"Bearer {TOKENS['trainer']}"}, timeout=30)
    assert response.status_code == 422 and "bytes, more than" in response.text


def test_pack_unpack_is_exact() -> None:
    frames = np.random.default_rng(0).integers(0, 256, (5, 9, 16, 16), dtype=np.uint8)
    assert np.array_equal(unpack_frames(pack_frames(frames)), frames)
    with pytest.raises(ValueError, match="uint8"):
        pack_frames(frames.astype(float))
