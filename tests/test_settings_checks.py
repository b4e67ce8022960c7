"""Every numeric setting of DTDPG, of learn() and of the baselines (through make_model) is range-checked where it
enters, the error naming the field and the value."""

import re

import gymnasium as gym
import numpy as np
import pytest
import torch as th

from sb3_dtdpg import DTDPG
from sb3_dtdpg.baselines import make_env, make_model

TINY = dict(policy_kwargs=dict(net_arch=[8]), learning_starts=10, batch_size=8)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(buffer_size=0), "buffer_size must be an integer >= 1, got 0"),
        (dict(buffer_size=-1), "buffer_size must be an integer >= 1, got -1"),
        (dict(buffer_size=1e5), "buffer_size must be an integer >= 1, got 100000.0"),
        (dict(batch_size=0), "batch_size must be an integer >= 1, got 0"),
        (dict(n_steps=0), "n_steps must be an integer >= 1, got 0"),
        (dict(n_steps=-3), "n_steps must be an integer >= 1, got -3"),
        (dict(gamma=1.5), "gamma must be a number in [0, 1], got 1.5"),
        (dict(gamma=float("nan")), "gamma must be a number in [0, 1], got nan"),
        (dict(tau=2), "tau must be a number in (0, 1], got 2"),
        (dict(tau=0.0), "tau must be a number in (0, 1], got 0.0"),
        (dict(policy_kwargs=dict(net_arch=[0])), "policy_kwargs['net_arch'] must hold layer sizes >= 1, got [0]"),
        (dict(policy_kwargs=dict(net_arch=dict(pi=[8], qf=[-1]))), "policy_kwargs['net_arch'] must hold layer sizes"),
        (dict(learning_rate=float("inf")), "learning_rate must be a finite number > 0, got inf"),
        (dict(learning_rate=float("nan")), "learning_rate must be a finite number > 0, got nan"),
        (dict(learning_rate=-1), "learning_rate must be a finite number > 0, got -1"),
        (dict(learning_rate=0.0), "learning_rate must be a finite number > 0, got 0.0"),
        (
            dict(learning_rate=lambda progress: float("inf")),
            "the initial value of the learning-rate schedule must be a finite",
        ),
        (dict(learning_starts=-1), "learning_starts must be an integer >= 0, got -1"),
        (dict(train_freq=0), "train_freq must be a Python integer >= 1 or a tuple (frequency, unit) with one, got 0"),
        (dict(train_freq=[2, "episode"]), "train_freq must be a Python integer >= 1 or a tuple"),  # SB3 refuses lists
        (
            dict(train_freq=np.int64(2)),
            "train_freq must be a Python integer >= 1 or a tuple (frequency, unit) with one, got 2 (numpy.int64)",
        ),  # ... and numpy integers, named with their type (numpy 1 shows np.int64(2) as a bare 2)
        (
            dict(train_freq=(np.int32(2), "episode")),
            "train_freq must be a Python integer >= 1 or a tuple (frequency, unit) with one, got (2 (numpy.int32), 'episode')",
        ),
        (dict(train_freq=(2, "epoch")), "the unit of train_freq must be 'step' or 'episode', got 'epoch'"),
        (dict(gradient_steps=-2), "gradient_steps must be an integer >= 0, or -1, got -2"),
        (dict(gradient_steps=1.5), "gradient_steps must be an integer >= 0, or -1, got 1.5"),
        (dict(n_steps=10**9), "n_steps must be at most buffer_size (1000000), got 1000000000"),
        (dict(policy_kwargs="x"), "policy_kwargs must be a dict, e.g. dict(net_arch=[64, 64]), got 'x'"),
        (dict(reinitialize_at_transfer="no"), "reinitialize_at_transfer must be True or False, got 'no'"),
        (dict(lean=None), "lean must be True or False, got None"),
    ],
)
def test_dtdpg_constructor_ranges(kwargs, message):
    with pytest.raises(ValueError, match=re.escape(f"DTDPG: {message}")):
        DTDPG("MlpPolicy", "Pendulum-v1", **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(log_interval=0), "log_interval must be a positive integer or None, got 0"),  # was a ZeroDivisionError
        (dict(callback=5), "callback must be a BaseCallback, a function or a list of these, got int 5"),
        (dict(callback=[lambda *_: True, "x"]), "got str 'x'"),
    ],
)
def test_learn_refuses_arguments_that_would_fail_mid_training(kwargs, message):
    model = DTDPG("MlpPolicy", "Pendulum-v1", **TINY)
    with pytest.raises(ValueError, match=re.escape(message)):
        model.learn(20, **kwargs)
    assert model.num_timesteps == 0


