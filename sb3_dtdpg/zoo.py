"""
RL Baselines3 Zoo integration: DT-DPG as one of the zoo's algorithms.

Custom algorithms join the zoo by adding themselves to its tables before its ``train()``/``enjoy()`` run
(the pattern sbx documents): :func:`register_dtdpg` adds ``"dtdpg"`` to ``rl_zoo3.ALGOS``, its Optuna
sampler to ``HYPERPARAMS_SAMPLER`` (``--optimize``) and its converter to ``HYPERPARAMS_CONVERTER``
(``--trial-id``, which reads a stored trial's raw parameters back through the converter).
Importing this module also imports :mod:`noma_radiomap`, so the NomaRadioMap env ids need no ``--gym-packages``.

:class:`ExperimentManager` is the zoo's own with a few fixes and the package's default configs, used by
``python -m sb3_dtdpg.train`` (see its docstring). This module needs the ``zoo`` extra
(``pip install -e ".[zoo]"`` in a clone of the repository); without it, importing it raises an ``ImportError``
that says so.
"""

import collections
import dataclasses
import sys
import warnings
from pathlib import Path
from typing import Any

try:
    import optuna
    import rl_zoo3
    import rl_zoo3.exp_manager
    from rl_zoo3.hyperparams_opt import HYPERPARAMS_CONVERTER, HYPERPARAMS_SAMPLER
except ModuleNotFoundError as error:
    raise ModuleNotFoundError(
        f"the RL Zoo integration of sb3-dtdpg needs the 'zoo' extra ({error.name} is not installed): "
        'pip install -e ".[zoo]" in your clone of the repository',
        name=error.name,
    ) from error

import noma_radiomap  # noqa: F401  (registers the NomaRadioMap env ids)
from sb3_dtdpg.baselines import check_training_budget
from sb3_dtdpg.common.phases import REPLAY_HANDLINGS
from sb3_dtdpg.dtdpg import DTDPG
from sb3_dtdpg.env_settings import record
from sb3_dtdpg.missions import default_phases
from sb3_dtdpg.overrides import HyperparameterError

ALGO_NAME = "dtdpg"


class ZooOptionError(ValueError):
    """Zoo flags that cannot run together (``python -m sb3_dtdpg.train`` prints it as one ``error:`` line, exit 2)."""


# Hidden layers (actor and critic alike). The paper uses 64-128 units per layer (Section V).
NET_ARCHS: dict[str, list[int]] = {
    "64-64": [64, 64],
    "128-64": [128, 64],
    "128-128": [128, 128],
    "256-256": [256, 256],
}
# Early transfer out of the destination phase: success rate over the last episodes (None: budget only).
EARLY_TRANSFER_THRESHOLDS: tuple[float | None, ...] = (None, 0.8, 0.9, 0.95)


