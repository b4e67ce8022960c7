"""The algorithm set compared on the mission environments (the paper's Sec. V; docs/RESULTS.md).

``make_env`` and ``make_model`` build every algorithm the same way, so that a comparison differs only
in the algorithm:

- ``"dtdpg"``: :class:`sb3_dtdpg.DTDPG` with the settings set's curriculum, "destination" then "mqi" (the env
  starts in "destination"; the curriculum switches it).
- ``"ddpg"``: plain SB3 ``DDPG``, the paper's comparison: a plain MLP of DT-DPG's sizes (no batch norm),
  *constant* OU noise of scale 0.5 (DT-DPG's initial scale, Table I), the ``"combined"`` reward (the
  paper's "contaminated" reward: inducing + QoS at once) and otherwise DT-DPG's settings set. It runs as
  :class:`~sb3_dtdpg.dtdpg.lean.LeanDDPG`, SB3's ``DDPG`` with DT-DPG's lean training step: the same parameters
  bit for bit as SB3's own ``DDPG`` (tested), in less time; its saved models load with SB3's ``DDPG.load``.
- ``"td3"``, ``"sac"`` (SB3) and ``"tqc"`` (sb3-contrib): the stronger learners a reviewer asks about,
  with SB3's defaults, the ``"combined"`` reward and, for TD3, Gaussian action noise of scale 0.1 (the RL
  Zoo's usual setting; SB3's TD3 has no exploration noise by default). Nothing else is tuned.

Every algorithm runs in NOMA and OMA mode (``multiple_access``) and gets the same budget (episodes).

The settings sets (``hyperparams``, ``--hyperparams`` of the CLI) are :mod:`sb3_dtdpg.presets`: ``"paper"``
(Table I) and ``"tuned"`` (the best measured settings on ``NomaRadioMap-v0``), the latter for ``dtdpg`` and
``ddpg`` only.
"""

from __future__ import annotations

import contextlib
import inspect
import warnings
from collections.abc import Iterator, Mapping
from typing import Any

import gymnasium as gym
from sb3_contrib import TQC
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor

import noma_radiomap  # noqa: F401  (registers the env ids)
from sb3_dtdpg import presets
from sb3_dtdpg.common.checks import check_action_noise, check_off_policy_settings
from sb3_dtdpg.dtdpg.dtdpg import DTDPG
from sb3_dtdpg.dtdpg.lean import LeanDDPG

__all__ = [
    "ALGORITHMS",
    "DDPG_KWARGS",
    "DDPG_OU_SIGMA",
    "DEFAULT_ENV_ID",
    "HYPERPARAMS",
    "TD3_NOISE_SIGMA",
    "TUNED_KWARGS",
    "algorithm_class",
    "base_learning_rate",
    "check_hyperparams",
    "check_training_budget",
    "default_observation_of",
    "final_reward_phase",
    "hyperparameter",
    "is_mission_env",
    "load_model",
    "make_env",
    "make_model",
    "mission_callbacks",
    "reward_phase",
]

ALGORITHMS: tuple[str, ...] = ("dtdpg", "ddpg", "td3", "sac", "tqc")
DEFAULT_ENV_ID = "NomaRadioMap-v0"
_CLASSES: dict[str, type[BaseAlgorithm]] = {"dtdpg": DTDPG, "ddpg": LeanDDPG, "td3": TD3, "sac": SAC, "tqc": TQC}
#: The hyperparameter sets of :func:`make_model` (:data:`sb3_dtdpg.presets.PRESETS`).
HYPERPARAMS: tuple[str, ...] = presets.PRESETS
# Names of the presets' values kept for readers of the former constants (the same objects, not copies):
#: :data:`sb3_dtdpg.presets.TUNED`
TUNED_KWARGS: dict[str, Any] = presets.TUNED
#: :data:`sb3_dtdpg.presets.TABLE_I`, the settings DDPG shares with DT-DPG under ``hyperparams="paper"``
DDPG_KWARGS: dict[str, Any] = presets.TABLE_I
#: Scale of DDPG's constant OU noise (:data:`sb3_dtdpg.presets.BASELINE_NOISE`)
DDPG_OU_SIGMA: float = presets.BASELINE_NOISE["ddpg"][1]
#: Scale of TD3's Gaussian exploration noise (:data:`sb3_dtdpg.presets.BASELINE_NOISE`)
TD3_NOISE_SIGMA: float = presets.BASELINE_NOISE["td3"][1]


