import gymnasium as gym
import numpy as np
import pytest
import torch as th
from torch import nn

from sb3_dtdpg import DTDPG
from sb3_dtdpg.dtdpg.policies import DTDPGPolicy, StateActionBatchNorm


def _running_stats(module: nn.Module) -> dict[str, th.Tensor]:
    return {name: buf.clone() for name, buf in module.named_buffers() if "running_" in name}


def _model(**kwargs) -> DTDPG:
    kwargs = dict(policy_kwargs=dict(net_arch=[32]), seed=0) | kwargs
    return DTDPG("MlpPolicy", "Pendulum-v1", **kwargs)


def test_actor_ends_with_batch_norm_then_tanh():
    model = _model(policy_kwargs=dict(net_arch=[32, 16], batch_norm_momentum=0.2, batch_norm_eps=1e-4))
    for actor in (model.actor, model.actor_target):
        layers = list(actor.mu)
        assert [type(layer) for layer in layers] == [
            nn.Linear,
            nn.ReLU,
            nn.Linear,
            nn.ReLU,
            nn.Linear,
            nn.BatchNorm1d,
            nn.Tanh,
        ]
        assert layers[-2].num_features == 1
        assert layers[-2].momentum == 0.2 and layers[-2].eps == 1e-4


def test_actor_batch_norm_keeps_tanh_input_in_range():
    """Remark 1: whatever the scale of the last linear layer, the tanh input is normalised (train mode)."""
    model = _model()
    with th.no_grad():
        model.actor.mu[-3].weight.mul_(1e4)
    model.policy.set_training_mode(True)
    obs = th.as_tensor(np.random.default_rng(0).uniform(-1, 1, (256, 3)), dtype=th.float32)
    pre_tanh = model.actor.mu[:-1](obs)
    assert pre_tanh.abs().max() < 5.0
    assert not th.all(model.actor(obs).abs() > 0.999)


def test_critic_normalises_state_and_action_separately():
    model = _model(policy_kwargs=dict(net_arch=[32], n_critics=2))
    for critic in (model.critic, model.critic_target):
        assert len(critic.q_networks) == 2
        for q_net in critic.q_networks:
            norm = q_net[0]
            assert isinstance(norm, StateActionBatchNorm)
            assert isinstance(norm.state_norm, nn.BatchNorm1d) and norm.state_norm.num_features == 3
            assert isinstance(norm.action_norm, nn.BatchNorm1d) and norm.action_norm.num_features == 1
            assert norm.state_norm is not norm.action_norm
            assert isinstance(q_net[1], nn.Linear) and q_net[1].in_features == 4

    # Behaviour: with the running statistics of its inputs, the Q-value does not depend on the scale/offset of the
    # state or of the action inputs, each on its own (the two inputs of the paper "with different scales").
    model = _model(policy_kwargs=dict(net_arch=[32], batch_norm_eps=1e-12, batch_norm_momentum=1.0))
    model.policy.set_training_mode(True)
    rng = np.random.default_rng(1)
    obs = th.as_tensor(rng.uniform(-1, 1, (64, 3)), dtype=th.float64)
    actions = th.as_tensor(rng.uniform(-1, 1, (64, 1)), dtype=th.float64)
    critic = model.critic.double()
    (q,) = critic(obs, actions)  # momentum 1: the running statistics become this batch's
    (q_state_scaled,) = critic(obs * 1000.0 + 5.0, actions)
    (q_action_scaled,) = critic(obs, actions * 0.001 - 2.0)
    th.testing.assert_close(q_state_scaled, q, rtol=1e-5, atol=1e-6)
    th.testing.assert_close(q_action_scaled, q, rtol=1e-5, atol=1e-6)


def test_critic_is_a_fixed_function_of_the_action():
    """TD3's actor loss -Q(s, mu(s)) must see a shift of the actions shared by the whole batch."""
    model = _model()
    model.learn(120)  # some training, so the running statistics are not the identity
    model.policy.set_training_mode(True)
    critic = model.critic
    rng = np.random.default_rng(4)
    obs = th.as_tensor(rng.uniform(-1, 1, (64, 3)), dtype=th.float32)
    actions = th.as_tensor(rng.uniform(-1, 1, (64, 1)), dtype=th.float32)
    shift = th.zeros(1, requires_grad=True)
    critic.q1_forward(obs, actions + shift).mean().backward()
    assert shift.grad.abs().item() > 1e-6
    # train mode: the batch updates the running statistics, then the inputs are normalised with them,
    # so the result equals eval mode with the updated statistics
    stats = _running_stats(critic)
    (q_train,) = critic(obs, actions)
    assert any(not th.equal(value, stats[name]) for name, value in _running_stats(critic).items())
    model.policy.set_training_mode(False)
    (q_eval,) = critic(obs, actions)
    th.testing.assert_close(q_train, q_eval, rtol=0, atol=0)


