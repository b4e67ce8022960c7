"""The lean training step and acting path of DTDPG against SB3's generic ones (``lean=False``): bit-identical."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit
from phased_env import PhasedPointEnv
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import FakeImageEnv
from stable_baselines3.common.noise import NormalActionNoise
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.utils import polyak_update

from sb3_dtdpg import DTDPG, Phase
from sb3_dtdpg.dtdpg.lean import CACHE_ATTRIBUTE, LeanDDPG, LeanTD3, policy_action


class DictObservation(gym.ObservationWrapper):
    """The point env's observation split into a ``Dict`` of two vectors."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        box = env.observation_space
        self.split = box.shape[0] // 2
        self.observation_space = spaces.Dict(
            {
                "position": spaces.Box(box.low[: self.split], box.high[: self.split], dtype=box.dtype),
                "rest": spaces.Box(box.low[self.split :], box.high[self.split :], dtype=box.dtype),
            }
        )

    def observation(self, observation: np.ndarray) -> dict[str, np.ndarray]:
        return {"position": observation[: self.split], "rest": observation[self.split :]}


def _point_env() -> gym.Env:
    return TimeLimit(PhasedPointEnv(n_robots=2, v_max=0.05), max_episode_steps=15)


def _dict_env() -> gym.Env:
    return DictObservation(_point_env())


PHASES = [
    Phase("destination", n_timesteps=150, sigma=0.5, final_sigma=0.1, decay_episodes=10),
    Phase("mqi", sigma=0.4, final_sigma=0.05, decay_episodes=10, replay_handling="relabel"),
]
ONE_PHASE = [Phase("destination", sigma=0.5, final_sigma=0.1, decay_episodes=10)]

CASES = {
    # Vector observations, 3-step returns, the relabelling n-step buffer (transfer at step 150), 2 gradient steps
    "mlp_nstep_relabel": dict(make_env=_point_env, n_envs=1, policy="MlpPolicy", n_steps=3, gradient_steps=2, phases=PHASES),
    # Two envs in a vector env, one gradient step per env step, a learning-rate schedule
    "mlp_vec_env": dict(
        make_env=_point_env, n_envs=2, policy="MlpPolicy", n_steps=3, gradient_steps=-1, phases=ONE_PHASE, schedule=True
    ),
    # Networks re-created at the transfer (new optimizers: the caches are rebuilt)
    "mlp_reinitialize": dict(
        make_env=_point_env, n_envs=1, policy="MlpPolicy", n_steps=3, gradient_steps=1, phases=PHASES, reinitialize=True
    ),
    # Dict observations (SB3's Dict buffer, one-step returns), 3 gradient steps
    "multi_input": dict(
        make_env=_dict_env, n_envs=1, policy="MultiInputPolicy", n_steps=1, gradient_steps=3, phases=ONE_PHASE
    ),
}


def _linear_schedule(progress_remaining: float) -> float:
    return 3e-3 * progress_remaining


def _train(case: dict, lean: bool, tmp_path: Path) -> DTDPG:
    """Train, save (model and replay buffer), load, train on: the same calls for both paths."""
    env = make_vec_env(case["make_env"], n_envs=case["n_envs"], seed=0)
    model = DTDPG(
        case["policy"],
        env,
        learning_rate=_linear_schedule if case.get("schedule") else 3e-3,
        learning_starts=40,
        batch_size=16,
        buffer_size=1000,
        reinitialize_at_transfer=case.get("reinitialize", False),
        n_steps=case["n_steps"],
        gradient_steps=case["gradient_steps"],
        phases=case["phases"],
        policy_kwargs=dict(net_arch=[32, 32]),
        seed=0,
        device="cpu",
        lean=lean,
    )
    model.learn(120)
    path = tmp_path / f"model_{lean}"
    model.save(path)
    model.save_replay_buffer(tmp_path / f"buffer_{lean}")
    loaded = DTDPG.load(path, env=make_vec_env(case["make_env"], n_envs=case["n_envs"], seed=1), device="cpu")
    loaded.load_replay_buffer(tmp_path / f"buffer_{lean}")
    loaded.set_random_seed(1)
    loaded.learn(100, reset_num_timesteps=False)
    return loaded


