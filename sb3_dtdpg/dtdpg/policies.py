"""Batch-normalised actor and critic of DT-DPG (Section IV-C of the paper)."""

import math
from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, CombinedExtractor, FlattenExtractor, NatureCNN
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.td3.policies import Actor as TD3Actor
from stable_baselines3.td3.policies import TD3Policy
from torch import nn
from torch.nn import functional as F


class Actor(TD3Actor):
    """
    Actor network (policy) for DT-DPG: SB3's TD3 actor (hidden ``Linear -> activation`` layers, then a
    ``Linear`` output layer) with a ``BatchNorm1d`` inserted right before the ``Tanh`` output.

    Numerics (paper, Section IV-C and Remark 1): a deterministic actor trained through ``tanh`` drifts
    towards pre-activations of large magnitude, where ``tanh`` saturates, its gradient vanishes and the agent
    keeps outputting extreme actions. Normalising the pre-activations per action dimension keeps them at the
    learned scale ``gamma`` around the learned offset ``beta`` (both initialised to 1 and 0: the
    non-saturated range of ``tanh``). During training the layer normalises with the statistics of the sampled
    batch; at collection time (SB3 switches the policy to eval mode, batch of one observation) it uses its
    running mean and variance, which are buffers (saved in the ``state_dict``, copied to the target actor
    by TD3's ``train`` with ``tau = 1``).

    :param observation_space: Observation space
    :param action_space: Action space
    :param net_arch: Network architecture
    :param features_extractor: Network to extract features
        (a CNN when using images, a nn.Flatten() layer otherwise)
    :param features_dim: Number of features
    :param activation_fn: Activation function
    :param normalize_images: Whether to normalize images or not,
         dividing by 255.0 (True by default)
    :param batch_norm_momentum: Momentum of the running statistics (PyTorch convention: weight of the new batch)
    :param batch_norm_eps: Value added to the variance for numerical stability
    :param norm: ``"batch"`` (the batch norm before ``tanh``), ``"layer"`` (a ``LayerNorm`` after each hidden
        ``Linear``) or ``"none"``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: nn.Module,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        normalize_images: bool = True,
        batch_norm_momentum: float = 0.01,
        batch_norm_eps: float = 1e-3,
        norm: str = "batch",
    ):
        super().__init__(
            observation_space,
            action_space,
            net_arch,
            features_extractor,
            features_dim,
            activation_fn=activation_fn,
            normalize_images=normalize_images,
        )
        _check_norm("actor_norm", norm)
        self.batch_norm_momentum = batch_norm_momentum
        self.batch_norm_eps = batch_norm_eps
        self.norm = norm
        # TD3's actor ends with Linear -> Tanh: insert the batch norm between them
        *layers, tanh = self.mu
        assert isinstance(tanh, nn.Tanh)
        action_dim = get_action_dim(self.action_space)
        if norm == "batch":
            output_norm = nn.BatchNorm1d(action_dim, eps=batch_norm_eps, momentum=batch_norm_momentum)
            self.mu = nn.Sequential(*layers, output_norm, tanh)
        elif norm == "layer":
            self.mu = nn.Sequential(*_with_layer_norm(layers), tanh)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(dict(batch_norm_momentum=self.batch_norm_momentum, batch_norm_eps=self.batch_norm_eps, norm=self.norm))
        return data


NORMS: tuple[str, ...] = ("batch", "layer", "none")


def _check_norm(name: str, value: str) -> None:
    if value not in NORMS:
        raise ValueError(f"{name} must be one of {NORMS}, got {value!r}")


def _with_layer_norm(layers: list[nn.Module]) -> list[nn.Module]:
    """A ``LayerNorm`` after every hidden ``Linear`` (before its activation); the output layer is left alone."""
    linears = [i for i, layer in enumerate(layers) if isinstance(layer, nn.Linear)]
    out: list[nn.Module] = []
    for i, layer in enumerate(layers):
        out.append(layer)
        if isinstance(layer, nn.Linear) and i != linears[-1]:
            out.append(nn.LayerNorm(layer.out_features))
    return out


class StateActionBatchNorm(nn.Module):
    """
    Input layer of the DT-DPG critic: the state features and the action, which come in the critic's input
    ``th.cat([features, actions], dim=1)``, each pass through their own ``BatchNorm1d`` (paper, Section
    IV-C: "the scales of the input values are likely to be significantly different") and are concatenated
    again.

    Numerics: the inputs are normalised with the layers' running statistics in both modes; in train mode each
    batch first updates them. The critic is then one fixed (slowly moving) function of the state and the
    action in all its uses: the critic loss, the bootstrapped target (target critic, eval mode) and the actor
    loss. With batch statistics the actor loss ``-Q(s, mu(s))`` would be blind to any shift or scale of the
    actions shared by the batch (``BN(a + c) = BN(a)``), so the actor could not learn the level of its
    actions, and the critic would be fitted on inputs normalised differently from those of its target
    (measured on Pendulum-v1 with RL Zoo's DDPG settings: mean return -426 with batch statistics,
    -172 and -127 (2 seeds) with running statistics, SB3's DDPG -137).

    :param features_dim: Number of state features (the first columns of the input)
    :param action_dim: Number of action dimensions (the last columns)
    :param momentum: Momentum of the running statistics
    :param eps: Value added to the variance for numerical stability
    """

    def __init__(self, features_dim: int, action_dim: int, momentum: float = 0.01, eps: float = 1e-3):
        super().__init__()
        self.features_dim = features_dim
        self.action_dim = action_dim
        # No learnable scale and shift: the Linear layer that follows absorbs any per-feature affine map
        self.state_norm = nn.BatchNorm1d(features_dim, eps=eps, momentum=momentum, affine=False)
        self.action_norm = nn.BatchNorm1d(action_dim, eps=eps, momentum=momentum, affine=False)

    @staticmethod
    def _normalize(norm: nn.BatchNorm1d, x: th.Tensor) -> th.Tensor:
        if norm.training:
            with th.no_grad():
                # what norm(x) does to the running statistics, without computing its (unused) output
                th.batch_norm_update_stats(x, norm.running_mean, norm.running_var, norm.momentum)
                norm.num_batches_tracked.add_(1)
        return F.batch_norm(x, norm.running_mean, norm.running_var, training=False, eps=norm.eps)

    def forward(self, state_action: th.Tensor) -> th.Tensor:
        state, action = state_action.split([self.features_dim, self.action_dim], dim=1)
        return th.cat([self._normalize(self.state_norm, state), self._normalize(self.action_norm, action)], dim=1)


class Critic(ContinuousCritic):
    """
    Critic network(s) for DT-DPG: SB3's continuous critic (``Linear -> activation`` layers on the
    concatenated state and action, then ``Q``) whose input first passes :class:`StateActionBatchNorm`,
    one per Q-network. The running statistics are buffers: TD3's ``train`` copies them to the target critic
    (with ``tau = 1``), which normalises the bootstrapped target with them, as the online critic does.

    :param observation_space: Observation space
    :param action_space: Action space
    :param net_arch: Network architecture
    :param features_extractor: Network to extract features
        (a CNN when using images, a nn.Flatten() layer otherwise)
    :param features_dim: Number of features
    :param activation_fn: Activation function
    :param normalize_images: Whether to normalize images or not,
         dividing by 255.0 (True by default)
    :param n_critics: Number of critic networks to create.
    :param share_features_extractor: Whether the features extractor is shared or not
        between the actor and the critic (this saves computation time)
    :param batch_norm_momentum: Momentum of the running statistics
    :param batch_norm_eps: Value added to the variance for numerical stability
    :param norm: ``"batch"`` (:class:`StateActionBatchNorm` at the input), ``"layer"`` (a ``LayerNorm`` after each
        hidden ``Linear``) or ``"none"``
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        normalize_images: bool = True,
        n_critics: int = 1,
        share_features_extractor: bool = True,
        batch_norm_momentum: float = 0.01,
        batch_norm_eps: float = 1e-3,
        norm: str = "batch",
    ):
        super().__init__(
            observation_space,
            action_space,
            net_arch,
            features_extractor,
            features_dim,
            activation_fn=activation_fn,
            normalize_images=normalize_images,
            n_critics=n_critics,
            share_features_extractor=share_features_extractor,
        )
        _check_norm("critic_norm", norm)
        action_dim = get_action_dim(self.action_space)
        for idx, q_net in enumerate(self.q_networks):
            if norm == "batch":
                input_norm = StateActionBatchNorm(features_dim, action_dim, momentum=batch_norm_momentum, eps=batch_norm_eps)
                self.q_networks[idx] = nn.Sequential(input_norm, *q_net)
            elif norm == "layer":
                self.q_networks[idx] = nn.Sequential(*_with_layer_norm(list(q_net)))
            else:
                continue
            self.add_module(f"qf{idx}", self.q_networks[idx])