def _check_algo(algo: str) -> str:
    if algo not in ALGORITHMS:
        raise ValueError(f"algo must be one of {ALGORITHMS}, got {algo!r}")
    return algo


def algorithm_class(algo: str) -> type[BaseAlgorithm]:
    """
    :param algo: one of :data:`ALGORITHMS`
    :return: the SB3 class of the algorithm (to ``load`` a saved model)
    """
    return _CLASSES[_check_algo(algo)]


def load_model(algo: str, path: Any, **kwargs: Any) -> BaseAlgorithm:
    """
    SB3's ``load`` of a saved model of ``algo``, without the warning SB3 2.9.2 gives on reloading its own n-step
    models ("`n_steps=3` is ignored because a custom `replay_buffer_class` ... was passed": the saved buffer
    settings are restored all the same).

    :param algo: one of :data:`ALGORITHMS`
    :param path: the zip
    :param kwargs: ``load``'s keyword arguments (``env``, ``device``, ``custom_objects``, settings)
    :return: the model
    """
    with without_n_step_load_warning():
        return algorithm_class(algo).load(path, **kwargs)


@contextlib.contextmanager
def without_n_step_load_warning() -> Iterator[None]:
    """Silence SB3 2.9.2's warning on loading its own n-step models (see :func:`load_model`) inside the block."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"`n_steps=\d+` is ignored because a custom `replay_buffer_class`")
        yield


def check_hyperparams(algo: str, hyperparams: str) -> None:
    """
    :param algo: one of :data:`ALGORITHMS`
    :param hyperparams: a name of :data:`HYPERPARAMS`
    :raises ValueError: when the set is unknown, or not defined for the algorithm
    """
    presets.check_preset(_check_algo(algo), hyperparams)


def hyperparameter(algo: str, name: str, hyperparams: str = "paper") -> Any:
    """
    :param algo: one of :data:`ALGORITHMS`
    :param name: a constructor argument of the algorithm (e.g. ``"learning_starts"``)
    :param hyperparams: one of :data:`HYPERPARAMS`
    :return: the value :func:`make_model` gives that argument when none is passed: the set's
        (:func:`sb3_dtdpg.presets.settings`), else the class default
    """
    values = presets.settings(_check_algo(algo), hyperparams)
    if name in values:
        return values[name]
    return inspect.signature(_CLASSES[algo]).parameters[name].default


def base_learning_rate(algo: str, hyperparams: str = "paper") -> float:
    """
    :param algo: one of :data:`ALGORITHMS`
    :param hyperparams: one of :data:`HYPERPARAMS`
    :return: the learning rate :func:`make_model` gives the algorithm when none is passed (a constant)
    """
    return hyperparameter(algo, "learning_rate", hyperparams)


def check_training_budget(total_timesteps: int, learning_starts: int, budget: str = "", hint: str = "") -> None:
    """
    The check that a training budget can train at all: SB3's off-policy algorithms take their first gradient
    step after ``learning_starts`` env steps, so a budget of at most that many steps only fills the replay
    buffer and leaves the networks as initialised.

    :param total_timesteps: the most env steps the run can take
    :param learning_starts: the model's ``learning_starts``
    :param budget: how the budget was given, for the message (default: ``"<total_timesteps> env steps"``)
    :param hint: what to change, appended to the message
    :raises ValueError: when ``total_timesteps <= learning_starts``
    """
    if total_timesteps <= learning_starts:
        raise ValueError(
            f"a training budget of {budget or f'{total_timesteps} env steps'} cannot train: the first gradient step "
            f"comes after learning_starts={learning_starts} steps" + (f"; {hint}" if hint else "")
        )


def reward_phase(algo: str) -> str:
    """
    :param algo: one of :data:`ALGORITHMS`
    :return: the env reward phase the algorithm starts in (DT-DPG's curriculum then switches it)
    """
    return "destination" if _check_algo(algo) == "dtdpg" else "combined"


def final_reward_phase(model: Any, algo: str) -> str | None:
    """
    :param model: a trained model
    :param algo: its algorithm (one of :data:`ALGORITHMS`)
    :return: the env reward phase it trained on last: a curriculum's current phase (DT-DPG), else the algorithm's
        (:func:`reward_phase`); None for a phase that leaves the env's reward alone
    """
    phases, state = getattr(model, "phases", None), getattr(model, "curriculum_state", None)
    if phases and state is not None:
        return phases[min(int(state["phase_index"]), len(phases) - 1)].reward_phase
    return reward_phase(algo)


def is_mission_env(env_id: str) -> bool:
    """
    :param env_id: a registered env id
    :return: whether it is one of the mission envs (:class:`noma_radiomap.NomaRadioMapEnv`), which take the
        mission options (``multiple_access``, ``channel``, ``scenario``, ``reward_phase``)
    :raises gymnasium.error.Error: when the id is not registered
    """
    from gymnasium.envs.registration import load_env_creator

    from noma_radiomap import NomaRadioMapEnv
    from noma_radiomap.registration import make_env as mission_entry_point

    entry_point = gym.spec(env_id).entry_point
    creator = load_env_creator(entry_point) if isinstance(entry_point, str) else entry_point
    if creator is mission_entry_point:  # the registered ids: the env in a TimeLimit of its scenario's length
        return True
    return isinstance(creator, type) and issubclass(creator, NomaRadioMapEnv)


def default_observation_of(env_id: str) -> str:
    """
    :param env_id: a registered mission env id
    :return: the observation layout ``gymnasium.make(env_id)`` gives: the id's own ``observation`` keyword, else
        the default of its task (:func:`noma_radiomap.observations.default_observation`: ``"paper"`` on the
        paper's task, ``"goal"`` otherwise)
    """
    from noma_radiomap.observations import default_observation

    kwargs = gym.spec(env_id).kwargs
    return kwargs.get("observation") or default_observation(kwargs.get("task", "missions"))


def make_env(
    algo: str,
    env_id: str = DEFAULT_ENV_ID,
    multiple_access: str | None = None,
    channel: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> gym.Env:
    """
    The training env of an algorithm, wrapped in a ``Monitor`` (episode returns for SB3's logger).

    A mission env (:func:`is_mission_env`) is built in the requested mode, starting in the algorithm's reward
    phase, and its ``Monitor`` also records ``is_success``. Any other registered env is built as it is
    (with ``env_kwargs``); the mission options must then be None.

    :param algo: one of :data:`ALGORITHMS`
    :param env_id: a registered env id
    :param multiple_access: mission envs: ``"noma"`` or ``"oma"`` (None: the env id's own)
    :param channel: mission envs: ``"radio_map"`` (the paper's training) or ``"rayleigh"`` ("reality" training)
        (None: the env id's own)
    :param env_kwargs: extra ``gymnasium.make`` keyword arguments (e.g. ``scenario``)
    :return: the env
    :raises ValueError: on mission options for another env, or an env whose actions are not continuous (every
        algorithm of the set acts in a ``Box``)
    """
    _check_algo(algo)
    mission_options = {"multiple_access": multiple_access, "channel": channel}
    if not is_mission_env(env_id):
        given = [name for name, value in mission_options.items() if value is not None]
        if given:
            raise ValueError(f"{env_id} is not a NomaRadioMap env: {', '.join(given)} apply to the mission envs only")
        env = gym.make(env_id, **(env_kwargs or {}))
        if not isinstance(env.action_space, gym.spaces.Box):
            env.close()
            raise ValueError(f"{env_id}: {algo} needs a continuous (Box) action space, the env has {env.action_space}")
        return Monitor(env)
    kwargs = {name: value for name, value in mission_options.items() if value is not None}
    kwargs.update(env_kwargs or {})
    kwargs["reward_phase"] = reward_phase(algo)
    return Monitor(gym.make(env_id, **kwargs), info_keywords=("is_success",))


#: Constructor arguments SB3 writes into (DDPG adds ``n_critics=1`` to ``policy_kwargs``, SAC and TQC ``use_sde``; an
#: n-step buffer of SB3's choice adds ``n_steps`` and ``gamma`` to ``replay_buffer_kwargs``): a model gets a copy.
_WRITTEN_BY_SB3 = ("policy_kwargs", "replay_buffer_kwargs")


def make_model(
    algo: str,
    env: gym.Env,
    seed: int | None = None,
    tensorboard_log: str | None = None,
    learning_rate: float | None = None,
    destination_episodes: int | None = None,
    verbose: int = 0,
    hyperparams: str = "paper",
    **kwargs: Any,
) -> BaseAlgorithm:
    """
    Build an algorithm of the set with its documented settings (see the module docstring).

    :param algo: one of :data:`ALGORITHMS`
    :param env: the training env (see :func:`make_env`; its reward phase must match the algorithm's)
    :param seed: seed of the model (and of its env)
    :param tensorboard_log: TensorBoard log folder (None: no logging)
    :param learning_rate: overrides the algorithm's learning rate (the paper's two-learning-rate experiment)
    :param destination_episodes: DT-DPG only: the episode budget of the destination phase (None: DTDPG's default)
    :param verbose: SB3 verbosity
    :param hyperparams: ``"paper"`` (Table I) or ``"tuned"`` (``dtdpg`` and ``ddpg`` only), :mod:`sb3_dtdpg.presets`;
        DT-DPG gets the set's mission curriculum on a mission env (on another env: the env's own or one phase)
    :param kwargs: further constructor arguments, passed on as is (``policy_kwargs`` and ``replay_buffer_kwargs`` as
        copies: SB3 adds its own keys to them, which would change the next model built from the caller's dict)
    :return: the (untrained) model
    """
    algo = _check_algo(algo)
    options = presets.model_kwargs(
        algo, hyperparams, env.action_space, destination_episodes=destination_episodes, curriculum=_is_mission(env)
    )
    if learning_rate is not None:
        options["learning_rate"] = learning_rate
    options.update(kwargs)
    check_off_policy_settings(algo, options)
    for name in _WRITTEN_BY_SB3:  # the caller's dicts stay as given (one dict may build several models)
        if isinstance(options.get(name), Mapping):
            options[name] = dict(options[name])
    check_action_noise(algo, options.get("action_noise"), env.action_space.shape)
    return _CLASSES[algo]("MlpPolicy", env, seed=seed, tensorboard_log=tensorboard_log, verbose=verbose, **options)


def _is_mission(env: gym.Env) -> bool:
    from noma_radiomap import NomaRadioMapEnv

    return isinstance(getattr(env, "unwrapped", None), NomaRadioMapEnv)


def mission_callbacks(model: BaseAlgorithm) -> list[BaseCallback]:
    """
    Callbacks to pass to ``learn`` so that every algorithm, DT-DPG included, logs the same ``mission/*`` scalars.

    :param model: a model built by :func:`make_model`
    :return: the callbacks
    """
    from sb3_dtdpg.missions import MissionLoggerCallback

    return [MissionLoggerCallback()]
