"""SB3's own test patterns for DDPG (test_cnn, test_dict_env, test_her, test_spaces, test_save_load), run on DTDPG."""

from copy import deepcopy
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from phased_env import PhasedPointEnv
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import BitFlippingEnv, FakeImageEnv
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.torch_layers import CombinedExtractor, FlattenExtractor, NatureCNN
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack, VecNormalize, VecTransposeImage, is_vecenv_wrapped
from torch import nn

from sb3_dtdpg import DTDPG, CnnPolicy, MlpPolicy, MultiInputPolicy
from sb3_dtdpg.dtdpg.policies import DTDPGPolicy, StateActionBatchNorm

IMAGE_SIZE = 36  # the smallest image NatureCNN accepts
TINY_CNN = dict(net_arch=[16], features_extractor_kwargs=dict(features_dim=16))
TINY_COMBINED = dict(net_arch=[16], features_extractor_kwargs=dict(cnn_output_dim=16))


class DictEnv(gym.Env):
    """SB3's ``DummyDictEnv`` (tests/test_dict_env.py): random image, vector and discrete observations, zero reward."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, channel_last: bool = False, vec_only: bool = False, discrete: bool = True):
        super().__init__()
        self.action_space = spaces.Box(-1, 1, shape=(2,), dtype=np.float32)
        image_shape = (IMAGE_SIZE, IMAGE_SIZE, 1) if channel_last else (1, IMAGE_SIZE, IMAGE_SIZE)
        obs: dict[str, spaces.Space] = {"vec": spaces.Box(-1, 1, shape=(2,), dtype=np.float32)}
        if not vec_only:
            obs["img"] = spaces.Box(0, 255, shape=image_shape, dtype=np.uint8)
            if discrete:
                obs["discrete"] = spaces.Discrete(4)
        self.observation_space = spaces.Dict(obs)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self.observation_space.seed(seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


class BoxEnv(gym.Env):
    """SB3's ``DummyEnv`` (tests/test_spaces.py): random observations of any space, zero reward."""

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Box):
        self.observation_space = observation_space
        self.action_space = action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


def _image_env(**kwargs) -> FakeImageEnv:
    return FakeImageEnv(screen_height=IMAGE_SIZE, screen_width=IMAGE_SIZE, n_channels=1, discrete=False, **kwargs)


def _assert_batch_norm_design(policy: DTDPGPolicy, features_dim: int, action_dim: int) -> None:
    """BN right before the actor's tanh; the critic's features and action each through their own BN."""
    for actor in (policy.actor, policy.actor_target):
        *_, norm, tanh = actor.mu
        assert isinstance(norm, nn.BatchNorm1d) and norm.num_features == action_dim
        assert isinstance(tanh, nn.Tanh)
    for critic in (policy.critic, policy.critic_target):
        for q_net in critic.q_networks:
            input_norm = q_net[0]
            assert isinstance(input_norm, StateActionBatchNorm)
            assert input_norm.state_norm.num_features == features_dim
            assert input_norm.action_norm.num_features == action_dim


def _randomize_(policy: nn.Module) -> dict[str, th.Tensor]:
    """Random values for every float tensor of the state dict (``num_batches_tracked`` counters are integers)."""
    params = {name: th.rand_like(value) if value.is_floating_point() else value for name, value in policy.state_dict().items()}
    policy.load_state_dict(params)
    return deepcopy(policy.state_dict())


def _assert_same_state(expected: dict[str, th.Tensor], actual: dict[str, th.Tensor]) -> None:
    assert expected.keys() == actual.keys()
    for name in expected:
        assert th.equal(expected[name], actual[name]), name