class DTDPGPolicy(TD3Policy):
    """
    Policy class (actor and critic, with their targets) for DT-DPG: the batch-normalised :class:`Actor`
    and :class:`Critic`. SB3's TD3 switches it to eval mode to collect experience (so the batch norm
    layers use their running statistics on a batch of one) and to train mode for gradient steps, and
    keeps the targets in eval mode.

    :param observation_space: Observation space
    :param action_space: Action space
    :param lr_schedule: Learning rate schedule (could be constant)
    :param net_arch: The specification of the policy and value networks
        (default: ``[128, 128]``, within the paper's "64-128 nodes per hidden layer")
    :param activation_fn: Activation function (ReLU in the paper)
    :param features_extractor_class: Features extractor to use.
    :param features_extractor_kwargs: Keyword arguments
        to pass to the features extractor.
    :param normalize_images: Whether to normalize images or not,
         dividing by 255.0 (True by default)
    :param optimizer_class: The optimizer to use,
        ``th.optim.Adam`` by default
    :param optimizer_kwargs: Additional keyword arguments,
        excluding the learning rate, to pass to the optimizer
        (None: ``{"fused": True}`` for Adam and AdamW, the fast single-kernel implementation)
    :param n_critics: Number of critic networks to create (1 for DT-DPG, as for DDPG).
    :param share_features_extractor: Whether to share or not the features extractor
        between the actor and the critic (this saves computation time)
    :param batch_norm_momentum: Momentum of the running statistics of every batch norm layer
        (PyTorch convention: the weight of the new batch; 0.01 is Keras' default 0.99, as in sb3-contrib's CrossQ)
    :param batch_norm_eps: Value added to the variance for numerical stability (1e-3, Keras' default: a feature
        that is constant in the replay buffer, such as an arrived flag, is not amplified more than ~30x)
    :param actor_norm: Normalisation in the actor: ``"batch"`` (the paper's design, a ``BatchNorm1d`` right before
        the ``tanh``), ``"layer"`` (a ``LayerNorm`` after each hidden ``Linear``) or ``"none"`` (TD3's plain actor);
        the alternatives are ablations (docs/BENCHMARKS.md)
    :param critic_norm: Normalisation in the critic: ``"batch"`` (the paper's design, separate batch norms of
        the state and the action at the input), ``"layer"`` (a ``LayerNorm`` after each hidden ``Linear``) or
        ``"none"`` (SB3's plain critic)
    """

    actor: Actor
    actor_target: Actor
    critic: Critic
    critic_target: Critic

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        n_critics: int = 1,
        share_features_extractor: bool = False,
        batch_norm_momentum: float = 0.01,
        batch_norm_eps: float = 1e-3,
        actor_norm: str = "batch",
        critic_norm: str = "batch",
    ):
        _check_norm("actor_norm", actor_norm)
        _check_norm("critic_norm", critic_norm)
        self.actor_norm = actor_norm
        self.critic_norm = critic_norm
        if not 0.0 < batch_norm_momentum <= 1.0:
            raise ValueError(f"batch_norm_momentum must be in (0, 1], got {batch_norm_momentum!r}")
        if not 0.0 < batch_norm_eps < math.inf:  # an infinite eps normalises everything to 0: constant actions
            raise ValueError(f"batch_norm_eps must be a finite number > 0, got {batch_norm_eps!r}")
        self.batch_norm_momentum = batch_norm_momentum
        self.batch_norm_eps = batch_norm_eps
        if optimizer_kwargs is None and optimizer_class in (th.optim.Adam, th.optim.AdamW):
            # One fused kernel for all parameter tensors: the batch norm layers add tensors, and with small
            # networks the per-tensor Python loop of the default Adam dominates a gradient step on CPU.
            optimizer_kwargs = {"fused": True}
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch=[128, 128] if net_arch is None else net_arch,
            activation_fn=activation_fn,
            features_extractor_class=features_extractor_class,
            features_extractor_kwargs=features_extractor_kwargs,
            normalize_images=normalize_images,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
            n_critics=n_critics,
            share_features_extractor=share_features_extractor,
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(
                batch_norm_momentum=self.batch_norm_momentum,
                batch_norm_eps=self.batch_norm_eps,
                actor_norm=self.actor_norm,
                critic_norm=self.critic_norm,
            )
        )
        return data

    def set_training_mode(self, mode: bool) -> None:
        """
        Put the actor and critic in training or evaluation mode (batch norm: batch or running statistics).

        SB3 calls this twice per env step (``collect_rollouts`` and ``predict``) and once per ``train()``; the
        recursive ``nn.Module.train`` over every layer costs more than a batch-of-one forward pass, so a call
        that changes nothing returns at once, and a switch sets the flag of every layer of the actor and the
        critic from a list made once (the same flags ``nn.Module.train`` sets; the targets stay in eval mode).

        :param mode: if true, set to training mode, else set to evaluation mode
        """
        if self.training == mode and self.actor.training == mode and self.critic.training == mode:
            return
        modules = self._mode_modules()
        if modules is None:
            super().set_training_mode(mode)
            return
        for module in modules:
            # what nn.Module.train does per module, without nn.Module.__setattr__'s checks (a bool is no parameter)
            object.__setattr__(module, "training", mode)
        self.training = mode

    def _mode_modules(self) -> list[nn.Module] | None:
        """
        Every module of the actor and the critic, listed once per actor/critic object; None when a module has its
        own ``train`` method (then only ``nn.Module.train`` itself knows what a switch does).
        """
        owners = getattr(self, "_mode_modules_owners", (None, None))
        if owners[0] is not self.actor or owners[1] is not self.critic:
            modules = [*self.actor.modules(), *self.critic.modules()]
            plain = all(type(module).train is nn.Module.train for module in modules)
            self._mode_modules_cache = modules if plain else None
            self._mode_modules_owners = (self.actor, self.critic)
        return self._mode_modules_cache

    def make_actor(self, features_extractor: BaseFeaturesExtractor | None = None) -> Actor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return Actor(
            **actor_kwargs,
            batch_norm_momentum=self.batch_norm_momentum,
            batch_norm_eps=self.batch_norm_eps,
            norm=self.actor_norm,
        ).to(self.device)

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> Critic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        return Critic(
            **critic_kwargs,
            batch_norm_momentum=self.batch_norm_momentum,
            batch_norm_eps=self.batch_norm_eps,
            norm=self.critic_norm,
        ).to(self.device)


