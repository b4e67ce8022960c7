import json
import pickle
import re
import warnings

import numpy as np
import pytest
import yaml

from sb3_dtdpg.common.phases import Phase, parse_phases, single_phase
from sb3_dtdpg.missions import default_phases


def test_defaults_and_reward_phase():
    phase = Phase("destination", n_episodes=10, sigma=0.5)
    assert phase.reward_phase == "destination"
    assert phase.noise_schedule() == (0.5, 0.5, 10)
    assert Phase("x", reward_phase="mqi").reward_phase == "mqi"
    assert Phase("x", reward_phase=None).reward_phase is None
    assert Phase("x").noise_schedule() is None
    assert Phase("x", n_timesteps=100, sigma=0.3, final_sigma=0.1, decay_episodes=7).noise_schedule() == (0.3, 0.1, 7)


def test_paper_phases():
    destination, mqi = default_phases()
    assert (destination.name, destination.reward_phase, destination.sigma) == ("destination", "destination", 0.5)
    assert (mqi.name, mqi.reward_phase, mqi.sigma) == ("mqi", "mqi", 0.4)
    assert destination.has_budget and not mqi.has_budget
    assert destination.success_threshold == 0.95
    (train,) = single_phase(0.2)
    assert train.reward_phase is None and train.noise_schedule() == (0.2, 0.2, 1)


@pytest.mark.parametrize(
    ("kwargs", "field", "value"),
    [
        ({"name": ""}, "name", "''"),
        ({"name": "a", "n_episodes": 0}, "n_episodes", "0"),
        ({"name": "a", "n_episodes": 2.5}, "n_episodes", "2.5"),
        ({"name": "a", "n_timesteps": True}, "n_timesteps", "True"),
        ({"name": "a", "n_episodes": 3, "n_timesteps": 9}, "n_timesteps", "9"),
        ({"name": "a", "sigma": -0.1}, "sigma", "-0.1"),
        ({"name": "a", "sigma": float("nan")}, "sigma", "nan"),
        ({"name": "a", "final_sigma": 0.1}, "final_sigma", "0.1"),
        ({"name": "a", "success_threshold": 1.5}, "success_threshold", "1.5"),
        ({"name": "a", "success_threshold": 0}, "success_threshold", "0"),
        ({"name": "a", "success_window": 0}, "success_window", "0"),
        ({"name": "a", "replay_handling": "drop"}, "replay_handling", "'drop'"),
        ({"name": "a", "reward_phase": 3}, "reward_phase", "3"),
    ],
)
def test_bad_field_names_field_and_value(kwargs, field, value):
    with pytest.raises(ValueError, match=field) as info:
        Phase(**kwargs)
    assert value in str(info.value)


def test_early_transfer_that_cannot_happen_is_warned():
    """A success window longer than the phase's episode budget never fills: the threshold would be dead silently."""
    with pytest.warns(UserWarning, match=r"success_window=20 is longer than the phase's n_episodes=10"):
        (destination, _) = default_phases(destination_episodes=10)
    assert destination.success_threshold == 0.95
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Phase("a", n_episodes=20, success_threshold=0.9, success_window=20)
        Phase("a", n_episodes=10, success_window=20)  # no early transfer asked for
        Phase("a", n_timesteps=10, success_threshold=0.9, success_window=20)  # steps, not episodes


def test_decay_without_horizon():
    with pytest.raises(ValueError, match="decay_episodes"):
        parse_phases([Phase("a", n_timesteps=10, sigma=0.5, final_sigma=0.1)])


def test_parse_phases_from_yaml_dicts():
    text = """
    - {name: destination, n_episodes: 30, sigma: 0.5, final_sigma: 0.1, success_threshold: 0.9, success_window: 5}
    - {name: mqi, sigma: 0.4, replay_handling: relabel}
    """
    phases = parse_phases(yaml.safe_load(text))
    assert phases == [
        Phase("destination", n_episodes=30, sigma=0.5, final_sigma=0.1, success_threshold=0.9, success_window=5),
        Phase("mqi", sigma=0.4, replay_handling="relabel"),
    ]


@pytest.mark.parametrize(
    ("phases", "match"),
    [
        ([], "at least one"),
        ([{"name": "a", "n_episodes": 3, "sigmaa": 0.2}], "sigmaa"),
        ([{"n_episodes": 3}], "name"),
        ([Phase("a", n_episodes=1), Phase("a")], "unique"),
        ([Phase("a"), Phase("b")], r"phases\[0\] \('a'\) has no budget"),
        (Phase("a"), "sequence"),
        (["a"], "dict"),
    ],
)
def test_parse_phases_errors(phases, match):
    with pytest.raises(ValueError, match=match):
        parse_phases(phases)


def test_round_trips():
    phases = default_phases(replay_handling="relabel")
    assert pickle.loads(pickle.dumps(phases)) == phases
    as_json = json.loads(json.dumps([phase.to_dict() for phase in phases]))
    assert parse_phases(as_json) == phases
    no_env_phase = Phase("train", reward_phase=None, n_episodes=4)
    assert Phase.from_dict(no_env_phase.to_dict()) == no_env_phase


def test_numpy_numbers_are_the_python_numbers_they_hold():
    phase = Phase("a", n_episodes=np.int64(30), sigma=np.float32(0.25), success_threshold=np.float64(0.5))
    assert (phase.n_episodes, phase.sigma, phase.success_threshold) == (30, 0.25, 0.5)
    assert type(phase.n_episodes) is int and type(phase.sigma) is float
    assert json.loads(json.dumps(phase.to_dict()))["n_episodes"] == 30
    with pytest.raises(ValueError, match=r"n_episodes must be a positive integer or None, got 2\.5"):
        Phase("a", n_episodes=np.float64(2.5))


def test_mission_logger_window_is_a_positive_integer():
    from sb3_dtdpg.missions import MissionLoggerCallback

    assert MissionLoggerCallback(stats_window_size=np.int64(5)).stats_window_size == 5
    for bad in (2.5, "5", 0, True):
        with pytest.raises(ValueError, match=re.escape(f"stats_window_size must be a positive integer or None, got {bad!r}")):
            MissionLoggerCallback(stats_window_size=bad)


def test_hyperparameter_values_take_lists_of_dict_calls():
    from sb3_dtdpg.overrides import HyperparameterError, parse_value

    phases = "[dict(name='destination', n_episodes=50, sigma=0.5), dict(name='mqi', sigma=0.4)]"
    assert parse_value(phases) == [{"name": "destination", "n_episodes": 50, "sigma": 0.5}, {"name": "mqi", "sigma": 0.4}]
    assert parse_value("{'a': dict(b=(1, 2))}") == {"a": {"b": (1, 2)}}
    for bad in ("[dict(**x)]", "[print(1)]", "{[1]: 2}"):
        with pytest.raises(HyperparameterError):
            parse_value(bad)