def sample_dtdpg_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    Sampler for DT-DPG hyperparameters (``--optimize --algo dtdpg``), built like the zoo's TD3 sampler.

    Besides DDPG's learning rate, discount, tau, batch size and network size it searches DT-DPG's own
    settings: the destination phase's episode budget and early-transfer threshold, both phases' initial
    OU noise scales, the MQI phase's noise-decay horizon and the replay handling when entering it.
    Phase budgets are in episodes (at most ``max_episode_steps`` env steps each): give the trials an
    ``-n`` that covers them, or the MQI phase is never reached.

    :param trial: Optuna trial.
    :param n_actions: Action dimension (unused: DT-DPG builds its own noise from the phases).
    :param n_envs: Number of training envs (unused).
    :param additional_args: The zoo's extra arguments (HER settings; unused).
    :return: ``DTDPG`` keyword arguments, :func:`convert_dtdpg_params` of the trial's raw parameters.
    """
    params: dict[str, Any] = {
        # The paper's range is 1e-5 to 1e-3 (Section V).
        "learning_rate": trial.suggest_float("learning_rate", 1e-5, 1e-3, log=True),
        "one_minus_gamma": trial.suggest_float("one_minus_gamma", 1e-4, 0.05, log=True),
        "tau": trial.suggest_float("tau", 5e-4, 0.05, log=True),
        # 2**5=32 to 2**8=256
        "batch_size_pow": trial.suggest_int("batch_size_pow", 5, 8),
        "net_arch": trial.suggest_categorical("net_arch", list(NET_ARCHS)),
        "phase1_episodes": trial.suggest_int("phase1_episodes", 20, 500, log=True),
        "phase1_sigma": trial.suggest_float("phase1_sigma", 0.1, 0.8),
        "success_threshold": trial.suggest_categorical("success_threshold", EARLY_TRANSFER_THRESHOLDS),
        "phase2_sigma": trial.suggest_float("phase2_sigma", 0.05, 0.6),
        "phase2_decay_episodes": trial.suggest_int("phase2_decay_episodes", 20, 500, log=True),
        "replay_handling": trial.suggest_categorical("replay_handling", REPLAY_HANDLINGS),
    }
    hyperparams = convert_dtdpg_params(params)
    trial.set_user_attr("gamma", hyperparams["gamma"])
    trial.set_user_attr("batch_size", hyperparams["batch_size"])
    return hyperparams


def convert_dtdpg_params(sampled_params: dict[str, Any]) -> dict[str, Any]:
    """
    Turn a DT-DPG trial's raw parameters into ``DTDPG`` keyword arguments
    (the counterpart of the zoo's ``convert_offpolicy_params``).

    The phases are the paper's two (:func:`sb3_dtdpg.missions.default_phases`) with the sampled
    budget, threshold, noise scales and replay handling, as plain dicts so that the zoo's saved
    ``config.yml`` stays readable YAML.

    :param sampled_params: ``trial.params`` of a trial sampled by :func:`sample_dtdpg_params`.
    :return: ``DTDPG`` keyword arguments.
    """
    params = dict(sampled_params)
    try:
        net_arch_name = params.pop("net_arch")
        if net_arch_name not in NET_ARCHS:
            raise ValueError(f"net_arch must be one of {list(NET_ARCHS)}, got {net_arch_name!r}")
        destination, mqi = default_phases(
            destination_episodes=params.pop("phase1_episodes"),
            success_threshold=params.pop("success_threshold"),
            replay_handling=params.pop("replay_handling"),
        )
        phases = [
            dataclasses.replace(destination, sigma=params.pop("phase1_sigma")),
            dataclasses.replace(mqi, sigma=params.pop("phase2_sigma"), decay_episodes=params.pop("phase2_decay_episodes")),
        ]
        hyperparams = {
            "learning_rate": params.pop("learning_rate"),
            "gamma": 1 - params.pop("one_minus_gamma"),
            "tau": params.pop("tau"),
            "batch_size": 2 ** params.pop("batch_size_pow"),
            "policy_kwargs": {"net_arch": list(NET_ARCHS[net_arch_name])},
            "phases": [phase.to_dict() for phase in phases],
        }
    except KeyError as e:
        raise ValueError(f"DT-DPG search parameter {e.args[0]!r} is missing from {sampled_params!r}") from e
    if params:
        raise ValueError(f"unknown DT-DPG search parameter(s) {sorted(params)} in {sampled_params!r}")
    return hyperparams


def register_dtdpg() -> None:
    """
    Add DT-DPG to the RL Zoo's algorithms, samplers and converters (idempotent).
    ``rl_zoo3.train``, ``rl_zoo3.enjoy`` and ``rl_zoo3.exp_manager`` all share these dicts.
    """
    rl_zoo3.ALGOS[ALGO_NAME] = DTDPG
    HYPERPARAMS_SAMPLER[ALGO_NAME] = sample_dtdpg_params
    HYPERPARAMS_CONVERTER[ALGO_NAME] = convert_dtdpg_params


def config_dir() -> Path:
    """
    :return: the folder of the package's RL Zoo configs (``zoo_configs/*.yml``): inside the installed package
        (``sb3_dtdpg/zoo_configs``), or the top-level ``zoo_configs/`` of a source checkout
    """
    packaged = Path(__file__).with_name("zoo_configs")
    return packaged if packaged.is_dir() else Path(__file__).resolve().parents[1] / "zoo_configs"


def default_config(algo: str, env_id: str) -> Path | None:
    """
    The package's config that ``python -m sb3_dtdpg.train`` uses when ``--conf-file`` is omitted.

    :param algo: the zoo's algorithm name (``dtdpg``, ``ddpg``, ...)
    :param env_id: the env id
    :return: the first of ``<config_dir>/<algo>.yml`` and ``<config_dir>/<algo>_paper.yml`` (the paper's task:
        ``NomaRadioMapPaper-v0``, ``NomaRadioMapPaperOMA-v0``) that has an entry for ``env_id``; else
        ``<algo>.yml`` for ``dtdpg`` (the zoo has none), None for the other algorithms (the zoo's own default
        file applies)
    """
    for path in (config_dir() / f"{algo}.yml", config_dir() / f"{algo}_paper.yml"):
        if path.is_file() and env_id in _config_entries(path):
            return path
    path = config_dir() / f"{algo}.yml"
    return path if algo == ALGO_NAME and path.is_file() else None


def _config_entries(path: str | Path) -> dict[str, Any]:
    """:return: the entries of a YAML hyperparameter file, by env id"""
    import yaml

    with open(path) as f:
        entries = yaml.safe_load(f) or {}
    return entries if isinstance(entries, dict) else {}


class _TrialNumber(int):
    """A trial number that is truthy even when it is 0 (see :class:`ExperimentManager`)."""

    def __bool__(self) -> bool:
        return True


class ExperimentManager(rl_zoo3.exp_manager.ExperimentManager):
    """
    The RL Zoo's experiment manager (same arguments), with the package's default configs and these fixes
    for rl_zoo3 2.9:

    - Without ``config`` (``--conf-file``), the package's ``zoo_configs/<algo>.yml`` is used (:func:`default_config`):
      always for ``dtdpg``, for the zoo's algorithms when it has an entry for the env; ``<algo>_paper.yml`` for the
      paper's task (``NomaRadioMapPaper-v0``, ``NomaRadioMapPaperOMA-v0``).
    - A YAML file without an entry for the env id is a :class:`ZooOptionError` that names the file's env ids
      (the zoo's own error is a traceback).
    - ``env_kwargs`` (``--env-kwargs``) are merged into the ``env_kwargs`` of the hyperparameter file instead of
      replacing them (``--env-kwargs multiple_access:"'oma'"`` keeps the file's ``reward_phase``);
      ``eval_env_kwargs`` (``--eval-env-kwargs``) are merged over the result the same way.
    - ``env_kwargs`` from the hyperparameter file also reach the evaluation env, as the zoo intends ("use
      env-kwargs if eval_env_kwargs was not specified"); in 2.9 they only did when ``--env-kwargs`` was given
      too, so e.g. DDPG's ``reward_phase: combined`` was evaluated on the env's default reward.
    - ``--trial-id 0`` (the first trial of a study) is honoured: the zoo tests ``self.trial_id`` for truth,
      so trial 0 was silently skipped and the YAML defaults trained instead (DLR-RM/rl-baselines3-zoo#498).
      ``--trial-id`` without ``--storage`` and ``--study-name`` is an error instead of being ignored.
    - A budget that cannot train (``n_timesteps <= learning_starts``) is an error
      (:func:`sb3_dtdpg.baselines.check_training_budget`).
    - A search worker that joins a shared study (``--storage``, ``--study-name``) whose ``--max-total-trials`` are all
      taken, none completed and some still running, ends with a line that says so (the zoo read ``study.best_trial``
      of a study without a completed trial: a traceback); a stored study whose trials all ended without completing
      is an error line.

    Every saved model records the env settings it was trained with (:func:`sb3_dtdpg.env_settings.record`), so
    ``sb3-dtdpg evaluate`` / ``enjoy`` refuse a mismatched env for SB3's algorithms too. For DT-DPG training runs it
    also puts the curriculum's phase checkpoints (``phase_<k>_<name>.zip``)
    in the run's log folder, unless the hyperparameters set ``curriculum_save_path`` themselves.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if kwargs.get("config") is None:
            path = default_config(self.algo, self.env_name.gym_id)
            if path is not None:
                self.config = str(path)
        if self.trial_id is not None:
            if not (self.storage and self.study_name):
                raise ZooOptionError(
                    f"--trial-id {self.trial_id} needs --storage and --study-name to find the trial, "
                    f"got storage={self.storage!r}, study_name={self.study_name!r}"
                )
            self.trial_id = _TrialNumber(self.trial_id)

    def load_trial(self, storage: str, study_name: str, trial_id: int | None = None, convert: bool = True) -> dict[str, Any]:
        """The zoo's ``load_trial``, its failures named in one error line: a missing ``.log`` storage (the zoo made an
        empty one), a study that is not there, a trial number that is not one of the study's."""
        if storage.endswith(".log") and not Path(storage).is_file():
            raise ZooOptionError(f"--storage {storage}: no such JournalFile (the .log file of an earlier search)")
        if trial_id is not None and trial_id < 0:
            raise ZooOptionError(f"--trial-id must be a trial number >= 0, got {int(trial_id)}")
        try:
            return super().load_trial(storage, study_name, trial_id, convert)
        except KeyError:
            raise ZooOptionError(f"--study-name {study_name!r}: no such study in --storage {storage}") from None
        except IndexError:
            n_trials = len(optuna.load_study(storage=self._optuna_storage(storage), study_name=study_name).trials)
            raise ZooOptionError(
                f"--trial-id {int(trial_id)}: the study {study_name!r} has {n_trials} trials (numbers 0 to {n_trials - 1})"
            ) from None

    @staticmethod
    def _optuna_storage(storage: str) -> Any:
        """The storage as the zoo opens it (a ``.log`` path: a JournalFile)."""
        if storage.endswith(".log"):
            return optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(storage))
        return storage

    def _check_config_entry(self) -> None:
        """The hyperparameter file's mistakes, each one error line before the log folder exists (the zoo's own errors
        are tracebacks): a ``--conf-file`` that is not there or not YAML, no entry for the env id (nor a ``default``
        one: the error names the file's env ids), an entry that is not a mapping of hyperparameters."""
        import yaml

        config = str(self.config)
        if config.endswith((".yml", ".yaml", ".py")) and not Path(config).is_file():
            raise ZooOptionError(f"--conf-file {config}: no such file")
        if not config.endswith((".yml", ".yaml")) or self._is_atari:
            return
        try:
            entries = _config_entries(config)
        except yaml.YAMLError as error:
            raise ZooOptionError(f"--conf-file {config} is not valid YAML: {' '.join(str(error).split())}") from None
        env_id = self.env_name.gym_id
        if env_id not in entries and "default" not in entries:
            raise ZooOptionError(
                f"--env {env_id}: {config} has no entry for it (its env ids: {', '.join(map(str, entries)) or 'none'}); "
                f"give one of them with --env, or another --conf-file"
            )
        name = env_id if env_id in entries else "default"
        if not isinstance(entries[name], dict):
            raise HyperparameterError(
                f"the entry {name} in {config} must be a mapping of hyperparameters (key: value lines indented under "
                f"it), got {entries[name]!r}"
            )

    def _check_zoo_hyperparams(self, hyperparams: dict[str, Any]) -> None:
        """The hyperparameters the zoo itself reads, checked before it uses them (its errors are tracebacks, some after
        the log folder was created): ``n_timesteps`` (unless ``-n``), ``n_envs``, and the class paths of ``policy``,
        ``env_wrapper``, ``vec_env_wrapper`` and ``callback``, which must import (and take the keyword arguments
        given with them)."""
        where = f" (env {self.env_name.gym_id} in {self.config}, or -params)"
        if self.n_timesteps <= 0:
            n_timesteps = hyperparams.get("n_timesteps")
            if n_timesteps is None:
                raise HyperparameterError(f"n_timesteps is missing{where}: give it in the file's entry or with -n")
            if isinstance(n_timesteps, bool) or not isinstance(n_timesteps, int | float):
                raise HyperparameterError(f"n_timesteps must be a number{where}, got {n_timesteps!r}")
        n_envs = hyperparams.get("n_envs", 1)
        if isinstance(n_envs, bool) or not isinstance(n_envs, int) or n_envs < 1:
            raise HyperparameterError(f"n_envs must be an integer >= 1{where}, got {n_envs!r}")
        policy = hyperparams.get("policy")
        if isinstance(policy, str) and "." in policy:  # a class path, not a name such as MlpPolicy
            _check_class_path(policy, {}, f"policy {policy!r}{where}", positional=3)  # spaces and lr schedule
        for key in ("env_wrapper", "vec_env_wrapper", "callback"):
            for name, kwargs in _class_paths(hyperparams.get(key), f"{key}{where}"):
                _check_class_path(name, kwargs, f"{key} {name!r}{where}", positional=int(key != "callback"))

    def read_hyperparameters(self) -> tuple[dict[str, Any], dict[str, Any]]:
        self._check_config_entry()
        # The zoo replaces the file's env_kwargs by --env-kwargs when both exist: hide ours from it, then merge.
        cli_env_kwargs, self.env_kwargs = self.env_kwargs, {}
        try:
            hyperparams, saved_hyperparams = super().read_hyperparameters()
        finally:
            self.env_kwargs = cli_env_kwargs
        file_env_kwargs = hyperparams.get("env_kwargs") or {}
        if not isinstance(file_env_kwargs, dict):
            raise HyperparameterError(f"env_kwargs in {self.config} must be a mapping, got {file_env_kwargs!r}")
        env_kwargs = {**file_env_kwargs, **cli_env_kwargs}
        if env_kwargs:
            hyperparams["env_kwargs"] = saved_hyperparams["env_kwargs"] = env_kwargs
        self.env_kwargs = env_kwargs
        self.eval_env_kwargs = {**env_kwargs, **(self._eval_env_kwargs_args or {})}
        return hyperparams, saved_hyperparams

    def _preprocess_hyperparams(self, hyperparams: dict[str, Any]) -> tuple[Any, ...]:
        self._check_zoo_hyperparams(hyperparams)
        learning_starts = hyperparams.get("learning_starts")
        hyperparams, *others = super()._preprocess_hyperparams(hyperparams)
        if learning_starts is None:
            learning_starts = _default_learning_starts(rl_zoo3.ALGOS[self.algo])
        if learning_starts is not None:
            try:
                check_training_budget(
                    self.n_timesteps,
                    learning_starts,
                    f"n_timesteps={self.n_timesteps}",
                    "raise n_timesteps (-n) or lower learning_starts (-params learning_starts:<steps>)",
                )
            except ValueError as error:  # python -m sb3_dtdpg.train prints it as one error line
                raise HyperparameterError(str(error)) from None
        self.eval_env_kwargs = {**self.env_kwargs, **(self._eval_env_kwargs_args or {})}
        if self.algo == ALGO_NAME and not self.optimize_hyperparameters:
            hyperparams.setdefault("curriculum_save_path", self.save_path)
        elif self.algo == ALGO_NAME and hyperparams.pop("curriculum_save_path", None) is not None:
            # every trial would save its phase models there: the second would be refused (another run's files)
            warnings.warn(
                "curriculum_save_path is left out of a hyperparameter search: its trials save no phase models",
                UserWarning,
                stacklevel=2,
            )
        return (hyperparams, *others)

    def hyperparameters_optimization(self) -> None:
        """The zoo's search; for ``dtdpg`` only on an env with reward phases (the sampler builds the mission's two)."""
        if self.algo == ALGO_NAME:
            import gymnasium as gym

            env = gym.make(self.env_name.gym_id, **(self.env_kwargs or {}))
            has_phases = hasattr(env.unwrapped, "set_reward_phase")
            env.close()
            if not has_phases:
                raise ZooOptionError(
                    f"-optimize with --algo dtdpg samples the mission's two reward phases (destination, mqi), and "
                    f"{self.env_name.gym_id} has no reward phases: search on a NomaRadioMap env"
                )
        try:
            super().hyperparameters_optimization()
        except ValueError as error:
            if "No trials are completed yet" not in str(error):  # only the zoo's study.best_trial, not a trial's error
                raise
            states = self._trial_states()
            if states is None:
                raise
            counts = ", ".join(f"{n} {state.lower()}" for state, n in sorted(states.items())) or "no trials"
            taken = sum(states.get(state, 0) for state in ("COMPLETE", "RUNNING", "PRUNED"))
            if self.max_total_trials is None or taken < self.max_total_trials or not states.get("RUNNING"):
                message = f"no trial of the study {self.study_name!r} completed ({counts}): no best trial"
                raise ZooOptionError(message) from error
            print(
                f"No trial of the study {self.study_name!r} has completed yet ({counts}) and its --max-total-trials "
                f"{self.max_total_trials} are all taken: no best trial to report yet (the worker that finishes last "
                "reports it)",
                file=sys.stderr,
            )

    def _trial_states(self) -> dict[str, int] | None:
        """:return: the number of the study's trials in each state (``{"RUNNING": 2}``), None without a storage"""
        if self.storage is None or self.study_name is None:
            return None
        study = optuna.load_study(storage=self._optuna_storage(self.storage), study_name=self.study_name)
        return dict(collections.Counter(trial.state.name for trial in study.trials))

    def _save_config(self, saved_hyperparams: dict[str, Any]) -> None:
        # The zoo's enjoy lets args.yml's env_kwargs replace config.yml's: args.yml gets the merged ones
        if getattr(self.args, "env_kwargs", None) is not None:
            self.args.env_kwargs = dict(self.env_kwargs)
        super()._save_config(saved_hyperparams)

    def setup_experiment(self) -> tuple[Any, dict[str, Any]] | None:
        """The zoo's set-up, the env settings recorded in the new model: every zip saved during training (the
        ``EvalCallback``'s ``best_model.zip``, the checkpoints) says what it trains on, for every algorithm."""
        experiment = super().setup_experiment()
        if experiment is not None:
            record(experiment[0])
        return experiment

    def save_trained_model(self, model: Any) -> None:
        """Save as the zoo does, with the env settings recorded for every algorithm (DTDPG's ``save`` does it too)."""
        record(model)
        super().save_trained_model(model)


def _default_learning_starts(algo_class: type) -> int | None:
    import inspect

    parameter = inspect.signature(algo_class).parameters.get("learning_starts")
    return None if parameter is None else parameter.default


def _class_paths(value: Any, what: str) -> list[tuple[str, dict[str, Any]]]:
    """
    :param value: a zoo hyperparameter that names classes (``callback``, ``env_wrapper``, ...): None, a class path, a
        ``{path: kwargs}`` mapping, or a list of them (a class or callback object in a ``.py`` config is left to the zoo)
    :param what: the hyperparameter and where it comes from, for the error
    :return: the class paths with their keyword arguments
    :raises HyperparameterError: a mapping of other than one class path to its keyword arguments
    """
    paths = []
    for item in [] if value is None else value if isinstance(value, list) else [value]:
        name, kwargs = next(iter(item.items())) if isinstance(item, dict) and len(item) == 1 else (item, {})
        if isinstance(item, dict) and not (len(item) == 1 and isinstance(name, str) and isinstance(kwargs, dict)):
            expected = "a class path or one {module.Class: {keyword: value, ...}}"
            raise HyperparameterError(f"{what}: expected {expected}, got {item!r}")
        if isinstance(name, str):
            paths.append((name, kwargs))
    return paths


def _check_class_path(name: str, kwargs: dict[str, Any], what: str, positional: int = 0) -> None:
    """
    :param name: a class path, ``module.Class``
    :param kwargs: keyword arguments the zoo will give the class
    :param what: the hyperparameter, for the error
    :param positional: how many positional arguments the zoo gives the class besides ``kwargs`` (a wrapper's env)
    :raises HyperparameterError: the class does not import, or does not take those arguments
    """
    import importlib
    import inspect

    module_name, _, class_name = name.rpartition(".")
    try:
        if not module_name:
            raise ImportError("not a module.Class path")
        found = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError, ValueError) as error:
        raise HyperparameterError(f"{what} does not import: {error}") from None
    try:
        signature = inspect.signature(found)
    except (TypeError, ValueError):  # no signature to check against
        return
    try:
        signature.bind(*[None] * positional, **kwargs)
    except TypeError as error:
        raise HyperparameterError(f"{what}: {error}") from None
