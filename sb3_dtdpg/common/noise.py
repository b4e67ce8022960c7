"""Linearly decayed Ornstein-Uhlenbeck action noise (DT-DPG, Section IV-B of the paper)."""

import copy
import warnings
from typing import Any

import numpy as np
from numpy.typing import DTypeLike
from stable_baselines3.common.noise import (
    ActionNoise,
    NormalActionNoise,
    OrnsteinUhlenbeckActionNoise,
    VectorizedActionNoise,
)

from sb3_dtdpg.common.checks import _is_real


def _as_sigma(name: str, value: float | np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.broadcast_to(np.asarray(value, dtype=np.float64), shape).copy()
    except (TypeError, ValueError) as e:
        raise ValueError(
            f"{name} must be a number or an array broadcastable to the action shape {shape}, got {value!r}"
        ) from e
    if not np.all(np.isfinite(array)) or np.any(array < 0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return array


def _check_process(mean: Any, sigma: Any, theta: Any = 0.15, dt: Any = 1e-2, initial_noise: Any = None) -> np.ndarray:
    """
    Check the settings of a Gaussian or OU noise before SB3's constructor takes them (it checks none: a wrong one
    failed, or went wrong, at the first draw, during training).

    :return: the mean as an array
    :raises ValueError: naming the first setting that is not finite, positive or of the mean's shape, or theta and dt
        when ``theta * dt >= 2`` (the process diverges)
    """
    try:
        array = np.asarray(mean, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or not np.all(np.isfinite(array)):
        raise ValueError(f"mean must be an array of finite numbers (its shape is the action shape), got {mean!r}")
    _as_sigma("sigma", sigma, array.shape)
    for name, value in (("theta", theta), ("dt", dt)):
        if not _is_real(value) or value <= 0:
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    # SB3's draw x += theta * (mean - x) * dt + ... multiplies x - mean by 1 - theta * dt: stable for theta * dt < 2
    if theta * dt >= 2:
        raise ValueError(
            f"theta * dt must be < 2 (from 2 on the OU process's steps grow without bound), got theta={theta!r}, "
            f"dt={dt!r}: theta * dt = {theta * dt!r}"
        )
    if initial_noise is not None:
        try:
            noise = np.broadcast_to(np.asarray(initial_noise, dtype=np.float64), array.shape)
        except (TypeError, ValueError):
            noise = None
        if noise is None or not np.all(np.isfinite(noise)):
            raise ValueError(
                f"initial_noise must be None or finite numbers of the mean's shape {array.shape}, got {initial_noise!r}"
            )
    return np.asarray(mean)


def _as_decay_episodes(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"decay_episodes must be an integer >= 1, got {value!r}")
    return int(value)


class _EpisodeSchedule:
    """
    The sigma schedule and its episode counter, shared by every copy of one noise
    (see :class:`LinearDecayOUNoise` on vectorized environments). ``version`` counts the changes of ``current``.
    """

    def __init__(self, sigma: np.ndarray, final_sigma: np.ndarray, decay_episodes: int) -> None:
        self.sigma = sigma
        self.final_sigma = final_sigma
        self.decay_episodes = decay_episodes
        self.episodes = 0
        self.current = sigma.copy()
        self.version = 0

    def set_episode(self, episodes: int) -> None:
        self.episodes = episodes
        # sigma_k = sigma_0 + (sigma_final - sigma_0) * k / K, evaluated from k each time (no drift), then sigma_final
        # exactly (the formula at k = K can be off by one ulp)
        if episodes >= self.decay_episodes:
            self.current = self.final_sigma.copy()
        else:
            self.current = self.sigma + (self.final_sigma - self.sigma) * episodes / self.decay_episodes
        self.version += 1


class LinearDecayOUNoise(ActionNoise):
    """
    Ornstein-Uhlenbeck action noise whose scale falls linearly per episode, the exploration noise of DT-DPG
    (Zhong et al., "Path Design and Resource Management for NOMA enhanced Indoor Intelligent Robots",
    Section IV-B: the action ``A_t = mu(S_t) + N(0, xi)`` of Eq. (20) with "linearly diminishing OU noise", the
    scale ``xi(X, E)`` a function of the training task and the episode number, updated at the start of every
    episode, Algorithm 1).

    In episode ``k`` (counting from 0 since construction or the last :meth:`rearm`) the scale is
    ``sigma_k = sigma + (final_sigma - sigma) * k / decay_episodes`` for ``k < decay_episodes``, then
    exactly ``final_sigma``. The process itself is SB3's ``OrnsteinUhlenbeckActionNoise`` of the current scale
    (:attr:`process`): when the scale changes, a new one of the new scale takes over the process's state
    (``noise_prev``), so the noise goes on without a jump. :meth:`reset` ends an episode:
    it resets the OU state (as SB3's ``OrnsteinUhlenbeckActionNoise`` does) and advances the schedule.
    A ``reset()`` with no noise drawn since the previous one does not count as an episode: SB3 also calls
    ``reset()`` when the noise is built, when ``VectorizedActionNoise`` wraps it and at the start of every
    ``learn()``, and these calls must not move the schedule. (A ``learn()`` call that starts in the middle of
    an episode therefore counts the interrupted part as one episode.)

    Vectorized environments: SB3's ``VectorizedActionNoise`` deep-copies the noise once per environment.
    The copies keep their own OU state but **share one episode counter**: the schedule advances once per
    finished episode of *any* environment, so ``decay_episodes`` counts episodes in total, like the
    curriculum's episode budgets, whatever the number of environments. This sharing is implemented in
    ``__deepcopy__``, for a deep copy of the noise itself: a deep copy of something that holds it (a model, a
    ``VectorizedActionNoise``) gets a schedule of its own, shared between the copies it holds. A pickle round-trip
    (``model.save`` / ``load``) keeps the sharing between the copies it saves together, and
    ``pickle.loads(pickle.dumps(noise))`` gives a fully independent copy.

    :param mean: Mean of the noise (its shape is the action shape)
    :param sigma: Initial scale of the noise (a number or one value per action dimension)
    :param final_sigma: Scale reached after ``decay_episodes`` episodes
    :param decay_episodes: Number of episodes over which the scale falls from ``sigma`` to ``final_sigma``
    :param theta: Rate of mean reversion
    :param dt: Timestep for the noise
    :param initial_noise: Initial value for the noise output (if None: 0)
    :param dtype: Type of the output noise
    """

    def __init__(
        self,
        mean: np.ndarray,
        sigma: float | np.ndarray,
        final_sigma: float | np.ndarray,
        decay_episodes: int,
        theta: float = 0.15,
        dt: float = 1e-2,
        initial_noise: np.ndarray | None = None,
        dtype: DTypeLike = np.float32,
    ) -> None:
        mean = _check_process(mean, sigma, theta, dt, initial_noise)
        super().__init__()
        self._schedule = _EpisodeSchedule(
            _as_sigma("sigma", sigma, mean.shape),
            _as_sigma("final_sigma", final_sigma, mean.shape),
            _as_decay_episodes(decay_episodes),
        )
        self._steps_since_reset = 0
        self._process_args: dict[str, Any] = dict(mean=mean, theta=theta, dt=dt, initial_noise=initial_noise, dtype=dtype)
        self.process = self._new_process()

    def _new_process(self) -> OrnsteinUhlenbeckActionNoise:
        self._process_version = self._schedule.version
        return OrnsteinUhlenbeckActionNoise(sigma=self._schedule.current, **self._process_args)

    @property
    def noise_prev(self) -> np.ndarray:
        """The OU state: the last noise drawn (the initial noise after a reset)."""
        return self.process.noise_prev

    @property
    def mean(self) -> np.ndarray:
        """Mean of the noise."""
        return self._process_args["mean"]

    @property
    def theta(self) -> float:
        return self._process_args["theta"]

    @property
    def dt(self) -> float:
        return self._process_args["dt"]

    @property
    def initial_sigma(self) -> np.ndarray:
        """The scale the schedule started from (at construction or the last :meth:`rearm`)."""
        return self._schedule.sigma.copy()

    @property
    def current_sigma(self) -> np.ndarray:
        """The noise scale of the current episode (one value per action dimension)."""
        return self._schedule.current.copy()

    @property
    def episode(self) -> int:
        """Episodes finished since construction or the last :meth:`rearm` (shared by vectorized copies)."""
        return self._schedule.episodes

    @property
    def final_sigma(self) -> np.ndarray:
        return self._schedule.final_sigma.copy()

    @property
    def decay_episodes(self) -> int:
        return self._schedule.decay_episodes

    def __call__(self) -> np.ndarray:
        self._steps_since_reset += 1
        if self._process_version != self._schedule.version:  # the shared schedule moved: go on at the new scale
            state = self.process.noise_prev
            self.process = self._new_process()
            self.process.noise_prev = state
        return self.process()

    def reset(self) -> None:
        """End an episode: advance the sigma schedule (if any noise was drawn in it) and reset the OU state."""
        if self._steps_since_reset > 0:
            self._schedule.set_episode(self._schedule.episodes + 1)
        self._steps_since_reset = 0
        self.process.reset()

    def rearm(
        self,
        sigma: float | np.ndarray,
        final_sigma: float | np.ndarray | None = None,
        decay_episodes: int | None = None,
    ) -> None:
        """
        Restart the schedule from episode 0 with a new initial scale (at a curriculum transfer).
        The episode in progress does not count towards the new schedule.

        :param sigma: New initial scale
        :param final_sigma: New final scale (None: keep the current one)
        :param decay_episodes: New decay horizon in episodes (None: keep the current one)
        """
        schedule, shape = self._schedule, self.mean.shape
        schedule.sigma = _as_sigma("sigma", sigma, shape)
        if final_sigma is not None:
            schedule.final_sigma = _as_sigma("final_sigma", final_sigma, shape)
        if decay_episodes is not None:
            schedule.decay_episodes = _as_decay_episodes(decay_episodes)
        schedule.set_episode(0)
        self._steps_since_reset = 0

    def __setstate__(self, state: dict[str, Any]) -> None:
        if "process" in state:
            self.__dict__.update(state)
            return
        # Pickled by sb3-dtdpg 0.1.0, whose noise drew the OU process itself (a model saved then still loads)
        schedule = state["_schedule"]
        schedule.__dict__.setdefault("version", 0)
        self._schedule, self._steps_since_reset = schedule, state["_steps_since_reset"]
        self._process_args = dict(
            mean=state["_mu"],
            theta=state["_theta"],
            dt=state["_dt"],
            initial_noise=state["initial_noise"],
            dtype=state["_dtype"],
        )
        self.process = self._new_process()
        self.process.noise_prev = state["noise_prev"]

    def __deepcopy__(self, memo: dict[int, Any]) -> "LinearDecayOUNoise":
        if not memo:  # the noise itself is copied, as SB3's VectorizedActionNoise does per env: share the schedule
            memo[id(self._schedule)] = self._schedule
        clone = self.__class__.__new__(self.__class__)
        memo[id(self)] = clone
        clone.__dict__.update(copy.deepcopy(self.__dict__, memo))
        return clone

    def __repr__(self) -> str:
        return (
            f"LinearDecayOUNoise(mu={self.mean}, sigma={self._schedule.sigma}, final_sigma={self._schedule.final_sigma}, "
            f"decay_episodes={self._schedule.decay_episodes}, episode={self._schedule.episodes})"
        )


class NormalNoise(NormalActionNoise):
    """
    SB3's ``NormalActionNoise`` (the same draws) whose settings are public attributes, so that a run's identity can
    record them and a curriculum can re-arm its scale (:meth:`rearm`); SB3's own noises keep their settings
    private. The baselines' Gaussian noise (:func:`sb3_dtdpg.presets.model_kwargs`).

    :param mean: Mean of the noise (its shape is the action shape)
    :param sigma: Scale (standard deviation) of the noise
    :param dtype: Type of the output noise
    """

    def __init__(self, mean: np.ndarray, sigma: np.ndarray, dtype: DTypeLike = np.float32) -> None:
        _check_process(mean, sigma)
        self.mean, self.sigma, self.dtype = mean, sigma, dtype
        super().__init__(mean, sigma, dtype)

    def rearm(self, sigma: float | np.ndarray) -> None:
        """
        Set a new scale, through the public constructor of SB3's noise.

        :param sigma: the new scale (a number or one value per action dimension)
        """
        self.sigma = _as_sigma("sigma", sigma, np.shape(self.mean))
        super().__init__(self.mean, self.sigma, self.dtype)


class OrnsteinUhlenbeckNoise(OrnsteinUhlenbeckActionNoise):
    """
    SB3's ``OrnsteinUhlenbeckActionNoise`` (the same draws) whose settings are public attributes, so that a run's
    identity can record them and a curriculum can re-arm its scale (:meth:`rearm`); SB3's own noises keep their
    settings private. The constant-scale OU noise of the DDPG baseline (:func:`sb3_dtdpg.presets.model_kwargs`).

    :param mean: Mean of the noise (its shape is the action shape)
    :param sigma: Scale of the noise
    :param theta: Rate of mean reversion
    :param dt: Timestep for the noise
    :param initial_noise: Initial value for the noise output (if None: 0)
    :param dtype: Type of the output noise
    """

    def __init__(
        self,
        mean: np.ndarray,
        sigma: np.ndarray,
        theta: float = 0.15,
        dt: float = 1e-2,
        initial_noise: np.ndarray | None = None,
        dtype: DTypeLike = np.float32,
    ) -> None:
        _check_process(mean, sigma, theta, dt, initial_noise)
        self.mean, self.sigma, self.theta, self.dt, self.dtype = mean, sigma, theta, dt, dtype
        super().__init__(mean, sigma, theta, dt, initial_noise, dtype)

    def rearm(self, sigma: float | np.ndarray) -> None:
        """
        Set a new scale, through the public constructor of SB3's noise; the process goes on from its current state.

        :param sigma: the new scale (a number or one value per action dimension)
        """
        state = self.noise_prev
        self.sigma = _as_sigma("sigma", sigma, np.shape(self.mean))
        super().__init__(self.mean, self.sigma, self.theta, self.dt, self.initial_noise, self.dtype)
        self.noise_prev = state


#: The noises whose scale can be re-armed with a constant scale, and the SB3 noise whose draws each one makes
#: (what a run's identity records as its type).
_CONSTANT_NOISES: dict[type, type] = {NormalNoise: NormalActionNoise, OrnsteinUhlenbeckNoise: OrnsteinUhlenbeckActionNoise}


def decaying_noise(
    action_shape: tuple[int, ...],
    sigma: float | np.ndarray,
    final_sigma: float | np.ndarray,
    decay_episodes: int,
    n_envs: int = 1,
) -> ActionNoise:
    """
    DT-DPG's exploration noise: a zero-mean :class:`LinearDecayOUNoise`, one per env (SB3's
    ``VectorizedActionNoise``) when ``n_envs > 1``.

    :param action_shape: the action space's shape
    :param sigma: initial scale
    :param final_sigma: scale reached after ``decay_episodes`` episodes
    :param decay_episodes: length of the linear decay in episodes
    :param n_envs: number of envs the noise serves
    :return: the noise
    """
    noise = LinearDecayOUNoise(np.zeros(action_shape, dtype=np.float32), sigma, final_sigma, decay_episodes)
    return VectorizedActionNoise(noise, n_envs) if n_envs > 1 else noise


def _noises(action_noise: ActionNoise) -> list[ActionNoise]:
    if isinstance(action_noise, VectorizedActionNoise):
        return [action_noise.base_noise, *action_noise.noises]
    return [action_noise]


def advance_noise(action_noise: ActionNoise | None, episodes: int) -> None:
    """
    Move the decay schedule of a :class:`LinearDecayOUNoise` (or of the copies of one in SB3's
    ``VectorizedActionNoise``) to ``episodes`` episodes since it was armed: a noise made anew for a curriculum resumed
    mid-phase goes on at the phase's scale of the moment. Other noises have no schedule and are left alone.

    :param action_noise: the noise (``model.action_noise``; None: nothing)
    :param episodes: the episodes of the phase so far
    """
    if action_noise is None:
        return
    for noise in _noises(action_noise):
        if isinstance(noise, LinearDecayOUNoise):
            noise._schedule.set_episode(episodes)


def rearm_noise(
    action_noise: ActionNoise | None,
    sigma: float | np.ndarray,
    final_sigma: float | np.ndarray | None = None,
    decay_episodes: int | None = None,
) -> None:
    """
    Re-arm the exploration noise of a model with a new initial scale (at a curriculum transfer).

    Works on a :class:`LinearDecayOUNoise`, on SB3's ``VectorizedActionNoise`` wrapping one, and on the
    constant-scale :class:`NormalNoise` / :class:`OrnsteinUhlenbeckNoise` (their scale is set to ``sigma``; a decay
    cannot be applied to them and is ignored with a warning). SB3's own ``NormalActionNoise`` /
    ``OrnsteinUhlenbeckActionNoise`` keep their scale private: they are left as they are, with a warning that names
    the noise to use instead. ``None`` (no noise) is left alone.

    :param action_noise: The noise to re-arm (``model.action_noise``)
    :param sigma: New initial scale
    :param final_sigma: New final scale (None: keep the current one)
    :param decay_episodes: New decay horizon in episodes (None: keep the current one)
    """
    if action_noise is None:
        return
    for noise in _noises(action_noise):
        if isinstance(noise, LinearDecayOUNoise):
            noise.rearm(sigma, final_sigma, decay_episodes)
        elif isinstance(noise, tuple(_CONSTANT_NOISES)):
            noise.rearm(sigma)
            if final_sigma is not None and not np.allclose(final_sigma, sigma):
                warnings.warn(f"{type(noise).__name__} has a constant scale: final_sigma={final_sigma!r} is ignored")
        elif isinstance(noise, tuple(_CONSTANT_NOISES.values())):
            warnings.warn(
                f"{type(noise).__name__} keeps its scale private: it is not re-armed to sigma={sigma!r}; pass "
                f"sb3_dtdpg.common.noise.{_public_noise_name(noise)} (the same noise) to re-arm it"
            )
        else:
            raise TypeError(f"Cannot re-arm action noise of type {type(noise).__name__}")


def _public_noise_name(noise: ActionNoise) -> str:
    return next(public.__name__ for public, sb3 in _CONSTANT_NOISES.items() if isinstance(noise, sb3))


def noise_sigma(action_noise: ActionNoise | None) -> float:
    """
    The current scale of a model's exploration noise, averaged over action dimensions (for logging).

    :param action_noise: ``model.action_noise``: a :class:`LinearDecayOUNoise`, :class:`NormalNoise` or
        :class:`OrnsteinUhlenbeckNoise`, SB3's ``VectorizedActionNoise`` wrapping one, or None (counts as 0); SB3's
        own noises, which keep their scale private, give NaN
    :return: The mean of the current sigma
    :raises TypeError: for another noise class
    """
    if action_noise is None:
        return 0.0
    if isinstance(action_noise, VectorizedActionNoise):
        action_noise = action_noise.base_noise
    if isinstance(action_noise, LinearDecayOUNoise):
        return float(np.mean(action_noise.current_sigma))
    if isinstance(action_noise, tuple(_CONSTANT_NOISES)):
        return float(np.mean(action_noise.sigma))
    if isinstance(action_noise, tuple(_CONSTANT_NOISES.values())):
        return float("nan")
    raise TypeError(f"Cannot read the scale of action noise of type {type(action_noise).__name__}")


def noise_settings(action_noise: ActionNoise | None) -> dict[str, Any] | None:
    """
    The settings of an exploration noise as plain data (a run's identity; :func:`sb3_dtdpg.presets.model_settings`).

    :param action_noise: ``model.action_noise``: a :class:`LinearDecayOUNoise`, :class:`NormalNoise` or
        :class:`OrnsteinUhlenbeckNoise` (recorded as the SB3 noise whose draws it makes), SB3's
        ``VectorizedActionNoise`` wrapping one, or None
    :return: ``{"type": "module.Class", ...}`` with lists for arrays and ``n_envs`` for a vectorized noise; None
    :raises TypeError: for another noise class, SB3's own noises included (they keep their settings private: use
        :class:`NormalNoise` / :class:`OrnsteinUhlenbeckNoise`, the same noises)
    """
    if action_noise is None:
        return None
    if isinstance(action_noise, VectorizedActionNoise):
        return {**(noise_settings(action_noise.base_noise) or {}), "n_envs": int(action_noise.n_envs)}
    if isinstance(action_noise, LinearDecayOUNoise):
        kind: type = type(action_noise)
        values: dict[str, Any] = dict(
            mean=action_noise.mean,
            sigma=action_noise.initial_sigma,
            final_sigma=action_noise.final_sigma,
            decay_episodes=action_noise.decay_episodes,
            theta=action_noise.theta,
            dt=action_noise.dt,
        )
    elif isinstance(action_noise, tuple(_CONSTANT_NOISES)):
        kind = next(sb3 for public, sb3 in _CONSTANT_NOISES.items() if isinstance(action_noise, public))
        values = dict(mean=action_noise.mean, sigma=action_noise.sigma)
        if isinstance(action_noise, OrnsteinUhlenbeckNoise):
            values.update(theta=action_noise.theta, dt=action_noise.dt)
    elif isinstance(action_noise, tuple(_CONSTANT_NOISES.values())):
        raise TypeError(
            f"Cannot read the settings of SB3's {type(action_noise).__name__}, which keeps them private: use "
            f"sb3_dtdpg.common.noise.{_public_noise_name(action_noise)}, the same noise with public settings"
        )
    else:
        raise TypeError(f"Cannot describe action noise of type {type(action_noise).__name__}")
    return {
        "type": f"{kind.__module__}.{kind.__qualname__}",
        **{
            key: np.asarray(value, dtype=np.float64).tolist() if isinstance(value, np.ndarray) else value
            for key, value in values.items()
        },
    }