@pytest.mark.parametrize(
    ("alias", "policy_class", "extractor_class"),
    [
        ("MlpPolicy", MlpPolicy, FlattenExtractor),
        ("CnnPolicy", CnnPolicy, NatureCNN),
        ("MultiInputPolicy", MultiInputPolicy, CombinedExtractor),
    ],
)
def test_policy_aliases_are_the_batch_norm_policy_with_ddpg_extractors(alias, policy_class, extractor_class):
    env = {"MlpPolicy": lambda: gym.make("Pendulum-v1"), "CnnPolicy": _image_env, "MultiInputPolicy": DictEnv}[alias]()
    assert DTDPG.policy_aliases[alias] is policy_class
    assert issubclass(policy_class, DTDPGPolicy)
    model = DTDPG(alias, env, buffer_size=100, policy_kwargs=dict(net_arch=[8]), seed=0)
    assert type(model.policy) is policy_class
    for net in (model.actor, model.critic, model.actor_target, model.critic_target):
        assert type(net.features_extractor) is extractor_class
    action_dim = env.action_space.shape[0]
    _assert_batch_norm_design(model.policy, model.actor.features_dim, action_dim)
    assert model.critic.q_networks[0][1].in_features == model.actor.features_dim + action_dim


@pytest.mark.parametrize("alias", ["CnnPolicy", "MultiInputPolicy"])
@pytest.mark.parametrize(("actor_norm", "critic_norm"), [("layer", "none"), ("none", "layer")])
def test_normalisation_options_work_for_image_and_dict_policies(alias, actor_norm, critic_norm):
    env = _image_env() if alias == "CnnPolicy" else DictEnv()
    policy_kwargs = dict(TINY_CNN if alias == "CnnPolicy" else TINY_COMBINED, actor_norm=actor_norm, critic_norm=critic_norm)
    model = DTDPG(alias, env, buffer_size=100, learning_starts=20, train_freq=8, policy_kwargs=policy_kwargs, seed=0)
    actor_layers = {type(m) for m in model.actor.mu if isinstance(m, (nn.BatchNorm1d, nn.LayerNorm))}
    assert actor_layers == ({nn.LayerNorm} if actor_norm == "layer" else set())
    critic_layers = {type(m) for m in model.critic.q_networks[0] if isinstance(m, (StateActionBatchNorm, nn.LayerNorm))}
    assert critic_layers == ({nn.LayerNorm} if critic_norm == "layer" else set())
    model.learn(40)
    assert model.policy._get_constructor_parameters()["actor_norm"] == actor_norm


def test_mlp_policy_on_dict_observations_is_an_error():
    with pytest.raises(ValueError, match="MultiInputPolicy"):
        DTDPG("MlpPolicy", BitFlippingEnv(n_bits=4, continuous=True))


# ------------------------------------------------------------------ test_cnn.py


@pytest.mark.parametrize("share_features_extractor", [False, True])
def test_cnn(tmp_path, share_features_extractor):
    env = _image_env()  # channel last: DTDPG wraps it in VecTransposeImage
    policy_kwargs = dict(TINY_CNN, share_features_extractor=share_features_extractor)
    model = DTDPG("CnnPolicy", env, buffer_size=250, learning_starts=50, train_freq=8, policy_kwargs=policy_kwargs, seed=1)
    shared = model.critic.features_extractor is model.actor.features_extractor
    assert shared == share_features_extractor
    _assert_batch_norm_design(model.policy, features_dim=16, action_dim=env.action_space.shape[0])
    critic_before = deepcopy(model.critic.state_dict())
    model.learn(150)
    assert is_vecenv_wrapped(model.get_env(), VecTransposeImage)
    assert not th.equal(model.critic.q_networks[0][0].state_norm.running_mean, critic_before["qf0.0.state_norm.running_mean"])
    # The critic's CNN learns through the critic loss (the actor's when shared)
    assert not th.equal(model.critic.features_extractor.cnn[0].weight, critic_before["features_extractor.cnn.0.weight"])

    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)
    model.save(tmp_path / "cnn_model.zip")
    loaded = DTDPG.load(tmp_path / "cnn_model.zip")
    assert type(loaded.policy) is CnnPolicy
    np.testing.assert_array_equal(action, loaded.predict(obs, deterministic=True)[0])


