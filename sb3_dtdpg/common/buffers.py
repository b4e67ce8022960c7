"""
Replay buffers: n-step returns gathered in one compiled pass, and buffers that keep the reward components of every
transition, so rewards can be relabelled.
"""

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import NStepReplayBuffer, ReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize

from noma_radiomap.compiled import compiled

#: numpy sums up to this many numbers with eight accumulators; longer sums it splits in two (recursively)
_PAIRWISE_BLOCK = 128


@compiled
def _numpy_sum(terms: np.ndarray, n: int) -> np.float32:
    """``terms[:n].sum()`` as numpy adds a contiguous row (its pairwise summation, for ``n <=`` 128): one by one
    from zero below 8 numbers, else in eight interleaved partial sums added pairwise, then the rest one by one."""
    total = np.float32(0.0)
    if n < 8:
        for i in range(n):
            total += terms[i]
        return total
    partial = terms[:8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            partial[j] += terms[i + j]
        i += 8
    total = ((partial[0] + partial[1]) + (partial[2] + partial[3])) + ((partial[4] + partial[5]) + (partial[6] + partial[7]))
    while i < n:
        total += terms[i]
        i += 1
    return total


@compiled
def _n_step_samples(
    observations: np.ndarray,
    next_observations: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray,
    dones: np.ndarray,
    timeouts: np.ndarray,
    batch_inds: np.ndarray,
    env_inds: np.ndarray,
    n_steps: int,
    last_valid: int,
    discounts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """SB3's ``NStepReplayBuffer._get_samples`` for flat observations, one sample at a time: the same float32
    operations in the same order (each return is the sum of ``r_k d_k m_k`` in numpy's order, :func:`_numpy_sum`).
    The n-step return extends the one-step target of Eq. (23): ``y_t = sum_{k<n} gamma^k R_{t+k} +
    gamma^n Q'(S_{t+n}, mu'(S_{t+n}))``; this gathers its first sum, the final state and whether it is terminal."""
    batch, size = batch_inds.shape[0], rewards.shape[0]
    obs = np.empty((batch, observations.shape[2]), observations.dtype)
    next_obs = np.empty((batch, next_observations.shape[2]), next_observations.dtype)
    acts = np.empty((batch, actions.shape[2]), actions.dtype)
    returns = np.empty((batch, 1), np.float32)
    lengths = np.empty((batch, 1), np.int64)
    final_dones = np.empty((batch, 1), np.float32)
    one, zero = np.float32(1.0), np.float32(0.0)
    terms = np.empty(n_steps, np.float32)
    for b in range(batch):
        start, env = batch_inds[b], env_inds[b]
        # The last stored transition counts as truncated unless it ended its episode (it may precede a stale one)
        end = n_steps - 1
        for k in range(n_steps):
            i = (start + k) % size
            if dones[i, env] or timeouts[i, env] or (i == last_valid and not dones[i, env]):
                end = k
                break
        for k in range(n_steps):
            terms[k] = rewards[(start + k) % size, env] * discounts[k] * (one if k <= end else zero)
        returns[b, 0] = _numpy_sum(terms, n_steps)
        lengths[b, 0] = end + 1
        last = (start + end) % size
        truncated = timeouts[last, env] or (last == last_valid and not dones[last, env])
        final_dones[b, 0] = (one if dones[last, env] else zero) * (one - (one if truncated else zero))
        obs[b] = observations[start, env]
        next_obs[b] = next_observations[last, env]
        acts[b] = actions[start, env]
    return obs, next_obs, acts, returns, lengths, final_dones


class FastNStepSampling:
    """
    Mixin for SB3's ``NStepReplayBuffer`` and its subclasses: the batch and its n-step returns are gathered in one
    compiled pass, with the same random draws and the same numbers, bit for bit, as SB3's ``_get_samples``
    (``tests/test_buffers.py``), in about a third of its time. Under ``VecNormalize`` (the samples are normalized)
    and for returns of more than 128 steps SB3's own method runs.
    """

    def _get_samples(self, batch_inds: np.ndarray, env: VecNormalize | None = None) -> ReplayBufferSamples:
        buffer: Any = self
        if env is not None or buffer.n_steps > _PAIRWISE_BLOCK:
            return super()._get_samples(batch_inds, env=env)  # type: ignore[misc]
        env_indices = np.random.randint(0, buffer.n_envs, size=batch_inds.shape)
        size, n_envs = buffer.buffer_size, buffer.n_envs
        obs, next_obs, actions, returns, lengths, final_dones = _n_step_samples(
            buffer.observations.reshape(size, n_envs, -1),
            buffer.next_observations.reshape(size, n_envs, -1),
            buffer.actions.reshape(size, n_envs, -1),
            buffer.rewards,
            buffer.dones,
            buffer.timeouts,
            batch_inds,
            env_indices,
            buffer.n_steps,
            (buffer.pos - 1) % size,
            buffer.gamma ** np.arange(buffer.n_steps, dtype=np.float32),
        )
        # SB3's expressions, on arrays of the same shapes and types
        target_q_discounts = buffer.gamma ** lengths.astype(np.float32)
        return ReplayBufferSamples(
            observations=th.from_numpy(obs.reshape(-1, *buffer.obs_shape)).to(buffer.device),
            actions=th.from_numpy(actions.reshape(-1, *buffer.actions.shape[2:])).to(buffer.device),
            next_observations=th.from_numpy(next_obs.reshape(-1, *buffer.obs_shape)).to(buffer.device),
            dones=th.from_numpy(final_dones).to(buffer.device),
            rewards=th.from_numpy(returns).to(buffer.device),
            discounts=th.from_numpy(target_q_discounts).to(buffer.device),
        )


class FastNStepReplayBuffer(FastNStepSampling, NStepReplayBuffer):
    """
    SB3's ``NStepReplayBuffer`` (the same arguments) with :class:`FastNStepSampling`: DT-DPG's buffer for
    ``n_steps > 1`` when no phase relabels the rewards.
    """


class RewardComponentsReplayBuffer(ReplayBuffer):
    """
    Replay buffer that also stores ``info["reward_components"]`` (a dict of floats) for every transition.

    A phased env's reward is a weighted sum of these components (``env.reward_weights(phase)``), so the reward
    of every stored transition can be recomputed for another reward phase with :meth:`relabel`: the
    ``"relabel"`` replay handling of :class:`sb3_dtdpg.common.callbacks.CurriculumTransferCallback`.
    The stored rewards are the env's raw rewards (SB3 stores un-normalized rewards under ``VecNormalize``), and
    so are the relabelled ones.

    :param buffer_size: Max number of element in the buffer
    :param observation_space: Observation space
    :param action_space: Action space
    :param device: PyTorch device
    :param n_envs: Number of parallel environments
    :param optimize_memory_usage: Enable a memory efficient variant of the replay buffer (see SB3's ``ReplayBuffer``)
    :param handle_timeout_termination: Handle timeout termination (due to timelimit) separately and treat the task
        as infinite horizon task (see SB3's ``ReplayBuffer``)
    :param component_keys: Names of the reward components, the keys every ``info["reward_components"]`` must have;
        None: the keys of the first stored ``info["reward_components"]``, in their order
    :param kwargs: Further arguments of the parent buffer class (``n_steps`` and ``gamma`` of
        :class:`RewardComponentsNStepReplayBuffer`)
    """

    reward_components: np.ndarray

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        component_keys: Sequence[str] | None = None,
        **kwargs: Any,
    ):
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device=device,
            n_envs=n_envs,
            optimize_memory_usage=optimize_memory_usage,
            handle_timeout_termination=handle_timeout_termination,
            **kwargs,
        )
        self.component_keys: tuple[str, ...] | None = None
        self.reward_components = np.zeros((self.buffer_size, self.n_envs, 0), dtype=np.float64)
        if component_keys is not None:
            self._set_component_keys(component_keys)

    def _set_component_keys(self, component_keys: Sequence[str]) -> None:
        if isinstance(component_keys, str):  # a sequence too: "time" would be the keys t, i, m, e
            raise ValueError(f"component_keys must be a sequence of names, got the string {component_keys!r}")
        component_keys = tuple(component_keys)
        if not component_keys or len(set(component_keys)) != len(component_keys):
            raise ValueError(f"component_keys must be non-empty and unique, got {component_keys!r}")
        self.component_keys = component_keys
        # float64: relabelled rewards are sums of several components, computed without float32 round-off
        self.reward_components = np.zeros((self.buffer_size, self.n_envs, len(component_keys)), dtype=np.float64)

    def _components_from_infos(self, infos: list[dict[str, Any]]) -> np.ndarray:
        if len(infos) != self.n_envs:
            raise ValueError(f"expected {self.n_envs} infos (one per env), got {len(infos)}")
        if self.component_keys is None:
            first = infos[0].get("reward_components")
            if not isinstance(first, Mapping):
                raise ValueError(
                    f"{type(self).__name__} needs info['reward_components'] (a dict of floats) from every step; "
                    f"env 0 gave {first!r}"
                )
            self._set_component_keys(list(first))
        assert self.component_keys is not None
        components = np.empty((self.n_envs, len(self.component_keys)), dtype=np.float64)
        for env_idx, info in enumerate(infos):
            values = info.get("reward_components")
            if not isinstance(values, Mapping):
                raise ValueError(
                    f"{type(self).__name__} needs info['reward_components'] (a dict with keys {list(self.component_keys)}) "
                    f"from every step; env {env_idx} gave {values!r}"
                )
            for k, key in enumerate(self.component_keys):
                if key not in values:
                    raise ValueError(
                        f"info['reward_components'] of env {env_idx} has no key {key!r} (it has {sorted(values)}, "
                        f"the buffer stores {list(self.component_keys)})"
                    )
                components[env_idx, k] = values[key]
        return components

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        # Read the components first: a bad info must not leave a half-written transition behind
        components = self._components_from_infos(infos)
        self.reward_components[self.pos] = components
        super().add(obs, next_obs, action, reward, done, infos)

    def relabel(self, weights: Mapping[str, float]) -> None:
        """
        Recompute every stored reward as the weighted sum of its stored reward components.

        :param weights: Weight per component (e.g. ``env.reward_weights(phase)``); components not given weigh 0.
        """
        if self.component_keys is None:  # nothing stored yet
            return
        unknown = sorted(set(weights) - set(self.component_keys))
        if unknown:
            raise ValueError(
                f"weights has component(s) {unknown} that the buffer does not store ({list(self.component_keys)})"
            )
        w = np.array([float(weights.get(key, 0.0)) for key in self.component_keys], dtype=np.float64)
        if not np.all(np.isfinite(w)):
            raise ValueError(f"weights must be finite, got {dict(weights)!r}")
        # Unused slots hold zero components and get a zero reward: harmless, they are never sampled
        self.rewards[...] = self.reward_components @ w

    def clear(self) -> None:
        """Empty the buffer (the storage is kept and overwritten by the next transitions)."""
        self.reset()