def test_load_checks_the_settings_it_is_given(tmp_path):
    DTDPG("MlpPolicy", "Pendulum-v1", **TINY).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=re.escape("DTDPG.load: gamma must be a number in [0, 1], got 5.0")):
        DTDPG.load(tmp_path / "model.zip", gamma=5.0)
    assert DTDPG.load(tmp_path / "model.zip", gamma=0.5).gamma == 0.5


@pytest.mark.parametrize("total_timesteps", [-5, 0, 2.5, "100", True])
def test_learn_needs_a_positive_integer_budget(total_timesteps):
    model = DTDPG("MlpPolicy", "Pendulum-v1", **TINY)
    with pytest.raises(ValueError, match=re.escape(f"total_timesteps must be a positive integer, got {total_timesteps!r}")):
        model.learn(total_timesteps)
    assert model.num_timesteps == 0


def test_learn_takes_a_float_budget_of_whole_steps_as_sb3_does():
    model = DTDPG("MlpPolicy", "Pendulum-v1", **TINY).learn(1e2)  # e.g. learn(1e5): was refused
    assert model.num_timesteps == 100 and model._total_timesteps == 100


def test_load_uses_the_replay_buffer_class_it_is_given(tmp_path):
    from stable_baselines3.common.buffers import ReplayBuffer

    class MyBuffer(ReplayBuffer):
        pass

    DTDPG("MlpPolicy", "Pendulum-v1", **TINY).save(tmp_path / "model.zip")
    model = DTDPG.load(tmp_path / "model.zip", env=gym.make("Pendulum-v1"), replay_buffer_class=MyBuffer)
    assert model.replay_buffer_class is MyBuffer and type(model.replay_buffer) is MyBuffer  # was SB3's, silently
    assert type(DTDPG.load(tmp_path / "model.zip", env=gym.make("Pendulum-v1")).replay_buffer) is not MyBuffer


def test_load_with_a_learning_rate_of_0_freezes_the_model_as_sb3_does(tmp_path):
    DTDPG("MlpPolicy", "Pendulum-v1", **TINY).save(tmp_path / "model.zip")
    model = DTDPG.load(tmp_path / "model.zip", env=gym.make("Pendulum-v1"), learning_rate=0.0)  # was refused
    before = [p.detach().clone() for p in model.actor.parameters()]
    model.learn(30)
    assert model.actor.optimizer.param_groups[0]["lr"] == 0.0
    assert all(th.equal(a, b.detach()) for a, b in zip(before, model.actor.parameters(), strict=True))