def test_cnn_with_frame_stack_and_vec_normalize():
    """Four stacked frames of a channel-first image env, VecNormalize'd rewards (SB3 test_cnn, test_vec_normalize)."""
    env = VecNormalize(VecFrameStack(DummyVecEnv([lambda: _image_env(channel_first=True)]), 4), norm_obs=False)
    model = DTDPG("CnnPolicy", env, buffer_size=100, learning_starts=50, train_freq=8, policy_kwargs=TINY_CNN, seed=0)
    assert model.observation_space.shape == (4, IMAGE_SIZE, IMAGE_SIZE)
    assert model.actor.features_extractor.cnn[0].in_channels == 4
    model.learn(100)
    assert model.get_vec_normalize_env() is env
    mean_reward, _ = evaluate_policy(model, env, n_eval_episodes=2, warn=False)
    assert np.isfinite(mean_reward)


# ------------------------------------------------------------------ test_dict_env.py


def test_dict_consistency_with_flattened_observations():
    """A Dict with one vector key and MultiInputPolicy is the same network and training as MlpPolicy on the vector."""
    dict_env = gym.wrappers.TimeLimit(DictEnv(vec_only=True), 100)
    flat_env = gym.wrappers.FlattenObservation(dict_env)
    obs, _ = dict_env.reset(seed=0)
    kwargs: dict[str, Any] = dict(buffer_size=100, train_freq=8, learning_starts=50, gamma=0.5, n_steps=1, seed=1)
    dict_model = DTDPG("MultiInputPolicy", dict_env, policy_kwargs=dict(net_arch=[8, 8]), **kwargs)
    before = dict_model.predict(obs, deterministic=True)[0]
    dict_model.learn(128)
    flat_model = DTDPG("MlpPolicy", flat_env, policy_kwargs=dict(net_arch=[8, 8]), **kwargs)
    np.testing.assert_allclose(before, flat_model.predict(obs["vec"], deterministic=True)[0])
    flat_model.learn(128)
    after = dict_model.predict(obs, deterministic=True)[0]
    assert not np.allclose(before, after)  # trained
    np.testing.assert_allclose(after, flat_model.predict(obs["vec"], deterministic=True)[0], rtol=1e-5)


@pytest.mark.parametrize("channel_last", [False, True])
def test_dict_spaces(channel_last):
    env = gym.wrappers.TimeLimit(DictEnv(channel_last=channel_last), 100)
    model = DTDPG(
        "MultiInputPolicy", env, buffer_size=250, train_freq=8, learning_starts=50, policy_kwargs=TINY_COMBINED, seed=1
    )
    features_dim = model.actor.features_extractor.features_dim
    assert features_dim == 16 + 2 + 4  # CNN output, vector, one-hot discrete
    _assert_batch_norm_design(model.policy, features_dim=features_dim, action_dim=2)
    model.learn(128)
    assert isinstance(model.replay_buffer, DictReplayBuffer)
    evaluate_policy(model, env, n_eval_episodes=2, warn=False)


def test_dict_vec_frame_stack_and_vec_normalize():
    venv = DummyVecEnv([lambda: gym.wrappers.TimeLimit(DictEnv(discrete=False), 50)])  # VecFrameStack stacks Boxes
    venv = VecNormalize(VecFrameStack(venv, n_stack=3, channels_order={"vec": None, "img": "first"}), norm_obs_keys=["vec"])
    model = DTDPG(
        "MultiInputPolicy", venv, buffer_size=64, train_freq=8, learning_starts=50, policy_kwargs=TINY_COMBINED, seed=1
    )
    assert model.observation_space["img"].shape == (3, IMAGE_SIZE, IMAGE_SIZE)
    model.learn(128)
    # The buffer holds the original (unnormalised) vectors, stacked three deep
    stored = model.replay_buffer.observations["vec"][: model.replay_buffer.size()]
    assert stored.shape[-1] == 6 and np.abs(stored).max() <= 1.0
    assert venv.obs_rms["vec"].count > 100
    evaluate_policy(model, venv, n_eval_episodes=2, warn=False)