MlpPolicy = DTDPGPolicy


class CnnPolicy(DTDPGPolicy):
    """
    Policy class (actor and critic, with their targets) for DT-DPG on image observations: :class:`DTDPGPolicy`
    with SB3's ``NatureCNN`` features extractor. The batch norms are those of :class:`DTDPGPolicy`: right before
    the actor's ``tanh``, and separately on the critic's CNN features and the action.

    :param observation_space: Observation space
    :param action_space: Action space
    :param lr_schedule: Learning rate schedule (could be constant)
    :param net_arch: The specification of the policy and value networks (default: ``[128, 128]``)
    :param features_extractor_class: Features extractor to use.
    :param kwargs: The other arguments of :class:`DTDPGPolicy`, by keyword (``activation_fn``,
        ``features_extractor_kwargs``, ``normalize_images``, ..., ``actor_norm``, ``critic_norm``)
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        *,
        features_extractor_class: type[BaseFeaturesExtractor] = NatureCNN,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch=net_arch,
            features_extractor_class=features_extractor_class,
            **kwargs,
        )


class MultiInputPolicy(DTDPGPolicy):
    """
    Policy class (actor and critic, with their targets) for DT-DPG on ``Dict`` observations (for instance goal envs
    with ``HerReplayBuffer``): :class:`DTDPGPolicy` with SB3's ``CombinedExtractor`` (a ``NatureCNN`` per image key,
    the other keys flattened, all concatenated). The batch norms are those of :class:`DTDPGPolicy`: right before
    the actor's ``tanh``, and separately on the critic's combined features and the action.

    :param observation_space: Observation space
    :param action_space: Action space
    :param lr_schedule: Learning rate schedule (could be constant)
    :param net_arch: The specification of the policy and value networks (default: ``[128, 128]``)
    :param features_extractor_class: Features extractor to use.
    :param kwargs: The other arguments of :class:`DTDPGPolicy`, by keyword (``activation_fn``,
        ``features_extractor_kwargs``, ``normalize_images``, ..., ``actor_norm``, ``critic_norm``)
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        *,
        features_extractor_class: type[BaseFeaturesExtractor] = CombinedExtractor,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch=net_arch,
            features_extractor_class=features_extractor_class,
            **kwargs,
        )
