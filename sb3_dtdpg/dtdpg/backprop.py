"""
The gradient step of the DDPG family with the backward passes written out, for the common case of MLP actors and
critics (DT-DPG's batch-norm networks and SB3's plain ones) on vector observations, on the CPU.

Autograd records a graph at every forward pass and walks it at every backward pass; for networks of a few hundred
units that bookkeeping costs more than the matrix products. Here the forward passes run without a graph and each
backward pass is the chain of the ATen kernels autograd itself would call, on tensors of the same shapes and
layouts: ``addmm`` (``nn.Linear``) backward is ``grad.mm(W)``, ``grad.t().mm(x)`` and ``grad.sum(0)``, ReLU backward
is ``threshold_backward`` on the layer's output, ``tanh`` backward is ``tanh_backward``, batch norm is
``native_batch_norm`` and ``native_batch_norm_backward`` (the critic's input batch norm, which normalises with its
running statistics, is that kernel's formula written out, on the whole input at once), the losses are
``mse_loss_backward`` and the mean's ``-1 / n``. So every number is the one autograd gives, bit for bit
(``tests/test_lean_step.py`` compares the two over whole training runs).

:meth:`BackpropNetworks.of` recognises the networks it can run; anything else trains on the autograd path of
:mod:`sb3_dtdpg.dtdpg.lean`.
"""

from dataclasses import dataclass
from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import FlattenExtractor
from torch import nn
from torch.nn import functional as F
from torch.nn.modules import module as torch_module

from sb3_dtdpg.dtdpg.policies import StateActionBatchNorm

_aten = th.ops.aten
#: The hook dictionaries of an ``nn.Module``, and torch's global ones
_MODULE_HOOKS = ("_forward_hooks", "_forward_pre_hooks", "_backward_hooks", "_backward_pre_hooks")
_GLOBAL_HOOKS = (
    "_global_forward_hooks",
    "_global_forward_pre_hooks",
    "_global_backward_hooks",
    "_global_backward_pre_hooks",
)
#: ``reduction`` of ``mse_loss`` and ``mse_loss_backward``: the mean
_MEAN = 1
#: The batch statistics batch norm keeps when it normalises with its running statistics: none
_NO_STATISTICS = th.empty(0)


@dataclass
class _Trace:
    """What a forward pass keeps for its backward pass: each ``Linear``'s input and a batch norm's input and
    statistics."""

    inputs: list[th.Tensor]
    pre_norm: th.Tensor | None = None
    save_mean: th.Tensor | None = None
    save_invstd: th.Tensor | None = None
    output: th.Tensor | None = None


class _LinearStack:
    """
    ``Linear (ReLU Linear)*``: its weights and biases, a forward pass and its backward pass.

    :param layers: The modules, in order
    """

    def __init__(self, layers: list[nn.Module]):
        linears, activations = layers[0::2], layers[1::2]
        self.supported = (
            len(layers) % 2 == 1
            and all(type(layer) is nn.Linear and layer.bias is not None for layer in linears)
            and all(type(layer) is nn.ReLU for layer in activations)
        )
        self.weights: list[th.Tensor] = [layer.weight for layer in linears] if self.supported else []
        self.biases: list[th.Tensor] = [layer.bias for layer in linears] if self.supported else []

    @property
    def params(self) -> list[th.Tensor]:
        """The parameters in the order :meth:`backward` fills their gradients in: weight, bias, layer by layer."""
        return [p for pair in zip(self.weights, self.biases, strict=True) for p in pair]

    def forward(self, x: th.Tensor, trace: _Trace | None) -> th.Tensor:
        """The output for ``x``; a trace keeps each layer's input."""
        last = len(self.weights) - 1
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            if trace is not None:
                trace.inputs.append(x)
            x = F.linear(x, weight, bias)
            if i < last:
                x = th.relu(x)
        return x

    def backward(self, grad: th.Tensor, trace: _Trace, param_grads: list[th.Tensor] | None) -> th.Tensor:
        """
        The backward pass of :meth:`forward`.

        :param grad: Gradient of the output
        :param trace: The forward pass's trace
        :param param_grads: Where to put the gradients of :attr:`params`, in their order (None: not needed, and the
            gradient of the input is computed instead)
        :return: The gradient of the input (with ``param_grads``: of the first layer's output)
        """
        for i in range(len(self.weights) - 1, -1, -1):
            x = trace.inputs[i]
            if param_grads is not None:
                param_grads[2 * i] = grad.t().mm(x)
                param_grads[2 * i + 1] = grad.sum([0], keepdim=True).view(-1)
                if i == 0:
                    break
            grad = grad.mm(self.weights[i])
            if i > 0:
                # ReLU's backward pass, on its output (the next layer's input)
                grad = _aten.threshold_backward(grad, x, 0)
        return grad


