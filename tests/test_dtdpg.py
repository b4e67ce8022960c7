"""SB3's generic checks applied to DTDPG (run, save/load, replay buffer, set_env, determinism, multi-env)."""

import contextlib
import inspect
import os
import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
import stable_baselines3
import torch as th
from gymnasium.wrappers import TimeLimit
from packaging.version import Version
from phased_env import PhasedPointEnv
from stable_baselines3 import DDPG
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.noise import VectorizedActionNoise

from sb3_dtdpg import DTDPG, LinearDecayOUNoise, Phase
from sb3_dtdpg.common.buffers import RewardComponentsNStepReplayBuffer, RewardComponentsReplayBuffer
from sb3_dtdpg.common.noise import NormalNoise
from sb3_dtdpg.dtdpg.policies import DTDPGPolicy

TINY = dict(policy_kwargs=dict(net_arch=[32]), learning_starts=50, batch_size=32)

#: SB3 2.9.2 warns that ``n_steps`` is ignored with a custom ``replay_buffer_class``; 2.9.0 ignores it silently
SB3_WARNS_OF_IGNORED_N_STEPS = Version(stable_baselines3.__version__) >= Version("2.9.2")


def _sb3s_ignored_n_steps_warning(n_steps: int) -> contextlib.AbstractContextManager:
    """SB3's own warning that ``n_steps`` is ignored, where this SB3 gives it."""
    if SB3_WARNS_OF_IGNORED_N_STEPS:
        return pytest.warns(UserWarning, match=f"`n_steps={n_steps}` is ignored because a custom `replay_buffer_class`")
    return contextlib.nullcontext()


def _pendulum(max_episode_steps: int = 200) -> gym.Env:
    return TimeLimit(gym.make("Pendulum-v1").unwrapped, max_episode_steps=max_episode_steps)


def _phased() -> gym.Env:
    # the robot cannot reach its destination in 20 steps: every episode lasts exactly 20 steps
    return TimeLimit(PhasedPointEnv(v_max=0.02, starts=[[0.05, 0.05]], destinations=[[0.95, 0.95]]), max_episode_steps=20)


def _params(model: DTDPG) -> dict[str, th.Tensor]:
    return {f"{key}.{name}": value for key, state in model.get_parameters().items() for name, value in state.items()}


def _assert_same_params(model_a: DTDPG, model_b: DTDPG) -> None:
    params_a, params_b = _params(model_a), _params(model_b)
    assert params_a.keys() == params_b.keys()
    for key in params_a:
        th.testing.assert_close(params_a[key], params_b[key], rtol=0, atol=0, msg=key)


def test_defaults_are_sb3_ddpgs():
    """The constructor's defaults are SB3's DDPG defaults (generic); the mission's settings are presets."""
    ddpg = inspect.signature(DDPG.__init__).parameters
    dtdpg = inspect.signature(DTDPG.__init__).parameters
    for name in ddpg:
        if name not in ("self", "policy", "env"):
            assert dtdpg[name].default == ddpg[name].default, name
    model, reference = DTDPG("MlpPolicy", "Pendulum-v1"), DDPG("MlpPolicy", "Pendulum-v1")
    for key in ("learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma", "n_steps", "train_freq"):
        assert getattr(model, key) == getattr(reference, key), key
    assert isinstance(model.policy, DTDPGPolicy)
    assert isinstance(model.actor.optimizer, th.optim.Adam)
    assert [layer.out_features for layer in model.actor.mu if isinstance(layer, th.nn.Linear)] == [128, 128, 1]
    assert len(model.critic.q_networks) == 1  # DDPG: one critic
    assert model.policy_delay == 1 and model.target_noise_clip == 0.0
    # the noise: linearly decayed OU armed from the single phase of an env that offers no curriculum
    assert [phase.reward_phase for phase in model.phases] == [None]
    assert isinstance(model.action_noise, LinearDecayOUNoise)
    np.testing.assert_array_equal(model.action_noise.current_sigma, [model.phases[0].sigma])


def test_is_a_drop_in_for_ddpg():
    ddpg_args = list(inspect.signature(DDPG.__init__).parameters)
    dtdpg_args = list(inspect.signature(DTDPG.__init__).parameters)
    assert dtdpg_args[: len(ddpg_args) - 1] == ddpg_args[:-1]  # same order, _init_setup_model last
    assert dtdpg_args[-1] == "_init_setup_model"