def test_state_action_batch_norm_normalises_each_column_by_running_statistics():
    norm = StateActionBatchNorm(features_dim=2, action_dim=1, momentum=1.0, eps=1e-12).double().train()
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.normal(300.0, 50.0, (128, 2)), rng.normal(-0.01, 0.001, (128, 1))], axis=1)
    out = norm(th.as_tensor(x, dtype=th.float64)).detach().numpy()
    # momentum 1: the running statistics are the batch mean and unbiased variance
    expected = (x - x.mean(axis=0)) / np.sqrt(x.var(axis=0, ddof=1) + 1e-12)
    np.testing.assert_allclose(out, expected, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(norm.state_norm.running_mean.numpy(), x[:, :2].mean(axis=0))
    np.testing.assert_allclose(norm.action_norm.running_var.numpy(), x[:, 2:].var(axis=0, ddof=1))


def test_state_action_batch_norm_updates_statistics_as_batch_norm_layers_do():
    # The running statistics and batch counters are bit for bit those of BatchNorm1d layers in train mode fed the
    # same (non-contiguous) column blocks of the input
    th.manual_seed(0)
    norm = StateActionBatchNorm(features_dim=3, action_dim=2, momentum=0.05, eps=1e-3).train()
    layers = [
        nn.BatchNorm1d(3, eps=1e-3, momentum=0.05, affine=False),
        nn.BatchNorm1d(2, eps=1e-3, momentum=0.05, affine=False),
    ]
    for _ in range(4):
        x = th.randn(64, 5) * th.tensor([3.0, 0.1, 20.0, 1.0, 0.5]) + th.tensor([1.0, -2.0, 50.0, 0.0, 0.3])
        norm(x)
        with th.no_grad():
            for layer, part in zip(layers, x.split([3, 2], dim=1), strict=True):
                layer(part)
    for mine, layer in zip((norm.state_norm, norm.action_norm), layers, strict=True):
        assert th.equal(mine.running_mean, layer.running_mean)
        assert th.equal(mine.running_var, layer.running_var)
        assert int(mine.num_batches_tracked) == int(layer.num_batches_tracked) == 4


def test_batch_norm_stats_unchanged_by_collection():
    # learning_starts=0: the policy acts from the first step (batch of one observation); gradient_steps=0: no training.
    model = _model(learning_starts=0, gradient_steps=0)
    before = _running_stats(model.policy)
    calls = []
    model.actor.mu.register_forward_hook(lambda module, inputs, output: calls.append((module.training, inputs[0].shape[0])))
    model.learn(250)
    assert len(calls) >= 250  # the actor did act
    assert all(not training and batch == 1 for training, batch in calls)
    after = _running_stats(model.policy)
    assert before.keys() == after.keys() and len(after) == 12  # (mean, var) x (actor, critic state, action) x target
    for name in before:
        th.testing.assert_close(after[name], before[name], rtol=0, atol=0)


def test_target_running_stats_equal_online_after_train_step():
    model = _model(learning_starts=50, batch_size=32)
    initial = _running_stats(model.policy)
    model.learn(60)
    assert model._n_updates > 0
    pairs = [(model.actor, model.actor_target), (model.critic, model.critic_target)]
    for online, target in pairs:
        online_stats, target_stats = _running_stats(online), _running_stats(target)
        assert online_stats.keys() == target_stats.keys()
        for name, value in online_stats.items():
            th.testing.assert_close(target_stats[name], value, rtol=0, atol=0)
    # the stats did move away from their initial values, while the weights are only soft-updated (tau < 1)
    changed = [name for name in initial if not th.equal(initial[name], _running_stats(model.policy)[name])]
    assert {"actor.mu.3.running_mean", "critic.qf0.0.state_norm.running_var", "critic.qf0.0.action_norm.running_var"} <= set(
        changed
    )
    assert not th.equal(model.actor.mu[0].weight, model.actor_target.mu[0].weight)


def test_eval_mode_predict_is_deterministic_and_batch_independent():
    model = _model(learning_starts=50, batch_size=32)
    model.learn(80)
    obs = np.random.default_rng(3).uniform(-1, 1, (5, 3)).astype(np.float32)
    batch_actions, _ = model.predict(obs, deterministic=True)
    single_actions = np.concatenate([model.predict(o, deterministic=True)[0] for o in obs])
    np.testing.assert_allclose(batch_actions.ravel(), single_actions, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(batch_norm_momentum=0.0), "batch_norm_momentum"),
        (dict(batch_norm_eps=0), "eps"),
        (dict(batch_norm_eps=float("inf")), "batch_norm_eps must be a finite number > 0, got inf"),  # constant actions
    ],
)
def test_bad_batch_norm_arguments(kwargs, match):
    env = gym.make("Pendulum-v1")
    with pytest.raises(ValueError, match=match):
        DTDPGPolicy(env.observation_space, env.action_space, lambda _: 1e-3, **kwargs)