def _assert_same_tensors(a: dict, b: dict, what: str) -> None:
    assert a.keys() == b.keys(), what
    for key in a:
        if isinstance(a[key], dict):
            _assert_same_tensors(a[key], b[key], f"{what}.{key}")
        elif isinstance(a[key], th.Tensor):
            assert a[key].dtype == b[key].dtype and th.equal(a[key], b[key]), f"{what}.{key} differs"
        else:
            assert a[key] == b[key], f"{what}.{key} differs"


def _assert_same_training(model, reference) -> None:
    """The same parameters, batch-norm statistics (and counters) and optimizer states, bit for bit."""
    _assert_same_tensors(model.policy.state_dict(), reference.policy.state_dict(), "policy")
    _assert_same_tensors(model.actor.optimizer.state_dict(), reference.actor.optimizer.state_dict(), "actor.optimizer")
    _assert_same_tensors(model.critic.optimizer.state_dict(), reference.critic.optimizer.state_dict(), "critic.optimizer")


@pytest.mark.parametrize("name", list(CASES))
def test_lean_step_is_bit_identical_to_sb3_train(name: str, tmp_path: Path) -> None:
    case = CASES[name]
    th.manual_seed(123)  # the same global state before each run
    reference = _train(case, lean=False, tmp_path=tmp_path)
    th.manual_seed(123)
    lean = _train(case, lean=True, tmp_path=tmp_path)

    assert lean.lean and not reference.lean
    # The lean model went through its own step, with the fused Adam kernel on the optimizers' state
    trainer = getattr(lean, CACHE_ATTRIBUTE)
    assert trainer.critic_adam._tensors is not None and trainer.actor_adam._tensors is not None
    assert getattr(reference, CACHE_ATTRIBUTE, None) is None
    # MLP networks on vector observations train with the backward passes written out; Dict observations with autograd
    assert (trainer.networks is not None) == (case["policy"] == "MlpPolicy")

    assert lean._n_updates == reference._n_updates > 50
    assert lean.num_timesteps == reference.num_timesteps == 220
    # Parameters of the four networks, batch-norm running statistics (and counters) included
    _assert_same_training(lean, reference)
    buffer, reference_buffer = lean.replay_buffer, reference.replay_buffer
    assert np.array_equal(buffer.actions, reference_buffer.actions)
    assert np.array_equal(buffer.rewards, reference_buffer.rewards)
    # The networks did learn: the online actor moved away from its initial (target-like) weights
    initial = DTDPG(case["policy"], case["make_env"](), policy_kwargs=dict(net_arch=[32, 32]), seed=0, phases=ONE_PHASE)
    moved = [
        not th.equal(p, q)
        for p, q in zip(lean.actor.parameters(), initial.actor.parameters(), strict=True)
        if p.shape == q.shape
    ]
    assert any(moved)


def _small_model(**kwargs) -> DTDPG:
    return DTDPG("MlpPolicy", _point_env(), policy_kwargs=dict(net_arch=[16]), phases=ONE_PHASE, **kwargs)


def test_lean_step_logs_the_same_losses() -> None:
    models = []
    for lean in (False, True):
        th.manual_seed(0)
        model = _small_model(learning_starts=30, batch_size=16, seed=3, lean=lean)
        model.learn(60)
        model.train(gradient_steps=3, batch_size=16)
        models.append(model)
    keys = ("train/actor_loss", "train/critic_loss", "train/n_updates")
    values = [{key: model.logger.name_to_value[key] for key in keys} for model in models]
    assert values[0] == values[1]
    assert values[1]["train/n_updates"] == models[1]._n_updates


