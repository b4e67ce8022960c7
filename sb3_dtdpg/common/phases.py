"""Training phases of DT-DPG's curriculum transfer (Algorithm 1 of the paper; docs/ARCHITECTURE.md)."""

import dataclasses
import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

ReplayHandling = Literal["keep", "clear", "relabel"]
REPLAY_HANDLINGS: tuple[str, ...] = ("keep", "clear", "relabel")


class _SameAsName:
    """Sentinel default of :attr:`Phase.reward_phase`: use the phase's own name."""

    def __repr__(self) -> str:
        return "<same as name>"


SAME_AS_NAME: Any = _SameAsName()


@dataclass(frozen=True)
class Phase:
    """
    One training phase ("training task" X of the paper's Algorithm 1).

    The budget is either ``n_episodes`` or ``n_timesteps``; only the last phase of a curriculum may have
    neither, it then lasts until ``learn()`` ends. A phase may end early when the success rate
    (``info["is_success"]`` at episode end) over its last ``success_window`` episodes reaches
    ``success_threshold``.

    :param name: Name of the phase (used in logs and checkpoint file names).
    :param reward_phase: Reward phase of the env set by ``env.set_reward_phase`` during this phase.
        Defaults to ``name``; ``None`` leaves the env alone (for envs without reward phases).
    :param n_episodes: Budget in finished episodes (counted over all envs of a vectorized env).
    :param n_timesteps: Budget in env steps (counted over all envs, like ``model.num_timesteps``).
    :param sigma: Initial OU noise scale of the phase, i.e. :math:`\\xi(X, 0)` of the paper;
        ``None`` leaves the model's action noise untouched.
    :param final_sigma: Noise scale reached after ``decay_episodes`` episodes (linear decay per episode);
        ``None`` keeps ``sigma`` constant.
    :param decay_episodes: Length of the linear decay in episodes; defaults to ``n_episodes`` (or 1 when the
        phase has no episode budget and no decay, which makes it irrelevant).
    :param success_threshold: Early-transfer threshold on the success rate in ``(0, 1]``; ``None`` disables it.
    :param success_window: Number K of most recent episodes of the phase over which the success rate is taken
        (a window longer than ``n_episodes`` never fills: warned, as the early transfer then never happens).
    :param replay_handling: What happens to the replay buffer when *entering* this phase: ``"keep"`` it,
        ``"clear"`` it, or ``"relabel"`` every stored reward for this phase from the stored reward components
        (needs :class:`sb3_dtdpg.common.buffers.RewardComponentsReplayBuffer`). Ignored for the first phase.
    """

    name: str
    reward_phase: str | None = SAME_AS_NAME
    n_episodes: int | None = None
    n_timesteps: int | None = None
    sigma: float | None = None
    final_sigma: float | None = None
    decay_episodes: int | None = None
    success_threshold: float | None = None
    success_window: int = 20
    replay_handling: ReplayHandling = "keep"

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):  # numpy numbers as the Python numbers they hold (JSON, identities)
            value = getattr(self, field.name)
            if isinstance(value, (np.integer, np.floating)):
                object.__setattr__(self, field.name, value.item())
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Phase.name must be a non-empty string, got {self.name!r}")
        where = f"Phase {self.name!r}"
        if self.reward_phase is SAME_AS_NAME:
            object.__setattr__(self, "reward_phase", self.name)
        elif self.reward_phase is not None and (not isinstance(self.reward_phase, str) or not self.reward_phase):
            raise ValueError(f"{where}: reward_phase must be a non-empty string or None, got {self.reward_phase!r}")
        for key in ("n_episodes", "n_timesteps", "decay_episodes"):
            _check_int(where, key, getattr(self, key), optional=True)
        _check_int(where, "success_window", self.success_window, optional=False)
        if self.n_episodes is not None and self.n_timesteps is not None:
            raise ValueError(
                f"{where}: give one budget, n_episodes or n_timesteps, not both "
                f"(n_episodes={self.n_episodes!r}, n_timesteps={self.n_timesteps!r})"
            )
        for key in ("sigma", "final_sigma"):
            value = getattr(self, key)
            if value is not None and (not _is_real(value) or value < 0):
                raise ValueError(f"{where}: {key} must be a finite number >= 0 or None, got {value!r}")
        if self.final_sigma is not None and self.sigma is None:
            raise ValueError(f"{where}: final_sigma={self.final_sigma!r} needs an initial sigma, got sigma=None")
        threshold = self.success_threshold
        if threshold is not None and (not _is_real(threshold) or not 0 < threshold <= 1):
            raise ValueError(f"{where}: success_threshold must be in (0, 1] or None, got {threshold!r}")
        if threshold is not None and self.n_episodes is not None and self.success_window > self.n_episodes:
            warnings.warn(
                f"{where}: success_window={self.success_window} is longer than the phase's "
                f"n_episodes={self.n_episodes}: the early transfer at success_threshold={threshold} can never "
                "happen (give n_episodes >= success_window or a shorter success_window)",
                stacklevel=3,
            )
        if self.replay_handling not in REPLAY_HANDLINGS:
            raise ValueError(f"{where}: replay_handling must be one of {REPLAY_HANDLINGS}, got {self.replay_handling!r}")

    @property
    def has_budget(self) -> bool:
        """Whether the phase ends on its own (an episode or timestep budget)."""
        return self.n_episodes is not None or self.n_timesteps is not None

    def noise_schedule(self) -> tuple[float, float, int] | None:
        """
        :return: ``(sigma, final_sigma, decay_episodes)`` with the defaults filled in,
            or ``None`` when the phase leaves the action noise untouched.
        """
        if self.sigma is None:
            return None
        final_sigma = self.sigma if self.final_sigma is None else self.final_sigma
        decay_episodes = self.decay_episodes if self.decay_episodes is not None else self.n_episodes
        if decay_episodes is None:
            if final_sigma != self.sigma:
                raise ValueError(
                    f"Phase {self.name!r}: a decay from sigma={self.sigma!r} to final_sigma={final_sigma!r} "
                    "needs decay_episodes (or an n_episodes budget)"
                )
            decay_episodes = 1
        return float(self.sigma), float(final_sigma), int(decay_episodes)

    def to_dict(self) -> dict[str, Any]:
        """
        :return: A plain dict (JSON/YAML friendly) that :func:`parse_phases` turns back into this phase.
        """
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Phase":
        """
        Build a phase from a dict (e.g. a YAML or RL Zoo hyperparameter file).

        :param data: Keys are the constructor arguments; ``name`` is required.
        :return: The phase.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"a phase must be a Phase or a dict, got {type(data).__name__}: {data!r}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(data) - set(known))
        if unknown:
            raise ValueError(f"unknown phase key(s) {unknown} in {dict(data)!r}; known keys: {known}")
        if "name" not in data:
            raise ValueError(f"a phase needs a 'name', got {dict(data)!r}")
        return cls(**data)


def _is_real(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_int(where: str, key: str, value: Any, optional: bool) -> None:
    if value is None and optional:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{where}: {key} must be a positive integer{' or None' if optional else ''}, got {value!r}")


def parse_phases(phases: Iterable[Phase | Mapping[str, Any]]) -> list[Phase]:
    """
    Validate a curriculum.

    :param phases: Phases in training order, as :class:`Phase` objects or dicts of their fields.
    :return: The list of phases.
    """
    if isinstance(phases, (Phase, Mapping, str)):
        raise ValueError(f"phases must be a sequence of phases, got {type(phases).__name__}: {phases!r}")
    parsed = [phase if isinstance(phase, Phase) else Phase.from_dict(phase) for phase in phases]
    if not parsed:
        raise ValueError("phases must hold at least one phase, got an empty sequence")
    names = [phase.name for phase in parsed]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(f"phase names must be unique, got {names} (repeated: {duplicates})")
    for index, phase in enumerate(parsed[:-1]):
        if not phase.has_budget:
            raise ValueError(
                f"phases[{index}] ({phase.name!r}) has no budget: only the last phase may leave "
                "n_episodes and n_timesteps unset"
            )
    for phase in parsed:
        phase.noise_schedule()  # raises on an incomplete decay schedule
    return parsed


def check_env_phases(phases: Sequence[Phase], env: Any) -> None:
    """
    :param phases: a curriculum
    :param env: the training env (an SB3 ``VecEnv``)
    :raises ValueError: the phases set reward phases and the env has no ``set_reward_phase``, or a phase's reward phase
        is not among the env's ``REWARD_PHASES`` (naming the phase and the reward phase)
    """
    reward_phases = sorted({phase.reward_phase for phase in phases if phase.reward_phase is not None})
    if not reward_phases:
        return
    if not env.has_attr("set_reward_phase"):
        raise ValueError(
            f"the phases use the env reward phases {reward_phases}, but the env has no set_reward_phase(); "
            "for an env without reward phases give the phases reward_phase=None (e.g. single_phase())"
        )
    if not env.has_attr("REWARD_PHASES"):
        return
    known = list(env.get_attr("REWARD_PHASES", indices=[0])[0])
    for phase in phases:
        if phase.reward_phase is not None and phase.reward_phase not in known:
            raise ValueError(
                f"phase {phase.name!r}: reward_phase {phase.reward_phase!r} is not a reward phase of the env {known}"
            )


def single_phase(
    sigma: float | None = None, final_sigma: float | None = None, decay_episodes: int | None = None
) -> list[Phase]:
    """
    A one-phase curriculum for envs without reward phases (the env's reward is left alone).

    :param sigma: Initial OU noise scale (``None``: leave the action noise untouched).
    :param final_sigma: Final noise scale of the linear decay (``None``: constant).
    :param decay_episodes: Length of the decay in episodes.
    :return: The single phase.
    """
    return parse_phases(
        [Phase("train", reward_phase=None, sigma=sigma, final_sigma=final_sigma, decay_episodes=decay_episodes)]
    )


#: The noise of the single phase of :func:`default_curriculum`: the paper's initial OU scale, decaying to 0.1 over
#: 300 episodes.
SINGLE_PHASE_NOISE: tuple[float, float, int] = (0.5, 0.1, 300)


def default_curriculum(env: Any) -> list[Phase]:
    """
    The curriculum ``DTDPG(phases=None)`` trains through.

    :param env: the training env (an SB3 ``VecEnv``), or None
    :return: the env's own curriculum when it offers one (an attribute ``default_curriculum``: a sequence of
        :class:`Phase` objects or dicts of their fields, or a method returning one), else a single phase that
        leaves the env's reward alone, with OU noise decaying from 0.5 to 0.1 over 300 episodes
    """
    if env is not None and env.has_attr("default_curriculum"):
        offered = env.get_attr("default_curriculum", indices=[0])[0]
        return parse_phases(offered() if callable(offered) else offered)
    sigma, final_sigma, decay_episodes = SINGLE_PHASE_NOISE
    return single_phase(sigma=sigma, final_sigma=final_sigma, decay_episodes=decay_episodes)