class RewardComponentsNStepReplayBuffer(FastNStepSampling, RewardComponentsReplayBuffer, NStepReplayBuffer):
    """
    :class:`RewardComponentsReplayBuffer` with n-step returns (SB3's ``NStepReplayBuffer``, sampled by
    :class:`FastNStepSampling`).

    SB3's n-step buffer stores one-step rewards and sums ``n_steps`` of them, discounted by ``gamma``, when it
    samples; :meth:`relabel` rewrites the one-step rewards, so the n-step returns sampled after a relabel are
    those of the new reward phase. ``DTDPG`` picks this buffer when a phase relabels and ``n_steps > 1``.

    :param args: Arguments of :class:`RewardComponentsReplayBuffer`
    :param n_steps: Number of steps summed in a return
    :param gamma: Discount factor of the n-step sums (the algorithm's ``gamma``)
    :param kwargs: Keyword arguments of :class:`RewardComponentsReplayBuffer`
    """

    def __init__(self, *args: Any, n_steps: int = 3, gamma: float = 0.99, **kwargs: Any):
        super().__init__(*args, n_steps=n_steps, gamma=gamma, **kwargs)


def reward_components_buffer(n_steps: int, gamma: float) -> tuple[type[RewardComponentsReplayBuffer], dict[str, Any]]:
    """
    The replay buffer that stores reward components for an algorithm's return length.

    :param n_steps: the algorithm's ``n_steps`` (1: one-step returns)
    :param gamma: the algorithm's discount factor (used by the n-step sums)
    :return: the buffer class and the ``replay_buffer_kwargs`` it needs
    """
    if n_steps > 1:
        return RewardComponentsNStepReplayBuffer, {"n_steps": n_steps, "gamma": gamma}
    return RewardComponentsReplayBuffer, {}