def test_lean_acting_matches_predict() -> None:
    env = make_vec_env(_dict_env, n_envs=3, seed=0)
    model = DTDPG(
        "MultiInputPolicy", env, learning_starts=30, batch_size=8, policy_kwargs=dict(net_arch=[16]), seed=0, phases=ONE_PHASE
    )
    model.learn(60)  # trained: the actor's batch-norm statistics are no longer their initial values
    assert not th.equal(model.actor.mu[-2].running_var, th.ones_like(model.actor.mu[-2].running_var))
    model.policy.set_training_mode(False)
    obs = model.env.reset()
    expected, _ = model.predict(obs, deterministic=False)
    actions = policy_action(model, obs)
    assert actions.shape == (3, *model.action_space.shape)
    assert np.array_equal(actions, expected)


def test_lean_caches_are_not_saved(tmp_path: Path) -> None:
    model = _small_model(learning_starts=20, batch_size=8, seed=0)
    model.learn(40)
    assert getattr(model, CACHE_ATTRIBUTE, None) is not None
    model.save(tmp_path / "model")
    data, _, _ = load_from_zip_file(tmp_path / "model")
    assert data is not None and CACHE_ATTRIBUTE not in data and data["lean"] is True
    loaded = DTDPG.load(tmp_path / "model", env=_point_env())
    assert getattr(loaded, CACHE_ATTRIBUTE, None) is None
    loaded.learn(10, reset_num_timesteps=False)  # builds its caches for the loaded networks
    assert getattr(loaded, CACHE_ATTRIBUTE).valid_for(loaded)


@pytest.mark.parametrize(("lean_class", "sb3_class"), [(LeanDDPG, DDPG), (LeanTD3, TD3)])
def test_sb3_loads_a_lean_baselines_n_step_model_without_a_warning(tmp_path: Path, lean_class, sb3_class) -> None:
    """SB3 picks ``NStepReplayBuffer`` for ``n_steps > 1`` and saves it; its own ``load`` then warns that n_steps is
    ignored (DLR-RM/stable-baselines3#2275). The lean baselines leave SB3's own choice out of the zip: SB3 chooses
    it again on load, silently, with the same returns; a buffer class given by hand is saved."""
    import warnings

    from stable_baselines3.common.buffers import NStepReplayBuffer, ReplayBuffer

    env = TimeLimit(PhasedPointEnv(), 20)
    lean_class("MlpPolicy", env, n_steps=3, gamma=0.9, learning_starts=10, seed=0).save(tmp_path / "auto")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = sb3_class.load(tmp_path / "auto", env=env)
    assert type(loaded.replay_buffer) is NStepReplayBuffer
    assert (loaded.replay_buffer.n_steps, loaded.replay_buffer.gamma) == (3, 0.9)
    lean_class("MlpPolicy", env, replay_buffer_class=ReplayBuffer, seed=0).save(tmp_path / "given")
    assert sb3_class.load(tmp_path / "given", env=env).replay_buffer_class is ReplayBuffer


def test_polyak_on_flat_buffers_follows_the_parameters() -> None:
    """The targets' Polyak update runs on flat buffers holding the parameters; a parameter given new memory
    (``.data``, as ``vector_to_parameters`` does) is gathered again, so the targets still follow the online
    networks as SB3's ``polyak_update`` has them."""
    model = _small_model(learning_starts=10, batch_size=8, seed=0)
    model.learn(20)
    trainer = getattr(model, CACHE_ATTRIBUTE)
    flat = trainer._flat
    assert flat is not None
    # One buffer per network: a network's state_dict holds its own parameters only
    for network in (model.critic, model.actor, model.critic_target, model.actor_target):
        params = list(network.parameters())
        assert len({p.untyped_storage().data_ptr() for p in params}) == 1
        assert params[0].untyped_storage().nbytes() < 4 * sum(p.numel() for p in params) + 64 * len(params)
    online_buffer = next(model.critic.parameters()).untyped_storage().data_ptr()
    # The batch-norm statistics stay in their modules' buffers (SB3's lists hold aliases of them)
    assert all(p.untyped_storage().data_ptr() != online_buffer for p in model.critic.buffers())

    first = next(model.critic.parameters())
    first.data = first.data.clone() + 1.0
    expected = [t.clone() for t in model.critic_target.parameters()]
    polyak_update(list(model.critic.parameters()), expected, model.tau)
    trainer.polyak(model.tau)
    assert trainer._flat is not flat and trainer._flat.current()
    for target, reference in zip(model.critic_target.parameters(), expected, strict=True):
        assert th.equal(target, reference)
    # The critic's batch-norm statistics were copied to its target, in the modules
    for online, target in zip(model.critic.buffers(), model.critic_target.buffers(), strict=True):
        if online.is_floating_point():
            assert th.equal(online, target)


