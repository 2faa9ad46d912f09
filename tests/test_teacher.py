"""Segment labels and the oracle teacher, exact and with the R_error noise band."""

from __future__ import annotations

import numpy as np
import pytest

from collie.tasks import BAD, GOOD, NEUTRAL, get_task
from collie.teacher import OracleTeacher, segment_label


@pytest.mark.parametrize(
    ("classes", "expected"),
    [
        ([GOOD] * 20, GOOD),
        ([GOOD] * 19 + [BAD], BAD),
        ([NEUTRAL, BAD, GOOD], BAD),
        ([GOOD, NEUTRAL, GOOD], NEUTRAL),
        ([NEUTRAL] * 5, NEUTRAL),
        ([BAD], BAD),
    ],
)
def test_segment_label(classes: list[int], expected: int) -> None:
    assert segment_label(np.array(classes, dtype=np.int8)) == expected


def test_segment_label_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        segment_label(np.array([], dtype=np.int8))
    with pytest.raises(ValueError):
        segment_label(np.array([1, 5]))


def line(start: tuple[float, float], end: tuple[float, float], n: int = 20) -> np.ndarray:
    return np.linspace(start, end, n)


def test_exact_labels_follow_the_task() -> None:
    teacher = OracleTeacher(get_task("range_north"))
    assert teacher.label(line((0, 2), (0, 20))) == GOOD
    assert teacher.label(line((0, 2), (10, 2))) == NEUTRAL  # good then neutral
    assert teacher.label(line((0, 10), (0, 30))) == BAD  # leaves the circle
    flips = OracleTeacher(get_task("not_flip", "half_cheetah"))
    assert flips.label(np.zeros((20, 2)), np.linspace(0, 1.5, 20)) == NEUTRAL
    assert flips.label(np.zeros((20, 2)), np.linspace(0, 2.0, 20)) == BAD


def test_noise_never_touches_states_far_from_boundaries() -> None:
    north = get_task("north")
    inside = line((0, 10), (0, 30))  # ≥ 10/√2 ≈ 7 from y = |x|
    outside = line((0, -10), (0, -30))  # ≥ 10 from the apex
    for seed in range(50):
        teacher = OracleTeacher(north, noise_band=3.0, seed=seed)
        assert teacher.label(inside) == NEUTRAL
        assert teacher.label(outside) == BAD
    good = OracleTeacher(get_task("range_north"), noise_band=2.0, seed=1)
    assert good.label(line((0, 2), (0, 20))) == GOOD  # ≥ 5 from the circle; y = |x| is no safety edge


def test_noise_band_yields_neutral_and_bad() -> None:
    north = get_task("north")
    near = np.array([[0.0, 0.5]] * 3)  # safe, 0.35 from the boundary
    labels = {OracleTeacher(north, noise_band=1.0, seed=s).label(near) for s in range(60)}
    assert labels == {NEUTRAL, BAD}
    per_state = np.concatenate([OracleTeacher(north, 1.0, seed=s).state_labels(near) for s in range(100)])
    assert set(per_state.tolist()) == {NEUTRAL, BAD}
    assert 0.35 < (per_state == BAD).mean() < 0.65  # uniform between the two
    good_near_circle = np.array([[0.0, 24.5]])  # range_north good, 0.5 inside the circle
    noisy = {OracleTeacher(get_task("range_north"), 1.0, seed=s).label(good_near_circle) for s in range(40)}
    assert noisy == {NEUTRAL, BAD}


def test_noise_is_deterministic_per_seed() -> None:
    task = get_task("range")
    rng = np.random.default_rng(123)
    segments = [rng.normal((0, 25), 1.0, size=(2, 2)) for _ in range(40)]

    def run(seed: int) -> tuple[list[int], list[int]]:
        teacher = OracleTeacher(task, noise_band=1.5, seed=seed)
        states = np.concatenate([teacher.state_labels(s) for s in segments]).tolist()
        return states, [teacher.label(s) for s in segments]

    assert run(7) == run(7)
    assert run(7)[0] != run(8)[0]


def test_noise_band_must_not_be_negative() -> None:
    with pytest.raises(ValueError):
        OracleTeacher(get_task("north"), noise_band=-1.0)