def test_phases_and_noise_on_a_phased_env():
    # an env with reward phases but no curriculum of its own: one phase that leaves its reward alone
    model = DTDPG("MlpPolicy", PhasedPointEnv())
    assert [(phase.name, phase.reward_phase) for phase in model.phases] == [("train", None)]
    assert noise_sigma_of(model) == 0.5
    # a user's noise is used as is: the default phases do not re-arm it
    user_noise = NormalNoise(np.zeros(3), 0.2 * np.ones(3))  # re-armable: the test sees that it is not re-armed
    model = DTDPG("MlpPolicy", _CurriculumPhasedEnv(v_max=0.02), action_noise=user_noise, phases=None, **TINY)
    assert model.action_noise is user_noise
    assert [phase.sigma for phase in model.phases] == [None, None]
    model.learn(60)
    assert model.action_noise is user_noise and noise_sigma_of(model) == pytest.approx(0.2)
    phases = [dict(name="destination", n_episodes=2, sigma=0.3, final_sigma=0.1), dict(name="mqi", replay_handling="relabel")]
    model = DTDPG("MlpPolicy", PhasedPointEnv(), phases=phases, n_steps=3)
    assert model.replay_buffer_class is RewardComponentsNStepReplayBuffer
    assert isinstance(model.replay_buffer, RewardComponentsReplayBuffer)
    assert noise_sigma_of(model) == 0.3
    assert type(DTDPG("MlpPolicy", PhasedPointEnv(), replay_buffer_class=ReplayBuffer, phases=phases[:1]).replay_buffer) is (
        ReplayBuffer
    )


def test_relabel_with_n_step_returns_picks_the_n_step_components_buffer(tmp_path):
    phases = [dict(name="destination", n_episodes=2, sigma=0.3), dict(name="mqi", replay_handling="relabel")]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # SB3's "n_steps is ignored" warning would be wrong here
        model = DTDPG("MlpPolicy", PhasedPointEnv(), phases=phases, n_steps=3, gamma=0.9, **TINY)
        buffer = model.replay_buffer
        assert type(buffer) is RewardComponentsNStepReplayBuffer
        assert (buffer.n_steps, buffer.gamma) == (3, 0.9)
        model.save(tmp_path / "model")
        loaded = DTDPG.load(tmp_path / "model", env=PhasedPointEnv())
    assert type(loaded.replay_buffer) is RewardComponentsNStepReplayBuffer
    assert (loaded.replay_buffer.n_steps, loaded.replay_buffer.gamma) == (3, 0.9)


def test_load_with_other_returns_rebuilds_the_buffer_the_model_picked(tmp_path):
    model = DTDPG("MlpPolicy", _pendulum(), n_steps=3, gamma=0.95, **TINY)
    model.save(tmp_path / "model")
    loaded = DTDPG.load(tmp_path / "model", env=_pendulum(), gamma=0.5)  # the returns follow the model's gamma
    assert (loaded.gamma, loaded.replay_buffer.gamma, loaded.replay_buffer.n_steps) == (0.5, 0.5, 3)
    assert DTDPG.load(tmp_path / "model", env=_pendulum(), n_steps=5).replay_buffer.n_steps == 5
    assert type(DTDPG.load(tmp_path / "model", env=_pendulum(), n_steps=1).replay_buffer) is ReplayBuffer
    # a zip saved before the buffer followed the returns keeps its buffer's, and says so
    model._buffer_follows_returns = False  # as such a zip loads
    model.save(tmp_path / "older")
    with (
        pytest.warns(UserWarning, match=r"the replay buffer of .*older.* keeps n_steps=3 .*pass replay_buffer_kwargs"),
        _sb3s_ignored_n_steps_warning(5),
    ):
        assert DTDPG.load(tmp_path / "older", env=_pendulum(), n_steps=5).replay_buffer.n_steps == 3
    # a buffer the user chose stays as given
    given = DTDPG("MlpPolicy", _pendulum(), replay_buffer_class=ReplayBuffer, **TINY)
    given.save(tmp_path / "given")
    with _sb3s_ignored_n_steps_warning(3):
        assert type(DTDPG.load(tmp_path / "given", env=_pendulum(), n_steps=3).replay_buffer) is ReplayBuffer