def test_vec_normalize_keeps_the_curriculum_of_a_phased_env():
    """VecNormalize forwards the env's curriculum, set_reward_phase and reward_weights: the curriculum switches the reward."""

    class CurriculumEnv(PhasedPointEnv):
        default_curriculum = ({"name": "destination", "n_episodes": 3}, {"name": "mqi", "replay_handling": "relabel"})

    venv = VecNormalize(DummyVecEnv([lambda: CurriculumEnv(max_steps=10)]))
    model = DTDPG("MlpPolicy", venv, learning_starts=20, policy_kwargs=dict(net_arch=[8]), seed=0)
    assert [phase.reward_phase for phase in model.phases] == ["destination", "mqi"]
    model.learn(60)
    assert model.curriculum_state["phase_index"] == 1
    assert venv.get_attr("reward_phase") == ["mqi"]


# ------------------------------------------------------------------ test_her.py


def _her_model(env, **kwargs) -> DTDPG:
    kwargs = (
        dict(
            replay_buffer_class=HerReplayBuffer,
            replay_buffer_kwargs=dict(n_sampled_goal=2, goal_selection_strategy="future"),
            train_freq=4,
            learning_starts=100,
            buffer_size=2_000,
            policy_kwargs=dict(net_arch=[64]),
        )
        | kwargs
    )
    return DTDPG("MultiInputPolicy", env, **kwargs)


@pytest.mark.parametrize("image_obs_space", [False, True])
def test_her(image_obs_space):
    def env_fn():
        return BitFlippingEnv(n_bits=4, continuous=True, image_obs_space=image_obs_space)

    model = _her_model(make_vec_env(env_fn, 1), replay_buffer_kwargs=dict(n_sampled_goal=2, copy_info_dict=True), seed=0)
    # A goal env has no reward phases: one phase, HER's buffer (not the reward-components relabelling buffer)
    assert [phase.reward_phase for phase in model.phases] == [None]
    model.learn(150)
    assert type(model.replay_buffer) is HerReplayBuffer
    assert model.curriculum_state["phase_index"] == 0
    _assert_batch_norm_design(model.policy, model.actor.features_dim, action_dim=4)
    evaluate_policy(model, Monitor(env_fn()), n_eval_episodes=2, warn=False)


def test_her_save_load(tmp_path):
    n_envs = 2
    env = make_vec_env(lambda: BitFlippingEnv(n_bits=4, continuous=True), n_envs)
    model = _her_model(env, tau=0.05, learning_rate=1e-3, gradient_steps=n_envs, seed=0)
    model.learn(150)
    env.reset()
    observations = env.step(np.array([env.action_space.sample() for _ in range(n_envs)]))[0]
    params = _randomize_(model.policy)
    actions, _ = model.predict(observations, deterministic=True)
    model.save(tmp_path / "her.zip")

    loaded = DTDPG.load(tmp_path / "her.zip", env=env, custom_objects=dict(learning_rate=2e-5))
    assert loaded.learning_rate == 2e-5
    assert type(loaded.policy) is MultiInputPolicy
    _assert_same_state(params, loaded.policy.state_dict())
    np.testing.assert_allclose(actions, loaded.predict(observations, deterministic=True)[0], rtol=1e-6)
    assert loaded.curriculum_state == model.curriculum_state
    loaded.learn(150)
    assert type(loaded.replay_buffer) is HerReplayBuffer and loaded.replay_buffer.size() > 0


@pytest.mark.slow
def test_her_solves_bit_flipping():
    """HER with the batch-norm policy learns the 4-bit goal env (1500 steps: 100% success with seeds 0 and 1)."""
    env = make_vec_env(lambda: BitFlippingEnv(n_bits=4, continuous=True), 1)
    model = _her_model(
        env,
        replay_buffer_kwargs=dict(n_sampled_goal=4, goal_selection_strategy="future"),
        learning_rate=1e-3,
        tau=0.05,
        gamma=0.95,
        batch_size=128,
        train_freq=1,
        buffer_size=100_000,
        policy_kwargs=dict(net_arch=[64, 64]),
        seed=0,
    )
    model.learn(1500)
    eval_env = BitFlippingEnv(n_bits=4, continuous=True)
    successes = []
    for episode in range(20):
        obs, _ = eval_env.reset(seed=1000 + episode)
        terminated = truncated = False
        while not (terminated or truncated):
            obs, _, terminated, truncated, info = eval_env.step(model.predict(obs, deterministic=True)[0])
        successes.append(info["is_success"])
    assert np.mean(successes) >= 0.9