@pytest.mark.filterwarnings("ignore:`n_steps=3` is ignored")  # SB3's load() of its own n-step DDPG
@pytest.mark.parametrize(
    ("lean_class", "sb3_class", "kwargs", "optimizer_kwargs"),
    [
        # DDPG with SB3's default Adam, 3-step returns and 2 gradient steps; TD3 with the fused Adam kernel, its
        # target noise, two critics and delayed policy updates
        (LeanDDPG, DDPG, dict(n_steps=3, gradient_steps=2), None),
        (LeanTD3, TD3, dict(policy_delay=2), dict(fused=True)),
    ],
)
def test_lean_ddpg_and_td3_are_bit_identical_to_sb3(
    lean_class: type, sb3_class: type, kwargs: dict, optimizer_kwargs: dict | None, tmp_path: Path
) -> None:
    policy_kwargs = dict(net_arch=[32, 32], optimizer_kwargs=optimizer_kwargs)
    models = []
    for cls in (sb3_class, lean_class):
        env = make_vec_env(_point_env, n_envs=1, seed=0)
        n_actions = env.action_space.shape[0]
        noise = NormalActionNoise(np.zeros(n_actions), 0.3 * np.ones(n_actions))
        model = cls(
            "MlpPolicy",
            env,
            learning_starts=40,
            batch_size=16,
            action_noise=noise,
            policy_kwargs=policy_kwargs,
            seed=0,
            **kwargs,
        )
        model.learn(120)
        model.save(tmp_path / cls.__name__)
        model.save_replay_buffer(tmp_path / f"{cls.__name__}_buffer")
        loaded = cls.load(tmp_path / cls.__name__, env=make_vec_env(_point_env, n_envs=1, seed=1))
        loaded.load_replay_buffer(tmp_path / f"{cls.__name__}_buffer")
        loaded.set_random_seed(1)
        loaded.learn(100, reset_num_timesteps=False)
        models.append(loaded)
    reference, lean = models
    assert getattr(lean, CACHE_ATTRIBUTE).valid_for(lean) and getattr(reference, CACHE_ATTRIBUTE, None) is None
    # SB3's plain MLPs: DDPG's one critic is written out, TD3's two critics train with autograd
    assert (getattr(lean, CACHE_ATTRIBUTE).networks is not None) == (sb3_class is DDPG)
    assert lean._n_updates == reference._n_updates > 100
    _assert_same_training(lean, reference)


@pytest.mark.parametrize("share_features_extractor", [False, True])
def test_lean_step_with_a_cnn_is_bit_identical(share_features_extractor: bool) -> None:
    # Images act through predict(); a features extractor shared with the actor gets no critic gradient
    policy_kwargs = dict(
        net_arch=[16], features_extractor_kwargs=dict(features_dim=16), share_features_extractor=share_features_extractor
    )
    models = []
    for lean in (False, True):
        env = FakeImageEnv(screen_height=36, screen_width=36, n_channels=1, discrete=False)
        env.observation_space.seed(0)  # its observations are samples of its space
        model = DTDPG(
            "CnnPolicy",
            env,
            buffer_size=200,
            learning_starts=40,
            batch_size=8,
            train_freq=4,
            gradient_steps=2,
            policy_kwargs=policy_kwargs,
            seed=2,
            lean=lean,
        )
        model.learn(80)
        models.append(model)
    reference, lean_model = models
    assert lean_model._n_updates == reference._n_updates > 0
    _assert_same_training(lean_model, reference)