def test_learn_without_an_env_is_sb3s_error(tmp_path):
    from stable_baselines3.common.env_util import make_vec_env

    DTDPG("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=2), **TINY).learn(20).save(tmp_path / "model.zip")
    with pytest.raises(AssertionError, match="You must set the environment before calling _setup_learn"):
        DTDPG.load(tmp_path / "model.zip").learn(10)  # was an AttributeError on None.num_envs


@pytest.mark.parametrize("setting", ["curriculum_save_path", "tensorboard_log"])
def test_a_folder_setting_that_is_a_file_is_refused_at_construction(tmp_path, setting):
    path = tmp_path / "taken"
    path.write_text("another run's file")
    with pytest.raises(ValueError, match=f"{setting} must be a folder, got the file"):
        DTDPG("MlpPolicy", "Pendulum-v1", **{setting: str(path)}, **TINY)
    assert path.read_text() == "another run's file"
    DTDPG("MlpPolicy", "Pendulum-v1", **{setting: str(tmp_path / "new")}, **TINY)  # a folder to be made


@pytest.mark.parametrize(
    "algo, kwargs, message",
    [
        ("ddpg", dict(learning_rate=float("inf")), "ddpg: learning_rate must be a finite number > 0, got inf"),
        ("td3", dict(batch_size=0), "td3: batch_size must be an integer >= 1, got 0"),
        ("sac", dict(gamma=2.0), "sac: gamma must be a number in [0, 1], got 2.0"),
        ("tqc", dict(policy_kwargs=dict(net_arch=[0])), "tqc: policy_kwargs['net_arch'] must hold layer sizes >= 1"),
        ("dtdpg", dict(buffer_size=-1), "dtdpg: buffer_size must be an integer >= 1, got -1"),
    ],
)
def test_make_model_checks_every_algorithm(algo, kwargs, message):
    env = make_env(algo, env_kwargs={"scenario": "small"})
    with pytest.raises(ValueError, match=re.escape(message)):
        make_model(algo, env, **kwargs)
    with pytest.raises(ValueError, match=re.escape("learning_rate must be a finite number > 0, got -1.0")):
        make_model(algo, env, learning_rate=-1.0)


def test_the_curriculum_callback_refuses_a_file_as_its_folder(tmp_path):
    from sb3_dtdpg import CurriculumTransferCallback, Phase

    (tmp_path / "taken").write_text("")
    with pytest.raises(ValueError, match="CurriculumTransferCallback: save_path must be a folder, got the file"):
        CurriculumTransferCallback([Phase("train", reward_phase=None)], save_path=tmp_path / "taken")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("episodes", 2.5, "RunSpec.episodes: expected an integer from 1"),
        ("seed", 1.5, "RunSpec.seed: expected an integer from 0"),  # was a numpy TypeError at the first reset
        ("seed", "0", "RunSpec.seed: expected an integer from 0"),
        ("eval_episodes", 0, "RunSpec.eval_episodes: expected an integer from 1"),  # all failed after training
        ("eval_seed", -1, "RunSpec.eval_seed: expected an integer from 0"),
        ("eval_channel", "x", "RunSpec.eval_channel: expected one of ('radio_map', 'rayleigh'), got 'x'"),
        ("destination_episodes", 0, "RunSpec.destination_episodes: expected an integer from 1"),  # trained 2
        ("tag", "a/b", "RunSpec.tag: expected letters, digits and ._+-"),  # a nested run folder
    ],
)
def test_a_run_spec_no_run_can_have_is_refused_when_made(field, value, message):
    from sb3_dtdpg.experiments.specs import RunSpec

    with pytest.raises(ValueError, match=re.escape(message)):
        RunSpec("dtdpg", "noma", **{"seed": 0, "episodes": 3, field: value})


def test_a_run_spec_with_an_unknown_override_is_refused_before_training():
    from sb3_dtdpg.experiments.specs import RunSpec, run_identity

    spec = RunSpec("dtdpg", "noma", 0, 3, scenario="small", overrides=(("gamam", "0.9"),))
    with pytest.raises(
        ValueError, match=r"unknown hyperparameter 'gamam' for DTDPG \(RunSpec.overrides\); did you mean 'gamma'"
    ):
        run_identity(spec)


def test_a_run_spec_is_the_same_run_whatever_the_order_of_its_overrides():
    from sb3_dtdpg.experiments.specs import RunSpec, run_identity

    given = (("tau", "0.01"), ("gamma", "0.9"))
    spec, reordered = (RunSpec("dtdpg", "noma", 0, 3, scenario="small", overrides=pairs) for pairs in (given, given[::-1]))
    assert spec == reordered and spec.run_id == reordered.run_id  # was: two run ids, the run trained twice
    assert run_identity(spec) == run_identity(reordered)
    assert spec.override_kwargs == {"gamma": 0.9, "tau": 0.01}


@pytest.mark.parametrize(
    "overrides, message",
    [
        ((("gamma", "0.9"), ("gamma", "0.8")), "each hyperparameter once"),
        ((("gamma", 0.9),), "pairs of strings"),
        (("gamma",), "pairs of strings"),
        (None, "pairs of strings"),
        ((pair for pair in [("gamma", "0.9")]), "pairs of strings"),  # was: a generator read once, no overrides left
    ],
)
def test_a_run_spec_refuses_overrides_that_are_not_one_pair_per_hyperparameter(overrides, message):
    from sb3_dtdpg.experiments.specs import RunSpec

    with pytest.raises(ValueError, match=rf"RunSpec.overrides: .*{message}.*got {re.escape(repr(overrides))}"):
        RunSpec("dtdpg", "noma", 0, 3, overrides=overrides)