def test_a_batch_of_one_is_refused_with_batch_norm():
    with pytest.raises(ValueError, match=r"batch_size must be at least 2 with batch normalisation .*got 1"):
        DTDPG("MlpPolicy", "Pendulum-v1", batch_size=1)
    # without batch norm a batch of one has no variance to take: SB3's DDPG trains on it
    plain = dict(actor_norm="none", critic_norm="none")
    DTDPG("MlpPolicy", "Pendulum-v1", batch_size=1, learning_starts=5, policy_kwargs=plain).learn(10)


def test_a_model_of_two_envs_trains_on_one_or_three(tmp_path):
    model = DTDPG("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=2), **TINY).learn(60)
    model.save(tmp_path / "two")
    one = DTDPG.load(tmp_path / "two", env=_pendulum()).learn(40, reset_num_timesteps=False)
    assert isinstance(one.action_noise, LinearDecayOUNoise) and one.num_timesteps == 100
    three = DTDPG.load(tmp_path / "two", env=make_vec_env("Pendulum-v1", n_envs=3)).learn(60)
    assert isinstance(three.action_noise, VectorizedActionNoise) and len(three.action_noise.noises) == 3


def test_load_checks_its_switches_and_phases(tmp_path):
    DTDPG("MlpPolicy", "Pendulum-v1", **TINY).save(tmp_path / "model")
    with pytest.raises(ValueError, match=r"DTDPG\.load: lean must be True or False, got 'no'"):
        DTDPG.load(tmp_path / "model", lean="no")
    loaded = DTDPG.load(tmp_path / "model", phases=[dict(name="destination", n_episodes=3)])
    assert loaded.phases == [Phase(name="destination", n_episodes=3)]


def noise_sigma_of(model: DTDPG) -> float:
    from sb3_dtdpg.common.noise import noise_sigma

    return noise_sigma(model.action_noise)


def test_learn_and_predict_shapes(tmp_path):
    model = DTDPG("MlpPolicy", "Pendulum-v1", tensorboard_log=str(tmp_path), **TINY)
    model.learn(120)
    assert model.num_timesteps == 120
    assert os.path.isdir(tmp_path / "DTDPG_1")
    obs = model.env.observation_space.sample()
    action, state = model.predict(obs, deterministic=True)
    assert action.shape == (1,) and state is None
    actions, _ = model.predict(np.stack([obs] * 5), deterministic=True)
    assert actions.shape == (5, 1)
    assert np.all(np.abs(actions) <= 2.0)


def test_save_load(tmp_path):
    model = DTDPG("MlpPolicy", "Pendulum-v1", seed=1, **TINY)
    model.learn(450)  # two full episodes and a half
    path = tmp_path / "dtdpg.zip"
    model.save(path)
    loaded = DTDPG.load(path, env=make_vec_env("Pendulum-v1"))
    _assert_same_params(model, loaded)
    # the running statistics of the batch norm layers are part of it
    th.testing.assert_close(loaded.actor.mu[-2].running_var, model.actor.mu[-2].running_var, rtol=0, atol=0)
    assert not th.allclose(loaded.actor.mu[-2].running_var, th.ones(1))
    obs = np.random.default_rng(0).uniform(-1, 1, (10, 3)).astype(np.float32)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
    # curriculum state and noise schedule
    assert loaded.curriculum_state == model.curriculum_state
    assert isinstance(loaded.action_noise, LinearDecayOUNoise)
    assert loaded.action_noise.episode == model.action_noise.episode == 2
    np.testing.assert_array_equal(loaded.action_noise.current_sigma, model.action_noise.current_sigma)
    assert loaded.phases == model.phases
    assert loaded.learning_rate == 1e-3 and loaded.tau == 0.005  # the defaults survive the round trip
    # loaded model trains on
    loaded.learn(60, reset_num_timesteps=False)
    assert loaded.num_timesteps == 510


def test_a_replay_buffer_of_other_returns_is_refused(tmp_path):
    # A buffer computing 3-step returns with gamma 0.9 samples discounts 0.729, which the targets use: loaded into a
    # model of one-step returns with gamma 0.99 it trained on the buffer's returns without a word
    source = DTDPG("MlpPolicy", "Pendulum-v1", n_steps=3, gamma=0.9, **{**TINY, "learning_starts": 10})
    source.learn(30)
    source.save(tmp_path / "model.zip")
    source.save_replay_buffer(tmp_path / "buffer.pkl")
    for settings, named in (({"n_steps": 1, "gamma": 0.99}, "n_steps 3 (the model's: 1)"), ({"gamma": 0.99}, "gamma 0.9 ")):
        model = DTDPG.load(tmp_path / "model.zip", env=gym.make("Pendulum-v1"), **settings)
        own = model.replay_buffer
        with pytest.raises(ValueError, match=re.escape(named)):
            model.load_replay_buffer(tmp_path / "buffer.pkl")
        assert model.replay_buffer is own
    same = DTDPG.load(tmp_path / "model.zip", env=gym.make("Pendulum-v1"))
    same.load_replay_buffer(tmp_path / "buffer.pkl")
    assert same.replay_buffer.pos == 30


def test_save_load_replay_buffer(tmp_path):
    model = DTDPG("MlpPolicy", "Pendulum-v1", **TINY)
    model.learn(100)
    path = tmp_path / "buffer.pkl"
    model.save_replay_buffer(path)
    old = model.replay_buffer
    model.replay_buffer = None
    model.load_replay_buffer(path)
    new = model.replay_buffer
    assert new.pos == old.pos == 100
    for name in ("observations", "actions", "rewards", "next_observations", "dones", "timeouts"):
        np.testing.assert_array_equal(getattr(new, name), getattr(old, name))
    model.learn(20, reset_num_timesteps=False)
    assert model.replay_buffer.pos == 120


def test_set_env_and_continue():
    model = DTDPG("MlpPolicy", "Pendulum-v1", **TINY)
    model.learn(60)
    model.set_env(make_vec_env("Pendulum-v1", n_envs=1))
    model.learn(40, reset_num_timesteps=False)
    assert model.num_timesteps == 100
    with pytest.raises(ValueError):
        model.set_env(make_vec_env("MountainCarContinuous-v0"))


def test_seeded_runs_are_identical():
    runs = []
    for _ in range(2):
        model = DTDPG("MlpPolicy", "Pendulum-v1", seed=3, **TINY)
        model.learn(300)
        runs.append(model)
    _assert_same_params(*runs)
    other = DTDPG("MlpPolicy", "Pendulum-v1", seed=4, **TINY).learn(300)
    assert not th.equal(_params(other)["policy.actor.mu.0.weight"], _params(runs[0])["policy.actor.mu.0.weight"])


def test_two_envs_with_time_limit():
    env = make_vec_env(_pendulum, n_envs=2, env_kwargs=dict(max_episode_steps=25))
    model = DTDPG("MlpPolicy", env, **TINY)
    model.learn(220)  # 110 steps per env: 4 episodes each
    buffer = model.replay_buffer
    assert buffer.n_envs == 2 and buffer.pos == 110
    # every episode end is a truncation (Pendulum never terminates), stored as a timeout, not as a terminal state
    assert buffer.dones[:110].sum() == 8
    np.testing.assert_array_equal(buffer.timeouts[:110], buffer.dones[:110])
    # the noise has one OU state per env and one schedule advanced by the episodes of both envs
    noise = model.action_noise
    assert isinstance(noise, VectorizedActionNoise) and len(noise.noises) == 2
    assert noise.noises[0].episode == noise.noises[1].episode == 8
    assert not np.array_equal(noise.noises[0].noise_prev, noise.noises[1].noise_prev)
    assert model.curriculum_state["episodes_in_phase"] == 8


def test_curriculum_runs_and_continues_across_learn_calls(tmp_path):
    phases = [
        Phase("destination", n_episodes=3, sigma=0.5, final_sigma=0.1),
        Phase("mqi", sigma=0.4, final_sigma=0.2, decay_episodes=5),
    ]
    model = DTDPG("MlpPolicy", _phased(), phases=phases, curriculum_save_path=str(tmp_path), **TINY)
    model.learn(50)  # 2 episodes of 20 steps and a half: still in phase 0
    assert model.curriculum_state["phase_index"] == 0
    assert model.get_env().get_attr("reward_phase") == ["destination"]
    model.learn(40, reset_num_timesteps=False)  # the 3rd episode ends at step 60: transfer
    assert model.curriculum_state["phase_index"] == 1
    assert model.get_env().get_attr("reward_phase") == ["mqi"]
    assert os.path.isfile(tmp_path / "phase_0_destination.zip")
    # the new schedule counts the episode that ended at step 80, as the curriculum does
    assert model.action_noise.episode == model.curriculum_state["episodes_in_phase"] == 1
    np.testing.assert_array_equal(model.action_noise.current_sigma, np.full(3, 0.4 + (0.2 - 0.4) * 1 / 5))


def test_the_phase_folder_is_not_saved_with_the_model(tmp_path):
    # A copy of a run's zip must not write phase files into the original run's folder: the folder is given again.
    phases = [Phase("destination", n_episodes=1, sigma=0.5), Phase("mqi", sigma=0.4)]
    model = DTDPG("MlpPolicy", _phased(), phases=phases, curriculum_save_path=str(tmp_path / "original"), **TINY)
    model.save(tmp_path / "copy.zip")
    loaded = DTDPG.load(tmp_path / "copy.zip", env=_phased())
    assert loaded.curriculum_save_path is None
    loaded.learn(30)  # the transfer at step 20 saves nothing
    assert loaded.curriculum_state["phase_index"] == 1 and not (tmp_path / "original").exists()
    again = DTDPG.load(tmp_path / "copy.zip", env=_phased(), curriculum_save_path=str(tmp_path / "phases"))
    again.learn(30)
    assert os.path.isfile(tmp_path / "phases" / "phase_0_destination.zip")
    # A zip saved before the folder was left out of saving still carries it: loading drops it all the same.
    older = DTDPG("MlpPolicy", _phased(), phases=phases, curriculum_save_path=str(tmp_path / "original"), **TINY)
    older._excluded_save_params = lambda: [n for n in DTDPG._excluded_save_params(older) if n != "curriculum_save_path"]
    older.save(tmp_path / "older.zip")
    assert DTDPG.load(tmp_path / "older.zip", env=_phased()).curriculum_save_path is None


class _ModeRecorder(BaseCallback):
    def _on_step(self) -> bool:
        assert not self.model.policy.actor.training
        return True


def test_user_callbacks_are_combined():
    calls = []
    model = DTDPG("MlpPolicy", "Pendulum-v1", **TINY)
    model.learn(60, callback=[_ModeRecorder(), lambda _locals, _globals: calls.append(1) or True])
    assert len(calls) == 60
    assert model.curriculum_state["phase_index"] == 0


class _CurriculumPhasedEnv(PhasedPointEnv):
    """A phased env that offers its own curriculum (``default_curriculum``), 20-step episodes."""

    default_curriculum = (
        {"name": "destination", "n_episodes": 2, "sigma": 0.5, "final_sigma": 0.1},
        {"name": "mqi", "sigma": 0.4, "replay_handling": "relabel"},
    )

    def __init__(self, **kwargs):
        super().__init__(starts=[[0.05, 0.05]], destinations=[[0.95, 0.95]], **kwargs)


def test_the_default_curriculum_is_the_envs_own():
    model = DTDPG("MlpPolicy", TimeLimit(_CurriculumPhasedEnv(v_max=0.02), max_episode_steps=20), **TINY)
    assert [(p.name, p.reward_phase, p.replay_handling) for p in model.phases] == [
        ("destination", "destination", "keep"),
        ("mqi", "mqi", "relabel"),
    ]
    assert isinstance(model.replay_buffer, RewardComponentsReplayBuffer)
    model.learn(60)  # the transfer after 2 episodes of 20 steps
    assert model.curriculum_state["phase_index"] == 1
    assert model.env.get_attr("reward_phase") == ["mqi"]


def test_reinitialize_draws_new_networks_and_keeps_the_rest():
    model = DTDPG("MlpPolicy", _pendulum(), learning_starts=10, batch_size=16, policy_kwargs={"net_arch": [16]}, seed=0)
    model.learn(30)
    buffer, noise = model.replay_buffer, model.action_noise
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    model.reinitialize()
    assert model.replay_buffer is buffer and model.action_noise is noise and model.seed == 0
    assert model.actor is model.policy.actor and model.critic_target is model.policy.critic_target
    after = model.policy.state_dict()
    weights = [k for k in before if k.endswith("weight")]
    assert sum(not th.equal(before[k], after[k]) for k in weights) >= len(weights) // 2
    assert not model.policy.training  # SB3 collects rollouts in eval mode
