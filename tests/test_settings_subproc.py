"""The settings of the envs of a ``SubprocVecEnv`` are read in their processes: recorded and checked as a DummyVecEnv's."""

import warnings
from contextlib import contextmanager

import gymnasium as gym
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

from noma_radiomap import NomaRadioMapEnv
from noma_radiomap.wrappers import RelativeGoalObservation
from sb3_dtdpg import DTDPG, env_settings
from sb3_dtdpg.env_settings import EnvSettingsMismatch, settings_of

# fork: the workers start fast and need no ``if __name__ == "__main__"`` guard
FORK = {"start_method": "fork"}


def small_vec_env(vec_env_cls=None, wrapper_class=None, wrapper_kwargs=None, **env_kwargs):
    return make_vec_env(
        "NomaRadioMap-v0",
        n_envs=2,
        env_kwargs={"scenario": "small", **env_kwargs},
        wrapper_class=wrapper_class,
        wrapper_kwargs=wrapper_kwargs,
        vec_env_cls=vec_env_cls,
        vec_env_kwargs=FORK if vec_env_cls is SubprocVecEnv else None,
    )


@contextmanager
def subproc(env_fns=None, **kwargs):
    """A SubprocVecEnv of two small mission envs built with ``kwargs`` (or of ``env_fns``), closed afterwards."""
    env = SubprocVecEnv(env_fns, **FORK) if env_fns else small_vec_env(SubprocVecEnv, **kwargs)
    try:
        yield env
    finally:
        env.close()


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({}, {"multiple_access": "noma", "observation": "goal", "power_mapping": "paper"}),
        ({"multiple_access": "oma"}, {"multiple_access": "oma"}),
        ({"power_mapping": "shares"}, {"power_mapping": "shares"}),
        ({"observation": "destinations", "wrapper_class": RelativeGoalObservation}, {"observation": "goal"}),
        (
            {"observation": "paper", "wrapper_class": RelativeGoalObservation, "wrapper_kwargs": {"distance_scale": 4.0}},
            {"observation": "paper+RelativeGoalObservation(distance_scale=4.0)"},
        ),
    ],
    ids=["plain", "oma", "power-shares", "relative-goal", "relative-goal-scaled"],
)
def test_subproc_settings_are_those_of_the_same_env_in_a_dummy_vec_env(kwargs, expected):
    dummy = settings_of(small_vec_env(**kwargs))
    assert dummy is not None and dummy.items() >= expected.items()
    with subproc(**kwargs) as env:
        assert settings_of(env) == dummy
        assert settings_of(VecNormalize(env)) == dummy  # behind a VecEnvWrapper too
        assert len(env.reset()) == 2  # the workers live on


def test_a_model_of_a_subproc_env_records_its_settings_and_is_refused_on_other_ones(tmp_path):
    with subproc() as env:
        model = DTDPG("MlpPolicy", env, buffer_size=100, seed=0)
        model.save(tmp_path / "noma.zip")
        assert model.env_settings == settings_of(small_vec_env())
    with pytest.raises(EnvSettingsMismatch, match="multiple_access='noma'"):
        DTDPG.load(tmp_path / "noma.zip", env=gym.make("NomaRadioMap-v0", scenario="small", multiple_access="oma"))
    DTDPG.load(tmp_path / "noma.zip", env=gym.make("NomaRadioMap-v0", scenario="small"))


def test_set_env_of_a_subproc_env_of_other_settings_is_refused(tmp_path):
    DTDPG("MlpPolicy", small_vec_env(), buffer_size=100, seed=0).save(tmp_path / "noma.zip")
    model = DTDPG.load(tmp_path / "noma.zip", env=small_vec_env())
    with subproc(multiple_access="oma") as oma, pytest.raises(EnvSettingsMismatch, match="multiple_access='noma'"):
        model.set_env(oma)
    assert model.get_env().num_envs == 2 and settings_of(model.get_env())["multiple_access"] == "noma"


def test_a_remote_mission_env_that_cannot_be_read_is_warned_of_once(monkeypatch):
    monkeypatch.setattr(env_settings, "_WARNED", set(), raising=False)
    # no Gymnasium wrapper around the env: nothing in its process to ask
    with subproc([lambda: NomaRadioMapEnv(scenario="small")] * 2) as env:
        with pytest.warns(UserWarning, match=r"first env of this SubprocVecEnv cannot be read \(its first env has no"):
            assert settings_of(env) is None
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert settings_of(env) is None  # once
        assert env.get_attr("multiple_access") == ["noma", "noma"]  # the workers live on
    with pytest.warns(UserWarning, match=r"SubprocVecEnv cannot be read \(it is closed\)"):
        assert settings_of(env) is None
    # an env of another kind has no settings to miss
    with subproc([lambda: gym.make("Pendulum-v1").unwrapped] * 2) as env, warnings.catch_warnings():
        warnings.simplefilter("error")
        assert settings_of(env) is None
    with subproc([lambda: gym.make("Pendulum-v1")] * 2) as env, warnings.catch_warnings():
        warnings.simplefilter("error")
        assert settings_of(env) is None