def test_an_action_noise_of_another_shape_is_refused_at_construction():
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise, VectorizedActionNoise

    env = make_env("dtdpg", env_kwargs={"scenario": "small"})
    shape = env.action_space.shape
    wrong = NormalActionNoise(np.zeros(shape[0] - 1), np.ones(shape[0] - 1))  # was a broadcast error at learning_starts
    message = f"DTDPG: action_noise draws noise of shape ({shape[0] - 1},), which does not fit the action space's shape"
    with pytest.raises(ValueError, match=re.escape(message)):
        DTDPG("MlpPolicy", env, action_noise=wrong, **TINY)
    with pytest.raises(ValueError, match=re.escape(message)):
        DTDPG("MlpPolicy", env, action_noise=VectorizedActionNoise(wrong, 2), **TINY)
    for fitting in (OrnsteinUhlenbeckActionNoise(np.zeros(shape), np.ones(shape)), NormalActionNoise(np.zeros(1), np.ones(1))):
        model = DTDPG("MlpPolicy", env, action_noise=fitting, **TINY)
        model.learn(12)  # past learning_starts: the noise is added to the policy's actions
        assert model.num_timesteps == 12


def test_an_action_noise_whose_mean_and_sigma_disagree_is_refused_at_construction():
    from stable_baselines3.common.noise import NormalActionNoise

    env = make_env("dtdpg", env_kwargs={"scenario": "small"})
    n = env.action_space.shape[0]
    with pytest.raises(ValueError, match=re.escape(f"mean of shape ({n},) and a sigma of shape ({n - 1},)")):
        DTDPG("MlpPolicy", env, action_noise=NormalActionNoise(np.zeros(n), np.ones(n - 1)), **TINY)


def test_load_checks_the_action_noise_it_is_given(tmp_path):
    from stable_baselines3.common.noise import NormalActionNoise

    env = make_env("dtdpg", env_kwargs={"scenario": "small"})
    n = env.action_space.shape[0]
    DTDPG("MlpPolicy", env, **TINY).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=re.escape(f"DTDPG.load: action_noise draws noise of shape ({n - 1},)")):
        DTDPG.load(tmp_path / "model.zip", env=env, action_noise=NormalActionNoise(np.zeros(n - 1), np.ones(n - 1)))
    fitting = NormalActionNoise(np.zeros(n), np.ones(n))
    assert DTDPG.load(tmp_path / "model.zip", env=env, action_noise=fitting).action_noise is fitting


@pytest.mark.parametrize(
    "buffer_kwargs, message",
    [
        (dict(n_steps=3), "replay_buffer_kwargs['n_steps'] = 3 differs from the model's n_steps = 1"),  # was one-step
        (dict(n_steps=1, gamma=0.5), "replay_buffer_kwargs['gamma'] = 0.5 differs from the model's gamma = 0.99"),
    ],
)
def test_returns_given_in_replay_buffer_kwargs_that_the_model_would_replace_are_refused(buffer_kwargs, message):
    with pytest.raises(ValueError, match=re.escape(f"DTDPG: {message}")):
        DTDPG("MlpPolicy", "Pendulum-v1", replay_buffer_kwargs=buffer_kwargs, **TINY)
    model = DTDPG("MlpPolicy", "Pendulum-v1", n_steps=3, replay_buffer_kwargs=dict(n_steps=3, gamma=0.99), **TINY)
    assert (model.replay_buffer.n_steps, model.replay_buffer.gamma) == (3, 0.99)  # the same values: taken as given


def test_load_refuses_returns_in_replay_buffer_kwargs_that_the_model_would_replace(tmp_path):
    DTDPG("MlpPolicy", "Pendulum-v1", n_steps=3, **TINY).save(tmp_path / "model.zip")
    message = "DTDPG.load: replay_buffer_kwargs['n_steps'] = 5 differs from the model's n_steps = 3"
    with pytest.raises(ValueError, match=re.escape(message)):  # was a buffer of 3-step returns, without a word
        DTDPG.load(tmp_path / "model.zip", replay_buffer_kwargs={"n_steps": 5})
    model = DTDPG.load(tmp_path / "model.zip", n_steps=5, replay_buffer_kwargs={"n_steps": 5}, env=gym.make("Pendulum-v1"))
    assert model.replay_buffer.n_steps == 5


def test_shortened_lists_name_the_first_items_and_count_the_others():
    from sb3_dtdpg.common.checks import shortened

    assert shortened(["a", "b"], 3) == "a, b"
    assert shortened(["a", "b", "c", "d", "e"], 3) == "a, b, c and 2 more"
    assert shortened(["a", "b", "c", "d"], 2, separator="; ") == "a; b; and 2 more"
    with pytest.raises(ValueError, match="limit must be an integer >= 1, got 0"):
        shortened(["a", "b"], 0)  # was " and 2 more"