@pytest.mark.parametrize(
    ("policy_kwargs", "written_out"),
    [
        # DT-DPG's networks at the benchmark's size (the matrix kernels of a larger batch), three hidden layers
        (dict(net_arch=[128, 128, 64]), True),
        # Without batch norms (TD3's plain actor, SB3's plain critic)
        (dict(net_arch=[64, 64], actor_norm="none", critic_norm="none"), True),
        # Not covered: layer norm, another activation (autograd)
        (dict(net_arch=[64, 64], actor_norm="layer"), False),
        (dict(net_arch=[64, 64], activation_fn=th.nn.Tanh), False),
    ],
)
def test_written_out_backward_is_bit_identical_to_autograd(policy_kwargs: dict, written_out: bool) -> None:
    models = []
    for backprop in (False, True):
        th.manual_seed(7)
        model = DTDPG(
            "MlpPolicy",
            make_vec_env(_point_env, n_envs=2, seed=0),
            learning_starts=150,
            batch_size=128,
            n_steps=3,
            gradient_steps=2,
            policy_kwargs=policy_kwargs,
            seed=4,
            phases=PHASES,
            backprop=backprop,
        )
        model.learn(300)
        models.append(model)
    autograd, backprop_model = models
    assert (getattr(backprop_model, CACHE_ATTRIBUTE).networks is not None) == written_out
    assert backprop_model._n_updates == autograd._n_updates == 150
    _assert_same_training(backprop_model, autograd)
    assert backprop_model.logger.name_to_value["train/critic_loss"] == autograd.logger.name_to_value["train/critic_loss"]


def test_module_hooks_run_the_networks_as_modules() -> None:
    # A hook registered on any layer is called: the step runs the modules under autograd while one is registered
    model = _small_model(learning_starts=20, batch_size=8, seed=0)
    model.learn(30)
    networks = getattr(model, CACHE_ATTRIBUTE).networks
    assert networks is not None and not networks.hooked()
    batches: list[int] = []
    handle = model.critic.q_networks[0][1].register_forward_hook(lambda module, inputs, output: batches.append(len(output)))
    assert networks.hooked()
    model.learn(5, reset_num_timesteps=False)
    assert batches and set(batches) == {8}  # the critic loss and the actor loss, on training batches
    handle.remove()
    assert not networks.hooked()
    model.learn(5, reset_num_timesteps=False)
    assert len(batches) == 5 * 2


@pytest.mark.parametrize("training", [True, False])
def test_written_out_critic_input_norm_is_the_modules_bit_for_bit(training: bool) -> None:
    """The critic's input batch norm, written out on the whole input, against :class:`StateActionBatchNorm`: the same
    output bits and running statistics, also for the inputs where float signs matter (``-0.0`` on a zero mean, an
    input equal to the mean)."""
    from sb3_dtdpg.dtdpg.backprop import MlpCritic

    model = _small_model(learning_starts=10, batch_size=8, seed=0)
    module = model.critic.q_networks[0][0]
    written_out = MlpCritic(model.critic)
    generator = th.Generator().manual_seed(0)
    for case in range(20):
        state_action = th.randn(32, module.features_dim + module.action_dim, generator=generator) * (case + 1)
        for norm in (module.state_norm, module.action_norm):
            norm.running_mean.copy_(th.randn(norm.num_features, generator=generator))
            norm.running_var.copy_(th.rand(norm.num_features, generator=generator) ** 3)
        if case % 2 == 0:
            for norm in (module.state_norm, module.action_norm):
                norm.running_mean.zero_()
            state_action[0] = -0.0
        state_action[1] = th.cat([module.state_norm.running_mean, module.action_norm.running_mean])
        statistics = [t.clone() for t in module.buffers()]
        module.train(training)
        with th.no_grad():
            expected = module(state_action)
        expected_statistics = [t.clone() for t in module.buffers()]
        for buffer, value in zip(module.buffers(), statistics, strict=True):
            buffer.copy_(value)
        output = written_out._normalize(state_action, None)
        assert th.equal(output.view(th.int32), expected.view(th.int32)), case
        for buffer, value in zip(module.buffers(), expected_statistics, strict=True):
            assert th.equal(buffer, value), case


