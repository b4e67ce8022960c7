"""
Lean training step and acting path of DT-DPG: the same math as SB3's TD3/DDPG ``train()`` and
``_sample_action()``, in fewer Python-level operations.

Every floating-point operation, every draw of the random generators and every Adam update of SB3's generic path
happens here too, in the same order, so the parameters, batch-norm statistics and optimizer states are
bit-identical to it (``tests/test_lean_step.py``). What is left out is work that changes no number: gradients of
the critic's weights in the actor loss (:func:`torch.autograd.grad` with respect to the actor's parameters only),
the per-call bookkeeping of ``Optimizer.step`` (the fused Adam kernel is applied to the optimizer's own state, its
step counts in one tensor), one kernel per tensor in the Polyak updates (the parameters and the batch-norm statistics
live in flat buffers, :class:`FlatPolyak` and :class:`FlatStatistics`), and the checks and copies of ``predict``
when acting. For MLP networks on vector observations (DT-DPG's and SB3's own),
the forward and backward passes run without autograd's graph (:mod:`sb3_dtdpg.dtdpg.backprop`), the same kernels on
the same tensors.
"""

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.preprocessing import is_image_space
from torch import nn
from torch.nn import functional as F

from sb3_dtdpg.dtdpg.backprop import BackpropNetworks

#: Name of the model attribute holding the lean path's caches (excluded from saving).
CACHE_ATTRIBUTE = "_lean_cache"


class FusedAdamStep:
    """
    One fused Adam step applied to a ``torch.optim.Adam(fused=True)`` optimizer's own state (its ``step``,
    ``exp_avg`` and ``exp_avg_sq`` tensors), given the gradients: the kernel ``Adam.step`` runs, without its
    per-call bookkeeping; the ``step`` counts become views of one tensor, counted by one kernel. Any other optimizer
    (or set-up: several parameter groups, AMSGrad, hooks, a state not yet created) goes through ``optimizer.step()``
    with the gradients set on the parameters.

    :param optimizer: The optimizer whose parameters and state are updated
    """

    def __init__(self, optimizer: th.optim.Optimizer):
        self.optimizer = optimizer
        self.params: list[th.Tensor] = [p for group in optimizer.param_groups for p in group["params"]]
        self._state: Any = None
        self._tensors: tuple[list[th.Tensor], list[th.Tensor], list[th.Tensor]] | None = None
        self._step_counts: th.Tensor | None = None

    def _fusable(self) -> bool:
        optimizer = self.optimizer
        if type(optimizer) is not th.optim.Adam or len(optimizer.param_groups) != 1:
            return False
        group = optimizer.param_groups[0]
        if not group.get("fused") or group.get("amsgrad") or group.get("capturable") or group.get("differentiable"):
            return False
        if group.get("decoupled_weight_decay") or getattr(optimizer, "grad_scale", None) is not None:
            return False
        if optimizer._optimizer_step_pre_hooks or optimizer._optimizer_step_post_hooks:
            return False
        from torch.optim import optimizer as optimizer_module

        if getattr(optimizer_module, "_global_optimizer_pre_hooks", None) or getattr(
            optimizer_module, "_global_optimizer_post_hooks", None
        ):
            return False
        return all(p in optimizer.state and "exp_avg" in optimizer.state[p] for p in self.params)

    def _state_tensors(self) -> tuple[list[th.Tensor], list[th.Tensor], list[th.Tensor]] | None:
        # load_state_dict() replaces optimizer.state: the cached tensors are those of the current state object
        if self._state is not self.optimizer.state or self._tensors is None:
            if not self._fusable():
                return None
            state = self.optimizer.state
            self._step_counts = self._gather_step_counts(state)
            self._tensors = (
                [state[p]["exp_avg"] for p in self.params],
                [state[p]["exp_avg_sq"] for p in self.params],
                [state[p]["step"] for p in self.params],
            )
            self._state = state
        return self._tensors

    def _gather_step_counts(self, state: Any) -> th.Tensor | None:
        """
        Move the parameters' ``step`` counts into one tensor, each its own view of it (Adam's ``step`` tensors are
        updated in place only), so that counting a step is one kernel instead of one per parameter.

        :return: that tensor, or None where the counts are not all scalars of one floating-point dtype on the CPU
        """
        counts = [state[p]["step"] for p in self.params]
        if (
            not counts
            or not all(
                isinstance(c, th.Tensor) and c.dim() == 0 and c.device.type == "cpu" and c.dtype == counts[0].dtype
                for c in counts
            )
            or not counts[0].is_floating_point()
        ):
            return None
        flat = th.stack(counts)
        for i, p in enumerate(self.params):
            state[p]["step"] = flat[i]
        return flat

    def step(self, grads: tuple[th.Tensor | None, ...]) -> None:
        """
        Update the parameters with their gradients.

        :param grads: One gradient per parameter, in the order of the optimizer's parameters (None: unused)
        """
        tensors = self._state_tensors() if all(g is not None for g in grads) else None
        if tensors is None:
            self.optimizer.zero_grad()
            for param, grad in zip(self.params, grads, strict=True):
                param.grad = grad
            self.optimizer.step()
            self._tensors = None  # the first step creates the state
            return
        exp_avgs, exp_avg_sqs, steps = tensors
        group = self.optimizer.param_groups[0]
        beta1, beta2 = group["betas"]
        with th.no_grad():
            if self._step_counts is not None:
                self._step_counts.add_(1)
            else:
                th._foreach_add_(steps, 1)
            th._fused_adam_(
                self.params,
                list(grads),  # type: ignore[arg-type]
                exp_avgs,
                exp_avg_sqs,
                [],
                steps,
                amsgrad=False,
                lr=group["lr"],
                beta1=beta1,
                beta2=beta2,
                weight_decay=group["weight_decay"],
                eps=group["eps"],
                maximize=group["maximize"],
                grad_scale=None,
                found_inf=None,
            )