def _plain_batch_norm(norm: nn.Module, affine: bool) -> bool:
    return (
        type(norm) is nn.BatchNorm1d
        and norm.track_running_stats
        and norm.momentum is not None
        and norm.affine == affine
        and norm.running_mean is not None
    )


class MlpActor:
    """
    An actor ``Linear (ReLU Linear)* [BatchNorm1d] Tanh`` on flattened vector observations (TD3's actor, DT-DPG's
    with the batch norm before ``tanh``).

    :param actor: The actor (``features_extractor``, ``mu``)
    """

    def __init__(self, actor: nn.Module):
        *layers, tanh = list(actor.mu)
        self.norm: nn.BatchNorm1d | None = layers.pop() if layers and type(layers[-1]) is nn.BatchNorm1d else None
        self.stack = _LinearStack(layers)
        self.supported = (
            type(tanh) is nn.Tanh
            and self.stack.supported
            and (self.norm is None or _plain_batch_norm(self.norm, affine=True))
            and type(actor.features_extractor) is FlattenExtractor
        )
        norm_params = [self.norm.weight, self.norm.bias] if self.norm is not None else []
        #: The parameters, in the order of the gradients of :meth:`backward`
        self.params: list[th.Tensor] = [*self.stack.params, *norm_params]

    def forward(self, obs: th.Tensor, trace: _Trace | None = None) -> th.Tensor:
        """
        The actions, in the module's mode (batch norm: the batch's statistics, and their update, in training mode).

        :param obs: Observations (B, features)
        :param trace: Filled with what :meth:`backward` needs
        """
        x = self.stack.forward(obs.float(), trace)
        norm = self.norm
        if norm is not None:
            if norm.training:
                norm.num_batches_tracked.add_(1)
            pre_norm = x
            x, save_mean, save_invstd = _aten.native_batch_norm(
                x, norm.weight, norm.bias, norm.running_mean, norm.running_var, norm.training, norm.momentum, norm.eps
            )
            if trace is not None:
                trace.pre_norm, trace.save_mean, trace.save_invstd = pre_norm, save_mean, save_invstd
        x = th.tanh(x)
        if trace is not None:
            trace.output = x
        return x

    def backward(self, grad: th.Tensor, trace: _Trace) -> list[th.Tensor]:
        """:return: the gradients of :attr:`params`, given the gradient of the actions"""
        grad = _aten.tanh_backward(grad, trace.output)
        param_grads: list[th.Tensor] = [grad] * len(self.params)
        norm = self.norm
        if norm is not None:
            grad, param_grads[-2], param_grads[-1] = _aten.native_batch_norm_backward(
                grad,
                trace.pre_norm,
                norm.weight,
                norm.running_mean,
                norm.running_var,
                trace.save_mean,
                trace.save_invstd,
                norm.training,
                norm.eps,
                [True, True, True],
            )
        self.stack.backward(grad, trace, param_grads)
        return param_grads