def test_adam_step_counts_are_views_of_one_tensor(tmp_path: Path) -> None:
    """The fused Adam step counts each optimizer's steps in one tensor whose views are the optimizer's ``step``
    entries: they count every update, also after the model is saved, loaded and trained on."""
    model = _small_model(learning_starts=10, batch_size=8, seed=0)
    model.learn(30)

    def step_counts(model) -> list[th.Tensor]:
        return [state["step"] for state in model.critic.optimizer.state.values()]

    counts = step_counts(model)
    assert len({c.untyped_storage().data_ptr() for c in counts}) == 1
    assert all(c.item() == model._n_updates > 0 for c in counts)
    model.save(tmp_path / "model")
    loaded = DTDPG.load(tmp_path / "model", env=_point_env())
    assert all(c.item() == model._n_updates for c in step_counts(loaded))
    loaded.learn(10, reset_num_timesteps=False)
    counts = step_counts(loaded)
    assert len({c.untyped_storage().data_ptr() for c in counts}) == 1
    assert all(c.item() == loaded._n_updates == model._n_updates + 10 for c in counts)


def test_batch_norm_statistics_are_copied_on_flat_buffers() -> None:
    """The copy of the batch-norm statistics to the targets runs on one flat buffer per network, which the modules'
    buffers and SB3's aliases of them both view: the targets' modules get the online statistics; a statistic given
    new memory leaves the copy to SB3's aliases, as SB3's ``polyak_update`` does it."""
    model = _small_model(learning_starts=10, batch_size=8, seed=0)
    model.learn(20)
    trainer = getattr(model, CACHE_ATTRIBUTE)
    assert trainer._flat_statistics is not None
    networks = {
        "critic": (model.critic, model.critic_batch_norm_stats),
        "critic_target": (model.critic_target, model.critic_batch_norm_stats_target),
        "actor": (model.actor, model.actor_batch_norm_stats),
        "actor_target": (model.actor_target, model.actor_batch_norm_stats_target),
    }
    statistics = {
        name: [buffer for key, buffer in network.named_buffers() if "running_" in key]
        for name, (network, _) in networks.items()
    }
    for name, (_, aliases) in networks.items():
        assert len({s.untyped_storage().data_ptr() for s in statistics[name]}) == 1, name
        assert [a.data_ptr() for a in aliases] == [s.data_ptr() for s in statistics[name]], name

    for statistic in model.critic_batch_norm_stats + model.actor_batch_norm_stats:
        statistic.add_(1.0)
    trainer.polyak(model.tau)
    for online, target in (("critic", "critic_target"), ("actor", "actor_target")):
        assert all(th.equal(a, b) for a, b in zip(statistics[online], statistics[target], strict=True))

    norm = model.critic.q_networks[0][0].state_norm
    norm.running_mean.data = norm.running_mean.data.clone() + 1.0  # the module's buffer only: SB3's alias stays behind
    expected = [t.clone() for t in model.critic_batch_norm_stats_target + model.actor_batch_norm_stats_target]
    polyak_update(model.critic_batch_norm_stats + model.actor_batch_norm_stats, expected, 1.0)
    trainer.polyak(model.tau)
    assert trainer._flat_statistics is None
    for target, reference in zip(
        model.critic_batch_norm_stats_target + model.actor_batch_norm_stats_target, expected, strict=True
    ):
        assert th.equal(target, reference)