class FlatPolyak:
    """
    The Polyak updates of :class:`LeanTrainer` on flat memory: the parameters of each online network and of its target
    become views of two flat buffers (their ``.data``), so that an update is one multiply and one add per network
    instead of one kernel per tensor, the same elementwise operations on the same numbers. Each view starts at a
    64-byte boundary, as a tensor of its own does, so every other kernel (the matrix products, batch norm) reads the
    same memory layout. Only ``nn.Parameter`` objects are moved: they are the modules' own tensors, where SB3's lists
    of batch-norm statistics hold detached aliases of the modules' buffers (moving an alias would leave its buffer
    behind).

    :param pairs: per network, its parameters and its target's, in the same order
    """

    #: Alignment of each view in the buffers, in bytes (that of torch's CPU allocator)
    ALIGNMENT = 64

    def __init__(self, pairs: list[tuple[list[th.Tensor], list[th.Tensor]]]):
        self.buffers = [(self._gather(online), self._gather(target)) for online, target in pairs]
        self.tensors = [t for online, target in pairs for t in (*online, *target)]
        self.pointers = [t.data_ptr() for t in self.tensors]

    @classmethod
    def of(cls, pairs: list[tuple[list[th.Tensor], list[th.Tensor]]]) -> "FlatPolyak | None":
        """:return: the flat updates, or None where the tensors do not allow them (each tensor must be an
        ``nn.Parameter`` in one pair once, contiguous, on the CPU, of its network's floating-point dtype, and match its
        online tensor's shape)"""
        tensors = [t for online, target in pairs for t in (*online, *target)]
        if not all(isinstance(t, nn.Parameter) for t in tensors) or not cls._movable(pairs):
            return None
        return cls(pairs)

    @staticmethod
    def _movable(pairs: list[tuple[list[th.Tensor], list[th.Tensor]]]) -> bool:
        """:return: whether each tensor is in one pair once, contiguous, on the CPU, of its network's floating-point
        dtype, and of its online tensor's shape"""
        tensors = [t for online, target in pairs for t in (*online, *target)]
        if not tensors or len({id(t) for t in tensors}) != len(tensors) or any(not online for online, _ in pairs):
            return False
        for online, target in pairs:
            dtype = online[0].dtype
            for t in (*online, *target):
                if t.device.type != "cpu" or not t.is_contiguous() or t.dtype != dtype or not t.is_floating_point():
                    return False
            if len(online) != len(target) or any(a.shape != b.shape for a, b in zip(online, target, strict=True)):
                return False
        return True

    @classmethod
    def _gather(cls, tensors: list[th.Tensor]) -> th.Tensor:
        """Move the tensors into one new buffer, each a view of it; :return: the buffer"""
        step = max(1, cls.ALIGNMENT // tensors[0].element_size())
        offsets, size = [], 0
        for t in tensors:
            offsets.append(size)
            size += -(-t.numel() // step) * step
        buffer = th.zeros(size, dtype=tensors[0].dtype)
        for t, offset in zip(tensors, offsets, strict=True):
            view = buffer[offset : offset + t.numel()].view_as(t)
            view.copy_(t.detach())
            t.data = view
        return buffer

    def current(self) -> bool:
        """:return: whether every tensor still lives in its buffer"""
        return all(t.data_ptr() == pointer for t, pointer in zip(self.tensors, self.pointers, strict=True))

    def update(self, tau: float) -> None:
        """``target = (1 - tau) * target + tau * online`` on each network's buffers."""
        for online, target in self.buffers:
            target.mul_(1 - tau)
            target.add_(online, alpha=tau)


class FlatStatistics(FlatPolyak):
    """
    The copy of the batch-norm statistics to the targets (SB3's ``polyak_update`` with ``tau = 1``) on flat memory,
    as :class:`FlatPolyak` updates the parameters: one buffer per network for its statistics, so that a copy is one
    multiply and one add per network, the same operations on the same numbers. SB3's lists of statistics hold
    detached aliases of the modules' buffers: each module buffer moves to its view, and so does its alias.

    :param pairs: per network, the module buffers of its statistics and its target's, in the same order
    :param aliases: SB3's aliases of the same buffers, in the same layout
    """

    def __init__(self, pairs: list[tuple[list[th.Tensor], list[th.Tensor]]], aliases: list[th.Tensor]):
        super().__init__(pairs)
        moved = [t for online, target in pairs for t in (*online, *target)]
        for alias, buffer in zip(aliases, moved, strict=True):
            alias.data = buffer.data
        self.tensors = [*self.tensors, *aliases]
        self.pointers = [t.data_ptr() for t in self.tensors]

    @classmethod
    def of_statistics(
        cls, pairs: list[tuple[list[th.Tensor], list[th.Tensor]]], networks: list[nn.Module]
    ) -> "FlatStatistics | None":
        """
        :param pairs: per network, SB3's aliases of its statistics and of its target's
        :param networks: The modules holding those statistics
        :return: the flat copies, or None where an alias is not one module buffer's, or the buffers do not allow them
            (see :meth:`FlatPolyak.of`, buffers in place of parameters)
        """
        buffers: dict[int, list[th.Tensor]] = {}
        for network in networks:
            for buffer in network.buffers():
                buffers.setdefault(buffer.data_ptr(), []).append(buffer)
        owned: list[tuple[list[th.Tensor], list[th.Tensor]]] = []
        for online, target in pairs:
            owners: tuple[list[th.Tensor], list[th.Tensor]] = ([], [])
            for aliases, found in zip((online, target), owners, strict=True):
                for alias in aliases:
                    candidates = [b for b in buffers.get(alias.data_ptr(), []) if b.shape == alias.shape]
                    if len(candidates) != 1:
                        return None
                    found.append(candidates[0])
            owned.append(owners)
        if not cls._movable(owned):
            return None
        return cls(owned, [t for online, target in pairs for t in (*online, *target)])


class LeanTrainer:
    """
    The tensors and helpers one model's lean step needs, built once per set of networks and optimizers (a new
    policy, from ``_setup_model``, ``reinitialize`` or ``load``, makes a new one; :class:`FusedAdamStep` follows a
    loaded optimizer state).

    :param model: A TD3/DDPG model (``actor``, ``critic``, their targets and optimizers, batch-norm statistics)
    """

    def __init__(self, model: Any):
        self.owners = self._owners(model)
        self.networks = BackpropNetworks.of(model)
        self.actor_adam = FusedAdamStep(model.actor.optimizer)
        self.critic_adam = FusedAdamStep(model.critic.optimizer)
        # The gradients are those of the parameters each optimizer updates
        self.actor_params = self.actor_adam.params
        self.critic_params = self.critic_adam.params
        # SB3 Polyak-updates the critic, then the actor (tau), then copies the critic's and the actor's batch-norm
        # statistics (tau = 1): one pass per run of these groups that touches each target once (a
        # features extractor shared by actor and critic is updated twice, one after the other, as SB3 does)
        groups = [
            (list(model.critic.parameters()), list(model.critic_target.parameters()), False),
            (list(model.actor.parameters()), list(model.actor_target.parameters()), False),
            (list(model.critic_batch_norm_stats), list(model.critic_batch_norm_stats_target), True),
            (list(model.actor_batch_norm_stats), list(model.actor_batch_norm_stats_target), True),
        ]
        self.groups = groups
        self.passes: list[tuple[list[th.Tensor], list[th.Tensor], bool]] = []
        for online, target, copy in groups:
            if len(online) != len(target):
                raise ValueError("the target networks do not match the online networks")
            if not target:
                continue
            last = self.passes[-1] if self.passes else None
            if last is not None and last[2] == copy and not {id(t) for t in target} & {id(t) for t in last[1]}:
                last[0].extend(online)
                last[1].extend(target)
            else:
                self.passes.append((list(online), list(target), copy))
        self._flatten()

    def _flatten(self) -> None:
        """Move the parameters to :class:`FlatPolyak` and the batch-norm statistics to :class:`FlatStatistics` where
        they can take them, one buffer per network (so that a network's ``state_dict`` saves its own tensors only);
        the rest stay foreach passes."""
        self._flat = FlatPolyak.of([(online, target) for online, target, copy in self.groups if not copy])
        self._flat_statistics = FlatStatistics.of_statistics(
            [(online, target) for online, target, copy in self.groups if copy and target], list(self.owners[1:5])
        )
        flat = {False: self._flat is not None, True: self._flat_statistics is not None}
        self._foreach_passes = [p for p in self.passes if not flat[p[2]]]

    @staticmethod
    def _owners(model: Any) -> tuple[Any, ...]:
        networks = (model.policy, model.actor, model.critic, model.actor_target, model.critic_target)
        return (*networks, model.actor.optimizer, model.critic.optimizer)

    def valid_for(self, model: Any) -> bool:
        """:return: whether this cache was built for the model's current networks"""
        return all(a is b for a, b in zip(self.owners, self._owners(model), strict=True))

    def polyak(self, tau: float) -> None:
        """SB3's ``polyak_update`` of the targets (``target = (1 - tau) * target + tau * online``), and the copy of the
        batch-norm statistics (the same update with ``tau = 1``): on the flat buffers of :class:`FlatPolyak` and
        :class:`FlatStatistics` where they apply, the rest with one foreach kernel over the tensors of each pass."""
        with th.no_grad():
            if any(flat is not None and not flat.current() for flat in (self._flat, self._flat_statistics)):
                self._flatten()  # a tensor was given new memory (``.data``, ``.to()``)
            if self._flat is not None:
                self._flat.update(tau)
            if self._flat_statistics is not None:
                self._flat_statistics.update(1.0)
            for online, target, copy in self._foreach_passes:
                weight = 1.0 if copy else tau
                th._foreach_mul_(target, 1 - weight)
                th._foreach_add_(target, online, alpha=weight)


def lean_trainer(model: Any) -> LeanTrainer:
    """:return: the model's :class:`LeanTrainer`, built anew when its networks changed"""
    trainer = getattr(model, CACHE_ATTRIBUTE, None)
    if trainer is None or not trainer.valid_for(model):
        trainer = LeanTrainer(model)
        setattr(model, CACHE_ATTRIBUTE, trainer)
    return trainer


def _written_out(model: Any, trainer: LeanTrainer) -> BackpropNetworks | None:
    """:return: the networks with their passes written out, where the model asks for them (``backprop``), they cover
    its networks and no module hook is registered; else None (autograd and the modules)"""
    networks = trainer.networks
    if networks is None or not getattr(model, "backprop", True) or networks.hooked():
        return None
    return networks


def lean_train(model: Any, gradient_steps: int, batch_size: int) -> None:
    """
    SB3's TD3 ``train()`` (DDPG: TD3 with one critic, no target noise and no policy delay), the same math in
    fewer operations (see the module docstring).

    :param model: The TD3/DDPG model
    :param gradient_steps: Number of gradient steps
    :param batch_size: Minibatch size
    """
    trainer = lean_trainer(model)
    model.policy.set_training_mode(True)
    model._update_learning_rate([model.actor.optimizer, model.critic.optimizer])
    networks = _written_out(model, trainer)
    actor_losses: list[float] = []
    critic_losses: list[float] = []
    for _ in range(gradient_steps):
        model._n_updates += 1
        data = model.replay_buffer.sample(batch_size, env=model._vec_normalize_env)
        target_q_values = _target_q_values(model, data, networks)
        if networks is None:
            critic_losses.append(_autograd_critic_step(model, trainer, data, target_q_values))
        else:
            critic_losses.append(networks.critic_step(data, target_q_values, trainer.critic_adam))
        if model._n_updates % model.policy_delay == 0:
            if networks is None:
                actor_losses.append(_autograd_actor_step(model, trainer, data.observations))
            else:
                actor_losses.append(networks.actor_step(data.observations, trainer.actor_adam))
            trainer.polyak(model.tau)
    model.logger.record("train/n_updates", model._n_updates, exclude="tensorboard")
    if len(actor_losses) > 0:
        model.logger.record("train/actor_loss", _mean(actor_losses))
    model.logger.record("train/critic_loss", _mean(critic_losses))


def _mean(values: list[float]) -> float:
    """``np.mean(values)``, without numpy's overhead for the usual one value (the same number)."""
    return values[0] if len(values) == 1 else float(np.mean(values))


@th.no_grad()
def _target_q_values(model: Any, data: Any, networks: BackpropNetworks | None) -> th.Tensor:
    """The bootstrapped targets of Eq. (23) (TD3's minimum over the target critics; ``gamma ** n`` of n-step returns),
    through the modules or the written-out networks."""
    discounts = data.discounts if data.discounts is not None else model.gamma
    # The target noise is drawn as SB3 draws it (also when its scale is 0): the torch generator's stream stays the same
    noise = th.empty_like(data.actions).normal_(0, model.target_policy_noise)
    noise = noise.clamp(-model.target_noise_clip, model.target_noise_clip)
    if networks is None:
        next_actions = (model.actor_target(data.next_observations) + noise).clamp(-1, 1)
        next_q = model.critic_target(data.next_observations, next_actions)
        next_q_values = next_q[0] if len(next_q) == 1 else th.cat(next_q, dim=1).min(dim=1, keepdim=True)[0]
    else:
        next_actions = (networks.actor_target.forward(data.next_observations) + noise).clamp(-1, 1)
        next_q_values = networks.critic_target.forward(data.next_observations, next_actions)
    return data.rewards + (1 - data.dones) * discounts * next_q_values


def _autograd_critic_step(model: Any, trainer: LeanTrainer, data: Any, target_q_values: th.Tensor) -> float:
    """One update of the critic(s) through autograd (any networks), the loss of Eq. (22); :return: the loss"""
    current_q_values = model.critic(data.observations, data.actions)
    if len(current_q_values) == 1:
        critic_loss = F.mse_loss(current_q_values[0], target_q_values)
    else:
        critic_loss = sum(F.mse_loss(current_q, target_q_values) for current_q in current_q_values)
    # allow_unused: a features extractor shared with the actor gets no gradient from the critic loss (SB3's Adam then
    # skips it, as FusedAdamStep does)
    trainer.critic_adam.step(th.autograd.grad(critic_loss, trainer.critic_params, allow_unused=True))
    return critic_loss.item()


def _autograd_actor_step(model: Any, trainer: LeanTrainer, observations: th.Tensor) -> float:
    """One update of the actor through autograd (any networks), the policy gradient of Eq. (21); :return: the loss"""
    actor_loss = -model.critic.q1_forward(observations, model.actor(observations)).mean()
    trainer.actor_adam.step(th.autograd.grad(actor_loss, trainer.actor_params, allow_unused=True))
    return actor_loss.item()


def fast_actable(observation_space: spaces.Space) -> bool:
    """:return: whether :func:`policy_action` can act on observations of this space (vector or dict of vectors)"""
    if isinstance(observation_space, spaces.Dict):
        return all(isinstance(s, spaces.Box) and not is_image_space(s) for s in observation_space.spaces.values())
    return isinstance(observation_space, spaces.Box) and not is_image_space(observation_space)


def policy_action(model: Any, observation: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
    """
    The actions ``model.predict(observation, deterministic=False)`` returns for a vectorized observation of a
    :func:`fast_actable` space, computed without its checks and copies (under ``inference_mode``); the policy must
    be in evaluation mode, as it is while SB3 collects rollouts.

    :param model: The TD3/DDPG model
    :param observation: The vectorized observation (one row per env)
    :return: The actions, in the action space's bounds, one row per env
    """
    policy = model.policy
    device = model.device
    if isinstance(observation, dict):
        obs: th.Tensor | dict[str, th.Tensor] = {key: th.as_tensor(value, device=device) for key, value in observation.items()}
    else:
        obs = th.as_tensor(observation, device=device)
    networks = _written_out(model, lean_trainer(model))
    with th.inference_mode():
        actions = model.actor(obs) if networks is None else networks.actor.forward(obs)  # type: ignore[arg-type]
    actions = actions.cpu().numpy().reshape((-1, *model.action_space.shape))
    return (
        policy.unscale_action(actions)
        if policy.squash_output
        else np.clip(actions, model.action_space.low, model.action_space.high)
    )


class LeanStep:
    """
    Mixin for SB3's TD3 and its subclasses (DDPG, DTDPG): ``train()`` is :func:`lean_train` and, after the warm-up,
    ``_sample_action()`` acts through :func:`policy_action`, both bit-identical to SB3's; with ``lean = False``
    (an instance attribute) the model uses SB3's generic ones. The caches are not saved with the model.
    """

    #: Train and act with the lean step (False: SB3's generic ``train()`` and ``_sample_action()``)
    lean: bool = True
    #: In the lean step, write the backward passes out where the networks allow it (False: autograd)
    backprop: bool = True

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        if not self.lean:
            super().train(gradient_steps, batch_size)  # type: ignore[misc]
            return
        lean_train(self, gradient_steps, batch_size)

    def _sample_action(
        self,
        learning_starts: int,
        action_noise: ActionNoise | None = None,
        n_envs: int = 1,
    ) -> tuple[np.ndarray, np.ndarray]:
        model: Any = self
        if not self.lean or model.num_timesteps < learning_starts or not fast_actable(model.observation_space):
            return super()._sample_action(learning_starts, action_noise, n_envs)  # type: ignore[misc]
        assert model._last_obs is not None, "self._last_obs was not set"
        model.policy.set_training_mode(False)  # a no-op while collecting rollouts
        # What SB3 does with predict()'s actions: rescale to [-1, 1], add the noise, store the scaled action
        scaled_action = model.policy.scale_action(policy_action(model, model._last_obs))
        if action_noise is not None:
            scaled_action = np.clip(scaled_action + action_noise(), -1, 1)
        return model.policy.unscale_action(scaled_action), scaled_action

    def _excluded_save_params(self) -> list[str]:
        excluded = [*super()._excluded_save_params(), CACHE_ATTRIBUTE]  # type: ignore[misc]
        if _buffer_of_sb3s_choice(self):
            # Left out, SB3's load chooses the same buffer again; saved, SB3 hands it back as a custom class and
            # warns that n_steps is ignored on every load (DLR-RM/stable-baselines3#2275)
            excluded.append("replay_buffer_class")
        return excluded


def _buffer_of_sb3s_choice(model: Any) -> bool:
    """:return: whether the model's replay buffer class is the one SB3 picks for its ``n_steps`` (and ``gamma``)"""
    kwargs = model.replay_buffer_kwargs or {}
    return (
        model.replay_buffer_class is NStepReplayBuffer
        and model.n_steps > 1
        and kwargs.get("n_steps") == model.n_steps
        and kwargs.get("gamma") == model.gamma
    )


class LeanDDPG(LeanStep, DDPG):
    """SB3's DDPG with the lean training step and acting path: the same parameters bit for bit, faster on CPU."""


class LeanTD3(LeanStep, TD3):
    """SB3's TD3 with the lean training step and acting path: the same parameters bit for bit, faster on CPU."""