class MlpCritic:
    """
    The first Q-network of a critic ``[StateActionBatchNorm] Linear (ReLU Linear)*`` on the concatenated
    flattened observation and action (SB3's critic, DT-DPG's with the batch norms of state and action).

    :param critic: The critic (``features_extractor``, ``q_networks``)
    """

    def __init__(self, critic: nn.Module):
        layers = list(critic.q_networks[0])
        has_norm = bool(layers) and type(layers[0]) is StateActionBatchNorm
        self.input_norm: StateActionBatchNorm | None = layers.pop(0) if has_norm else None  # type: ignore[assignment]
        self.stack = _LinearStack(layers)
        self.action_dim = get_action_dim(critic.action_space)
        norm = self.input_norm
        self.supported = (
            critic.n_critics == 1
            and self.stack.supported
            and (
                norm is None
                or (
                    _plain_batch_norm(norm.state_norm, affine=False)
                    and _plain_batch_norm(norm.action_norm, affine=False)
                    and norm.state_norm.eps == norm.action_norm.eps
                )
            )
            and type(critic.features_extractor) is FlattenExtractor
        )
        #: The parameters, in the order of the gradients of :meth:`backward_params`
        self.params: list[th.Tensor] = self.stack.params

    def _normalize(self, state_action: th.Tensor, trace: _Trace | None) -> th.Tensor:
        """
        :class:`StateActionBatchNorm` on the concatenated input, in one pass over it: the running statistics of both
        parts are updated (training mode) as the module updates them, then each column is normalised as batch norm's
        kernel normalises a column of a non-contiguous input (the module's parts are column slices) with running
        statistics, ``((x - mean) * invstd) * 1 + 0`` with ``invstd = 1 / sqrt(var + eps)``, the same float32
        operations on the same numbers. The trace keeps the action part for its backward pass.
        """
        norm = self.input_norm
        assert norm is not None
        state_norm, action_norm = norm.state_norm, norm.action_norm
        state, action = state_action.split([norm.features_dim, norm.action_dim], dim=1)
        for batch_norm, x in ((state_norm, state), (action_norm, action)):
            if batch_norm.training:
                th.batch_norm_update_stats(x, batch_norm.running_mean, batch_norm.running_var, batch_norm.momentum)
                batch_norm.num_batches_tracked.add_(1)
        if trace is not None:
            # batch norm with running statistics keeps no batch statistics: its backward pass gets empty ones
            trace.pre_norm, trace.save_mean, trace.save_invstd = action, _NO_STATISTICS, _NO_STATISTICS
        mean = th.cat([state_norm.running_mean, action_norm.running_mean])
        invstd = th.cat([state_norm.running_var, action_norm.running_var]).add_(state_norm.eps).sqrt_().reciprocal_()
        return state_action.sub(mean).mul_(invstd).add_(0.0)  # + 0: a -0.0 comes out +0.0, as from the kernel

    def forward(self, obs: th.Tensor, actions: th.Tensor, trace: _Trace | None = None) -> th.Tensor:
        """
        Q(obs, actions), in the module's mode (batch norm: the running statistics, first updated with the batch in
        training mode).

        :param obs: Observations (B, features)
        :param actions: Actions (B, action_dim)
        :param trace: Filled with what :meth:`backward_params` and :meth:`backward_actions` need
        """
        x = th.cat([obs.float(), actions], dim=1)
        if self.input_norm is not None:
            x = self._normalize(x, trace)
        return self.stack.forward(x, trace)

    def backward_params(self, grad: th.Tensor, trace: _Trace) -> list[th.Tensor]:
        """:return: the gradients of :attr:`params`, given the gradient of Q"""
        param_grads: list[th.Tensor] = [grad] * len(self.params)
        self.stack.backward(grad, trace, param_grads)
        return param_grads

    def backward_actions(self, grad: th.Tensor, trace: _Trace) -> th.Tensor:
        """:return: the gradient of the actions, given the gradient of Q"""
        grad_input = self.stack.backward(grad, trace, None)
        grad_action = grad_input.narrow(1, grad_input.shape[1] - self.action_dim, self.action_dim)
        norm = self.input_norm
        if norm is None:
            return grad_action
        batch_norm = norm.action_norm
        return _aten.native_batch_norm_backward(
            grad_action,
            trace.pre_norm,
            None,
            batch_norm.running_mean,
            batch_norm.running_var,
            trace.save_mean,
            trace.save_invstd,
            False,
            batch_norm.eps,
            [True, False, False],
        )[0]


