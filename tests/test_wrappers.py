"""The wrappers of the env (noma_radiomap.wrappers): PowerShares checks an action as the env does."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import noma_radiomap
from noma_radiomap.wrappers import PowerShares

BAD_ACTIONS = {
    "a (U, 3) array": np.zeros((2, 3)),
    "a batch of one": np.zeros((1, 6)),
    "too short": np.zeros(5),
    "bools": np.zeros(6, dtype=bool),
    "complex numbers": np.zeros(6, dtype=complex),
    "objects": np.zeros(6, dtype=object),
    "strings": np.array(["0"] * 6),
    "a string": "garbage",
    "ragged": [[0.0, 0.0, 0.0], [0.0, 0.0]],
    "a NaN motion": np.array([np.nan, 0.0, 0.0, 0.0, 0.0, 0.0]),
    "a NaN power": np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.nan]),
    "an infinite power": np.array([0.0, 0.0, -np.inf, 0.0, 0.0, 0.0]),
}


def _wrappers(env: gym.Env) -> list[type]:
    kinds = []
    while isinstance(env, gym.Wrapper):
        kinds.append(type(env))
        env = env.env
    return kinds


def _error(env: gym.Env, action) -> str:
    with pytest.raises(ValueError) as error:
        env.step(action)
    return str(error.value)


@pytest.mark.parametrize("case", list(BAD_ACTIONS))
def test_power_shares_refuse_an_action_as_the_env_does_and_change_nothing(case):
    """Without the check, the wrapper turned (2, 3), (1, 6), bool, complex and object arrays into a valid action."""
    envs = {mapping: gym.make("NomaRadioMap-v0", scenario="small", power_mapping=mapping) for mapping in ("paper", "shares")}
    assert _wrappers(envs["shares"]).count(PowerShares) == 1 and PowerShares not in _wrappers(envs["paper"])
    for env in envs.values():
        env.reset(seed=0)
        env.step(np.zeros(6))
    before = (envs["shares"].unwrapped.positions, envs["shares"].unwrapped.step_count)
    messages = {mapping: _error(env, BAD_ACTIONS[case]) for mapping, env in envs.items()}
    assert messages["shares"] == messages["paper"]
    assert messages["shares"].startswith("action")
    after = (envs["shares"].unwrapped.positions, envs["shares"].unwrapped.step_count)
    assert np.array_equal(before[0], after[0]) and before[1] == after[1] == 1
    envs["shares"].step(np.zeros(6))  # still usable
    assert envs["shares"].unwrapped.step_count == 2


def test_power_shares_take_the_actions_the_env_takes():
    env = gym.make("NomaRadioMap-v0", scenario="small", power_mapping="shares")
    env.reset(seed=0)
    for action in ([0.1, -0.2, 0.5, 0.3, 0.0, -0.5], np.arange(6, dtype=np.int32) - 3, np.full(6, 0.5, dtype=np.float32)):
        env.step(action)
    assert env.unwrapped.step_count == 3


def test_power_shares_before_the_first_reset_say_reset_first():
    env = noma_radiomap.make_env(scenario="small", power_mapping="shares")  # no OrderEnforcing: the env's own check
    for action in (np.zeros(6), np.zeros((2, 3))):
        with pytest.raises(ResetNeeded, match=r"reset"):
            env.step(action)