@pytest.mark.parametrize("actor_norm", ["batch", "layer", "none"])
@pytest.mark.parametrize("critic_norm", ["batch", "layer", "none"])
def test_normalisation_options_build_the_named_layers(actor_norm, critic_norm, tmp_path):
    model = _model(policy_kwargs=dict(net_arch=[32, 16], actor_norm=actor_norm, critic_norm=critic_norm))
    expected = {"batch": nn.BatchNorm1d, "layer": nn.LayerNorm, "none": None}
    for actor in (model.actor, model.actor_target):
        kinds = {type(m) for m in actor.modules() if isinstance(m, (nn.BatchNorm1d, nn.LayerNorm))}
        assert kinds == ({expected[actor_norm]} if expected[actor_norm] else set())
    for critic in (model.critic, model.critic_target):
        has_input_bn = any(isinstance(m, StateActionBatchNorm) for m in critic.modules())
        n_layer_norms = sum(isinstance(m, nn.LayerNorm) for m in critic.modules())
        assert has_input_bn == (critic_norm == "batch")
        assert n_layer_norms == (2 if critic_norm == "layer" else 0)  # one per hidden layer, none on Q's output
    model.learn(150)
    model.save(tmp_path / "model")
    loaded = DTDPG.load(tmp_path / "model")
    assert (loaded.policy.actor_norm, loaded.policy.critic_norm) == (actor_norm, critic_norm)
    obs = np.zeros((1, 3), dtype=np.float32)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


@pytest.mark.parametrize("key", ["actor_norm", "critic_norm"])
def test_unknown_normalisation_is_an_error_naming_the_option(key):
    with pytest.raises(ValueError, match=f"{key} must be one of .*'group'"):
        _model(policy_kwargs={key: "group"})


def _modes(module: nn.Module) -> set[bool]:
    return {m.training for m in module.modules()}


def test_set_training_mode_switches_every_actor_and_critic_layer_and_no_target():
    model = _model(policy_kwargs=dict(net_arch=[32, 16], actor_norm="layer"))
    policy = model.policy
    for mode in (True, False, True):
        policy.set_training_mode(mode)
        assert policy.training is mode
        assert _modes(policy.actor) == {mode} and _modes(policy.critic) == {mode}
        assert _modes(policy.actor_target) == {False} and _modes(policy.critic_target) == {False}

    # a new actor (as a user replacing it would make) is switched too, and the old one's layers no longer are
    old_actor = policy.actor  # in train mode, as the policy
    policy.actor = policy.make_actor().train(True)
    policy.set_training_mode(False)
    assert _modes(policy.actor) == {False}
    assert _modes(old_actor) == {True}


class _CountingFlatten(nn.Flatten):
    calls: int = 0

    def train(self, mode: bool = True) -> nn.Module:
        _CountingFlatten.calls += 1
        return super().train(mode)


class _CountingExtractor(th.nn.Module):
    def __init__(self, observation_space: gym.spaces.Box) -> None:
        super().__init__()
        self.features_dim = int(np.prod(observation_space.shape))
        self.flatten = _CountingFlatten()

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.flatten(observations)


def test_set_training_mode_calls_a_layer_s_own_train_method():
    model = _model(policy_kwargs=dict(net_arch=[16], features_extractor_class=_CountingExtractor))
    model.policy.set_training_mode(True)
    before = _CountingFlatten.calls
    model.policy.set_training_mode(False)
    assert _CountingFlatten.calls > before
    assert _modes(model.policy.actor) == {False} and _modes(model.policy.critic) == {False}
