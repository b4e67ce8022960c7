"""Evaluation of learned models and planners on the mission environments.

The paper's test protocol (Section V, Table II) is 20 episodes with random (Rayleigh) fading, so
that is the default here: ``evaluate(model, "NomaRadioMap-v0")`` builds the env with
``channel="rayleigh"`` and runs 20 episodes, episode ``i`` reset with ``seed + i``. Seeding each
episode makes the missions (starts, destinations) and the fading draws the same for every policy
evaluated with the same seed, so two policies are compared on paired episodes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from scipy import stats

from sb3_dtdpg.common.checks import check_confidence
from sb3_dtdpg.env_settings import check_settings, trained_settings

__all__ = ["EvaluationResult", "Planner", "evaluate", "format_ci", "mean_ci", "robot_positions"]


@runtime_checkable
class Planner(Protocol):
    """
    A non-learning policy that may read the true state of the env (positions, radio map).

    ``evaluate`` calls ``reset(env)`` after every ``env.reset`` and ``act(env, observation)`` at every
    step, with ``env`` the unwrapped :class:`noma_radiomap.NomaRadioMapEnv`. Planners that only need
    the observation can implement SB3's ``predict`` instead and are evaluated like a model.
    """

    def reset(self, env: gym.Env) -> None: ...

    def act(self, env: gym.Env, observation: np.ndarray) -> np.ndarray: ...


def mean_ci(values: Sequence[float] | np.ndarray, confidence: float = 0.95) -> tuple[float, float]:
    """
    Mean and half-width of the two-sided Student-t confidence interval of the mean.

    :param values: samples (e.g. the MQI of each test episode, or each seed's mean)
    :param confidence: confidence level in (0, 1)
    :return: ``(mean, half_width)``; the half-width is ``nan`` for fewer than two samples
        and 0 when all samples are equal
    """
    check_confidence(confidence)
    x = np.asarray(values, dtype=np.float64).ravel()
    if x.size == 0:
        return math.nan, math.nan
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan
    sem = float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean, float(stats.t.ppf(0.5 + confidence / 2.0, df=x.size - 1) * sem)


def format_ci(value: float | None, half: float | None, digits: int = 1, scale: float = 1.0) -> str:
    """
    ``"mean ± half-width"`` for a table cell: ``"-"`` without a value, ``"mean ± n/a"`` when the CI is
    undefined (e.g. one seed).

    :param value: the mean
    :param half: the CI half-width
    :param digits: decimals
    :param scale: factor applied to both (e.g. 100 for percentages)
    :return: the cell text
    """
    if value is None or not np.isfinite(value):
        return "-"
    text = f"{value * scale:.{digits}f}"
    return text + (f" ± {half * scale:.{digits}f}" if half is not None and np.isfinite(half) else " ± n/a")


def robot_positions(env: gym.Env) -> np.ndarray:
    """
    Current (x, y) positions of the robots of a mission env, shape (U, 2), in metres.

    :param env: a (possibly wrapped) ``NomaRadioMapEnv``
    """
    return np.array(env.unwrapped.positions, dtype=np.float64).reshape(-1, 2)


@dataclass
class EvaluationResult:
    """
    Outcome of :func:`evaluate`.

    :param episodes: one record per episode (a list of flat dicts: ``pandas.DataFrame(result.episodes)``)
    :param trajectories: per episode, the robots' positions, shape (steps + 1, U, 2) (when requested)
    :param confidence: confidence level of the intervals in :meth:`summary`
    """

    episodes: list[dict[str, Any]]
    trajectories: list[np.ndarray] = field(default_factory=list)
    confidence: float = 0.95

    def _column(self, key: str) -> np.ndarray:
        return np.array([float(record[key]) for record in self.episodes])

    @property
    def n_episodes(self) -> int:
        return len(self.episodes)

    @property
    def success_rate(self) -> float:
        return float(self._column("success").mean())

    @property
    def mqi_mean(self) -> float:
        return mean_ci(self._column("mqi"), self.confidence)[0]

    @property
    def mqi_ci(self) -> float:
        """Half-width of the confidence interval of the mean MQI over episodes."""
        return mean_ci(self._column("mqi"), self.confidence)[1]

    def __repr__(self) -> str:
        """One line (the per-episode records are in ``episodes``, the means in :meth:`summary`)."""
        if not self.episodes:
            return "EvaluationResult(0 episodes)"
        summary = self.summary()
        return (
            f"EvaluationResult({self.n_episodes} episodes: success {100 * summary['success_rate']:.0f} %, "
            f"MQI {format_ci(summary['mqi'], summary['mqi_ci'])}, outage steps {summary['outage_steps']:.1f}, "
            f"mission time {summary['mission_time']:.1f}; .summary() for the means, .episodes for the records)"
        )

    def summary(self) -> dict[str, float]:
        """Means (and CI half-widths ``*_ci``) of the episode metrics, as a flat dict."""
        out: dict[str, float] = {"n_episodes": float(self.n_episodes), "success_rate": self.success_rate}
        for key in ("mqi", "outage_steps", "mission_time", "path_length", "episode_return"):
            out[key], out[f"{key}_ci"] = mean_ci(self._column(key), self.confidence)
        return out


#: What :func:`evaluate` says of an env that is not a mission env (the missions are what it measures)
_NOT_A_MISSION_ENV = (
    "evaluate measures the missions of noma_radiomap's envs (e.g. NomaRadioMap-v0); {name} is {kind}: use SB3's "
    "evaluate_policy for other envs"
)


def _check_mission_env(env: gym.Env, name: str) -> None:
    """:raises ValueError: ``env`` is not a mission env of ``noma_radiomap``, naming it"""
    from sb3_dtdpg.baselines import _is_mission

    if not _is_mission(env):
        raise ValueError(_NOT_A_MISSION_ENV.format(name=name, kind=f"a {type(env.unwrapped).__name__}"))


def _make_env(
    env_id_or_env: str | gym.Env,
    channel: str | None,
    multiple_access: str | None,
    env_kwargs: dict[str, Any] | None,
) -> tuple[gym.Env, bool]:
    if isinstance(env_id_or_env, str):
        kwargs = dict(env_kwargs or {})
        for name, wanted in (("channel", channel), ("multiple_access", multiple_access)):
            given = kwargs.get(name)
            if wanted is not None and given is not None and given != wanted:
                raise ValueError(f"{name}={wanted!r} and env_kwargs[{name!r}]={given!r}: give it once")
            if wanted is not None:
                kwargs[name] = wanted
        kwargs.setdefault("channel", "rayleigh")  # the test missions' channel, unless given either way
        from sb3_dtdpg.baselines import is_mission_env

        if not is_mission_env(env_id_or_env):  # it would not take the mission's keyword arguments
            raise ValueError(_NOT_A_MISSION_ENV.format(name=env_id_or_env, kind=f"{gym.spec(env_id_or_env).entry_point}"))
        return gym.make(env_id_or_env, **kwargs), True
    if not isinstance(env_id_or_env, gym.Env):
        raise ValueError(f"env_id_or_env must be an env id or a gymnasium.Env, got {type(env_id_or_env).__name__}")
    _check_mission_env(env_id_or_env, "the given env")
    if env_kwargs:
        raise ValueError(f"env_kwargs can only be used with an env id, got an env instance and env_kwargs={env_kwargs!r}")
    base = env_id_or_env.unwrapped
    for name, wanted in (("channel", channel), ("multiple_access", multiple_access)):
        actual = getattr(base, name, None)
        if wanted is not None and actual is not None and actual != wanted:
            raise ValueError(f"{name}={wanted!r} was requested but the given env was built with {name}={actual!r}")
    return env_id_or_env, False


def _policy_kind(policy: Any) -> str:
    if isinstance(policy, Planner):
        return "planner"
    if callable(getattr(policy, "predict", None)):  # SB3's PolicyPredictor protocol
        return "predictor"
    raise ValueError(
        f"policy must have predict(observation, ...) (an SB3 model) or reset(env)/act(env, observation) (a Planner), "
        f"got {type(policy).__name__}"
    )


def _episode_record(
    episode: int,
    seed: int,
    final_info: dict[str, Any],
    steps: int,
    episode_return: float,
    path: np.ndarray | None,
    destinations: np.ndarray,
) -> dict[str, Any]:
    outage = np.atleast_1d(np.asarray(final_info["outage_steps"], dtype=np.float64))
    mission_time = np.atleast_1d(np.asarray(final_info["mission_time"], dtype=np.float64))
    record: dict[str, Any] = {
        "episode": episode,
        "seed": seed,
        "success": bool(final_info["is_success"]),
        "mqi": float(final_info["mqi"]),
        "steps": steps,
        "episode_return": episode_return,
        # Mission time of the squad = when the last robot arrived (max_steps if one never did).
        "mission_time": float(mission_time.max()),
        "outage_steps": float(outage.sum()),
    }
    for u in range(outage.size):
        record[f"outage_steps_{u}"] = float(outage[u])
        record[f"mission_time_{u}"] = float(mission_time[u]) if mission_time.size > 1 else float(mission_time[0])
    for u, (x, y) in enumerate(np.asarray(destinations, dtype=np.float64).reshape(-1, 2)):
        record[f"destination_x_{u}"], record[f"destination_y_{u}"] = float(x), float(y)
    if path is not None:
        lengths = np.linalg.norm(np.diff(path, axis=0), axis=-1).sum(axis=0)
        record["path_length"] = float(lengths.sum())
        for u, length in enumerate(lengths):
            record[f"path_length_{u}"] = float(length)
    else:
        record["path_length"] = math.nan
    return record


def evaluate(
    policy: Any,
    env_id_or_env: str | gym.Env,
    n_episodes: int = 20,
    seed: int = 0,
    channel: str | None = None,
    multiple_access: str | None = None,
    deterministic: bool = True,
    options: dict[str, Any] | Sequence[dict[str, Any] | None] | None = None,
    env_kwargs: dict[str, Any] | None = None,
    return_trajectories: bool = False,
    confidence: float = 0.95,
) -> EvaluationResult:
    """
    Run a model or a planner for ``n_episodes`` missions and measure them.

    :param policy: an SB3 model (anything with SB3's ``predict``, see ``PolicyPredictor``) or a :class:`Planner`
    :param env_id_or_env: a registered env id (built with ``channel`` and ``multiple_access``) or an env
    :param n_episodes: number of test episodes (the paper uses 20)
    :param seed: episode ``i`` is reset with ``seed + i``, so missions and fading are reproducible and paired
    :param channel: ``"rayleigh"`` (random fading, the paper's test setting; the default for an env id, unless
        ``env_kwargs`` names one) or ``"radio_map"``; with an env instance it must be ``None`` or match the env's
    :param multiple_access: ``"noma"`` or ``"oma"``; ``None`` keeps the env's
    :param deterministic: passed to ``predict``; DT-DPG's, DDPG's and TD3's actors are deterministic either way
        (``predict`` adds no exploration noise), SAC's and TQC's sample their action when False
    :param options: ``reset`` options (fixed ``starts``/``destinations``), one dict for every episode or one per episode
    :param env_kwargs: extra ``gymnasium.make`` keyword arguments (with an env id only)
    :param return_trajectories: keep every episode's robot positions in ``result.trajectories``
    :param confidence: confidence level of the intervals
    :return: the per-episode records and their summary
    :raises sb3_dtdpg.env_settings.EnvSettingsMismatch: the model was trained with env settings (scenario,
        observation, multiple-access mode, task, power mapping: its own env's, else those its file recorded) other
        than the env's
    """
    if isinstance(n_episodes, bool) or not isinstance(n_episodes, (int, np.integer)) or n_episodes < 1:
        raise ValueError(f"n_episodes must be an integer >= 1, got {n_episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0 (episode i is reset with seed + i), got {seed!r}")
    seed = int(seed)  # Gymnasium takes Python integers only
    check_confidence(confidence)
    if options is not None and not isinstance(options, dict) and len(options) != n_episodes:
        raise ValueError(f"options must be one dict or one per episode ({n_episodes}), got {len(options)} entries")
    kind = _policy_kind(policy)
    env, owned = _make_env(env_id_or_env, channel, multiple_access, env_kwargs)
    result = EvaluationResult(episodes=[], confidence=confidence)
    try:
        # a model is only tested on an env with the settings it was trained with, as load() and set_env() check
        check_settings(trained_settings(policy), env, f"the {type(policy).__name__} model")
        for episode in range(n_episodes):
            episode_options = options if options is None or isinstance(options, dict) else options[episode]
            obs, _ = env.reset(seed=seed + episode, options=episode_options)
            if kind == "planner":
                policy.reset(env.unwrapped)
            path = [robot_positions(env)]
            state, episode_start = None, np.ones((1,), dtype=bool)
            episode_return, steps, done, info = 0.0, 0, False, {}
            while not done:
                if kind == "planner":
                    action = policy.act(env.unwrapped, obs)
                else:
                    action, state = policy.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)
                    episode_start = np.zeros((1,), dtype=bool)
                obs, reward, terminated, truncated, info = env.step(action)
                path.append(robot_positions(env))
                episode_return += float(reward)
                steps += 1
                done = terminated or truncated
            trajectory = np.stack(path)
            destinations = np.asarray(env.unwrapped.destinations)
            result.episodes.append(
                _episode_record(episode, seed + episode, info, steps, episode_return, trajectory, destinations)
            )
            if return_trajectories:
                result.trajectories.append(trajectory)
    finally:
        if owned:
            env.close()
    return result
