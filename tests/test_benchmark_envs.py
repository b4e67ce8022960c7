"""The learning benchmarks (benchmarks/targets.py) train on the observation layout they are asked for."""

import importlib.util
from pathlib import Path

import gymnasium as gym
import pytest

import noma_radiomap  # noqa: F401

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_script(name: str):
    spec = importlib.util.spec_from_file_location(f"benchmark_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("observation", ["goal", "destinations"])
def test_targets_trains_on_the_env_layout_it_names(observation):
    targets = load_script("targets")
    env = targets._make_env("NomaRadioMap-v0", observation, scenario="small")
    reference = gym.make("NomaRadioMap-v0", observation=observation, scenario="small")
    assert env.observation_space == reference.observation_space  # no second set of goal features
    obs, _ = env.reset(seed=3)
    expected, _ = reference.reset(seed=3)
    assert (obs == expected).all()


def test_targets_env_kwargs_may_name_another_layout():
    targets = load_script("targets")
    env = targets._make_env("NomaRadioMap-v0", "goal", scenario="small", observation="destinations")
    assert env.unwrapped.observation == "destinations"
