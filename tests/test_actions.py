"""Invalid actions: a clear error naming robot and component, and the env's state left as it was."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from noma_radiomap import NomaRadioMapEnv
from noma_radiomap.actions import check_action

N_ROBOTS = 2  # the `small` scenario
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=64)  # the whole float range


@pytest.fixture(scope="module")
def env():
    return NomaRadioMapEnv(scenario="small", multiple_access="noma", reward_phase="combined")


def snapshot(env):
    return (env.positions.copy(), env.arrived.copy(), env.step_count, len(env.trajectory), list(env.core.outage_steps[0]))


def assert_same_state(a, b):
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize(
    ("index", "robot", "component"), [(0, 0, "dx"), (1, 0, "dy"), (2, 0, "power"), (4, 1, "dy"), (5, 1, "power")]
)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_component_is_refused_and_state_kept(env, index, robot, component, bad):
    env.reset(seed=0)
    env.step(np.zeros(3 * N_ROBOTS))
    before = snapshot(env)
    action = np.zeros(3 * N_ROBOTS)
    action[index] = bad
    with pytest.raises(ValueError, match=rf"action\[{index}\] \(robot {robot}, {component}\)"):
        env.step(action)
    assert_same_state(snapshot(env), before)
    # The env goes on: a valid step after the refused one works and keeps every value finite.
    obs, reward, _, _, info = env.step(np.full(3 * N_ROBOTS, 0.5))
    assert np.isfinite(obs).all() and math.isfinite(reward) and np.isfinite(env.positions).all()
    assert np.isfinite(info["rate_bps"]).all()


@pytest.mark.parametrize(
    "action",
    [
        np.zeros(5),
        np.zeros(7),
        np.zeros((2, 3)),  # (U, 3): the layout would be a guess
        np.zeros((1, 6)),  # a batch of one
        np.zeros((6, 1)),
        np.zeros(()),
        np.array(["a"] * 6),
        np.array([True] * 6),
        np.zeros(6, dtype=complex),
        [[0.0, 0.0], [0.0]],  # ragged
        None,
        "left",
    ],
    ids=lambda a: repr(getattr(a, "shape", a)) + str(getattr(a, "dtype", "")),
)
def test_wrong_shape_or_type_is_a_clear_error(env, action):
    env.reset(seed=0)
    before = snapshot(env)
    with pytest.raises(ValueError, match=r"^action: expected"):
        env.step(action)
    assert_same_state(snapshot(env), before)


def test_nan_power_is_not_counted_as_no_outage(env):
    """The issue's second NaN case: a NaN power used to give NaN rates that compared as "not in outage"."""
    env.reset(seed=0)
    with pytest.raises(ValueError, match="power"):
        env.step(np.array([0.0, 0.0, math.nan, 0.0, 0.0, -1.0]))
    # A robot given no power is in outage; with the NaN refused nothing dodges the QoS penalty.
    _, _, _, _, info = env.step(np.array([0.0, 0.0, -1.0, 0.0, 0.0, 1.0]))
    assert info["outage"][0] and info["reward_components"]["qos"] < 0


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(ANY_FLOAT, min_size=3 * N_ROBOTS, max_size=3 * N_ROBOTS), st.integers(0, 3))
def test_any_float_action_is_refused_cleanly_or_keeps_every_invariant(env, values, seed):
    env.reset(seed=seed)
    action = np.array(values, dtype=np.float64)
    before = snapshot(env)
    if not np.isfinite(action).all():
        with pytest.raises(ValueError, match=r"action\[\d\] \(robot \d, (dx|dy|power)\): expected a finite number"):
            env.step(action)
        assert_same_state(snapshot(env), before)
        return
    obs, reward, _, _, info = env.step(action)
    assert np.isfinite(obs).all() and (np.abs(obs) <= 1).all()
    assert math.isfinite(reward)
    assert env.core.motion.is_free(env.positions).all()
    assert np.isfinite(info["rate_bps"]).all() and (info["power_w"] >= 0).all()
    assert info["power_w"].sum() <= env.core.max_power_w * (1 + 1e-9)
    assert all(math.isfinite(v) for v in info["reward_components"].values())


def test_check_action_returns_rows_per_robot():
    rows = check_action(np.arange(6, dtype=np.float32), 2)
    assert rows.dtype == np.float64 and rows.tolist() == [[0, 1, 2], [3, 4, 5]]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_vector_env_refuses_a_non_finite_action_of_any_mission_and_changes_nothing(bad):
    from noma_radiomap.vector import NomaRadioMapVecEnv

    env = NomaRadioMapVecEnv(3, scenario="small")
    env.reset(seed=0)
    before = (env.positions.copy(), env.arrived.copy(), env.step_counts.copy(), env.core.outage_steps.copy())
    actions = np.zeros((3, 3 * N_ROBOTS))
    actions[2, 5] = bad
    with pytest.raises(ValueError, match=r"actions\[2, 5\] \(mission 2, robot 1, power\): expected a finite number"):
        env.step(actions)
    with pytest.raises(
        ValueError, match=r"actions: expected shape \(3, 6\) \(one flat action per mission\), got shape \(3, 2, 3\)"
    ):
        env.step(np.zeros((3, N_ROBOTS, 3)))
    after = (env.positions, env.arrived, env.step_counts, env.core.outage_steps)
    for old, new in zip(before, after, strict=True):
        np.testing.assert_array_equal(old, new)
    env.step(np.zeros((3, 3 * N_ROBOTS)))  # still usable
    assert env.step_counts.tolist() == [1, 1, 1]