# ------------------------------------------------------------------ test_spaces.py

BOX_FLOAT32 = spaces.Box(-1, 1, shape=(2,), dtype=np.float32)
BOX_FLOAT64 = spaces.Box(-1, 1, shape=(2,), dtype=np.float64)


@pytest.mark.parametrize(
    "obs_space",
    [
        BOX_FLOAT32,
        BOX_FLOAT64,
        spaces.Dict({"a": BOX_FLOAT32, "b": BOX_FLOAT32}),
        spaces.Dict({"a": BOX_FLOAT32, "b": BOX_FLOAT64}),
    ],
)
@pytest.mark.parametrize(
    "action_space",
    [BOX_FLOAT32, spaces.Box(-2, 3, shape=(2,), dtype=np.float64), spaces.Box(-1, 1, shape=(2, 2), dtype=np.float64)],
)
def test_float64_and_multidimensional_action_spaces(obs_space, action_space):
    env = gym.wrappers.TimeLimit(BoxEnv(obs_space, action_space), max_episode_steps=200)
    policy = "MultiInputPolicy" if isinstance(obs_space, spaces.Dict) else "MlpPolicy"
    model = DTDPG(policy, env, learning_starts=30, policy_kwargs=dict(net_arch=[12]), seed=0)
    _assert_batch_norm_design(model.policy, model.actor.features_dim, action_dim=int(np.prod(action_space.shape)))
    model.learn(64)
    obs, _ = env.reset(seed=0)
    for deterministic in (False, True):
        action, _ = model.predict(obs, deterministic=deterministic)
        assert action.dtype == action_space.dtype and action.shape == action_space.shape
        assert action_space.contains(action)


# ------------------------------------------------------------------ test_save_load.py


@pytest.mark.parametrize("policy_str", ["MlpPolicy", "CnnPolicy", "MultiInputPolicy"])
def test_save_load_policy(tmp_path, policy_str):
    """The policy and its actor alone saved and loaded (``policy.save`` / ``Policy.load``) predict the same."""
    env_fn = {
        "MlpPolicy": lambda: gym.make("Pendulum-v1"),
        "CnnPolicy": lambda: _image_env(channel_first=True),
        "MultiInputPolicy": DictEnv,
    }[policy_str]
    policy_kwargs = {"MlpPolicy": dict(net_arch=[16]), "CnnPolicy": TINY_CNN, "MultiInputPolicy": TINY_COMBINED}[policy_str]
    env = DummyVecEnv([env_fn])
    model = DTDPG(policy_str, env, buffer_size=250, learning_starts=50, train_freq=4, policy_kwargs=policy_kwargs, seed=0)
    model.learn(100)
    env.reset()
    observations = [env.step(np.array([env.action_space.sample()]))[0] for _ in range(4)]
    if isinstance(observations[0], dict):
        observations = {key: np.concatenate([obs[key] for obs in observations]) for key in observations[0]}
    else:
        observations = np.concatenate(observations)

    policy, actor = model.policy, model.policy.actor
    params = _randomize_(policy)
    actions, _ = policy.predict(observations, deterministic=True)
    actor_actions, _ = actor.predict(observations, deterministic=True)
    np.testing.assert_allclose(actions, actor_actions)
    policy.save(tmp_path / "policy.pkl")
    actor.save(tmp_path / "actor.pkl")

    loaded_policy = type(policy).load(tmp_path / "policy.pkl")
    loaded_actor = type(actor).load(tmp_path / "actor.pkl")
    _assert_same_state(params, loaded_policy.state_dict())
    assert (loaded_policy.batch_norm_momentum, loaded_policy.actor_norm) == (policy.batch_norm_momentum, policy.actor_norm)
    np.testing.assert_allclose(actions, loaded_policy.predict(observations, deterministic=True)[0], rtol=1e-6)
    np.testing.assert_allclose(actor_actions, loaded_actor.predict(observations, deterministic=True)[0], rtol=1e-6)