def _order(params: list[th.Tensor], optimizer_params: list[th.Tensor]) -> list[int | None]:
    """:return: for each parameter of an optimizer, its index in ``params`` (None: not there, no gradient)"""
    index = {id(p): i for i, p in enumerate(params)}
    return [index.get(id(p)) for p in optimizer_params]


class BackpropNetworks:
    """
    A TD3/DDPG model's actor, critic and their targets as :class:`MlpActor` / :class:`MlpCritic`, and its gradient
    steps with the backward passes written out.

    :param model: The model, or its policy (anything with ``actor``, ``critic``, their targets and optimizers)
    """

    def __init__(self, model: Any):
        self.actor = MlpActor(model.actor)
        self.critic = MlpCritic(model.critic)
        self.actor_target = MlpActor(model.actor_target)
        self.critic_target = MlpCritic(model.critic_target)
        modules = [m for net in (model.actor, model.critic, model.actor_target, model.critic_target) for m in net.modules()]
        # The hooks of every module (and the global ones): dictionaries torch fills in place when a hook is registered
        self._hooks: list[dict] = [
            *(getattr(torch_module, name, {}) for name in _GLOBAL_HOOKS),
            *(getattr(m, name) for m in modules for name in _MODULE_HOOKS),
        ]
        self.actor_order = _order(self.actor.params, [p for g in model.actor.optimizer.param_groups for p in g["params"]])
        self.critic_order = _order(self.critic.params, [p for g in model.critic.optimizer.param_groups for p in g["params"]])

    def hooked(self) -> bool:
        """:return: whether a forward or backward hook is registered on a module of the networks (or globally): the
        written-out passes would not call it, so the networks run as modules under autograd then"""
        return any(self._hooks)

    @classmethod
    def of(cls, model: Any) -> "BackpropNetworks | None":
        """:return: the model's networks, or None where they are not of the kinds this module writes out"""
        space = model.observation_space
        # On a GPU, batch norm runs cuDNN's kernels under autograd: only the CPU's are written out here
        if not isinstance(space, spaces.Box) or len(space.shape) != 1 or th.device(model.device).type != "cpu":
            return None
        networks = cls(model)
        parts = (networks.actor, networks.critic, networks.actor_target, networks.critic_target)
        return networks if all(part.supported for part in parts) else None

    @th.no_grad()
    def critic_step(self, data: Any, target_q_values: th.Tensor, adam: Any) -> float:
        """
        One update of the critic: MSE to the targets (Eq. (22)), its backward pass, the Adam step.

        :param data: The batch (``observations``, ``actions``)
        :param target_q_values: The bootstrapped targets
        :param adam: The critic's :class:`~sb3_dtdpg.dtdpg.lean.FusedAdamStep`
        :return: The loss
        """
        trace = _Trace([])
        current_q_values = self.critic.forward(data.observations, data.actions, trace)
        critic_loss = F.mse_loss(current_q_values, target_q_values)
        grad_q = _aten.mse_loss_backward(th.ones_like(critic_loss), current_q_values, target_q_values, _MEAN)
        grads = self.critic.backward_params(grad_q, trace)
        adam.step(tuple(None if i is None else grads[i] for i in self.critic_order))
        return critic_loss.item()

    @th.no_grad()
    def actor_step(self, observations: th.Tensor, adam: Any) -> float:
        """
        One update of the actor: ``-mean(Q(s, mu(s)))`` (Eq. (21)), its backward pass through the critic, the Adam step.

        :param observations: The batch's observations
        :param adam: The actor's :class:`~sb3_dtdpg.dtdpg.lean.FusedAdamStep`
        :return: The loss
        """
        actor_trace, critic_trace = _Trace([]), _Trace([])
        actions = self.actor.forward(observations, actor_trace)
        q_values = self.critic.forward(observations, actions, critic_trace)
        actor_loss = -q_values.mean()
        # The gradient of -mean(Q) as autograd forms it: -1 spread over the batch, divided by its size
        grad_q = th.full_like(q_values, -1.0).div(q_values.numel())
        grads = self.actor.backward(self.critic.backward_actions(grad_q, critic_trace), actor_trace)
        adam.step(tuple(None if i is None else grads[i] for i in self.actor_order))
        return actor_loss.item()
