"""Reading a saved model for ``sb3-dtdpg evaluate`` / ``enjoy``: its algorithm, its env settings, the env to use.

A model may come from ``sb3-dtdpg train``/``compare`` (``<out>/runs/<run id>/model.zip``, beside a
``result.json`` that names the run's settings), from the RL Zoo (``logs/<algo>/<env>_<n>/<env>.zip``) or from
``model.save`` in Python. The settings come from, in order: the zip's ``env_settings`` (every DT-DPG model,
:mod:`sb3_dtdpg.env_settings`), the run's ``result.json``, and the observation length (the layout that has it).

A model trained on a scenario YAML file is tested on that file's scenario (the file it was read from, while it still
holds the same content), not on the built-in scenario of the same name.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from sb3_dtdpg.common.checks import shortened
from sb3_dtdpg.env_settings import (
    CHECKED,
    RETIRED_BUILTINS,
    builtin_scenario_digest,
    check_settings,
    describe_scenario,
    scenario_digest,
    split_observation,
)
from sb3_dtdpg.experiments.storage import RUN_RECORDS

__all__ = ["RUN_RECORDS", "SavedModel", "check_not_input", "check_output_file", "read_saved_model"]

#: The algorithm of a policy class name (SB3 stores the policy class in the zip).
_POLICY_ALGOS = {"DTDPGPolicy": "dtdpg", "TD3Policy": "td3", "SACPolicy": "sac", "TQCPolicy": "tqc"}
#: The algorithms whose models have a policy class: SB3's DDPG is TD3 with other settings, so it has TD3's policy.
_POLICY_FAMILIES = {"DTDPGPolicy": ("dtdpg",), "TD3Policy": ("td3", "ddpg"), "SACPolicy": ("sac",), "TQCPolicy": ("tqc",)}
#: The fields of a run record's ``spec`` that :func:`read_saved_model` reads (each a string, or null).
_SPEC_FIELDS = ("algo", "scenario", "observation", "multiple_access", "channel", "task", "env_id", "power_mapping")


class SavedModel:
    """
    A model file and what it says about itself.

    :param path: the zip
    :param algo: one of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param settings: the env settings it was trained with (:data:`sb3_dtdpg.env_settings.SETTINGS`), None where unknown
    :param env_id: the env id it was trained on, where known
    :param source: where the settings come from, for messages
    :param custom_objects: saved attributes to replace on loading (SB3's ``custom_objects``)
    :param normalization: the RL Zoo's ``vecnormalize.pkl`` of the model (its observation statistics), None: none
    :param guessed: the settings are only what the observation length tells (the model records none)
    """

    def __init__(
        self,
        path: Path,
        algo: str,
        settings: dict[str, Any] | None,
        env_id: str | None,
        source: str,
        custom_objects: dict[str, Any] | None = None,
        normalization: Path | None = None,
        guessed: bool = False,
    ) -> None:
        self.path, self.algo, self.settings, self.env_id, self.source = path, algo, settings, env_id, source
        self.custom_objects = dict(custom_objects or {})
        self.normalization, self.guessed = normalization, guessed

    def env_kwargs(self, channel: str, **overrides: Any) -> dict[str, Any]:
        """
        The ``gymnasium.make`` keyword arguments of a test env for this model: its recorded settings that shape the
        env (:data:`sb3_dtdpg.env_settings.CHECKED`), each replaced by an override that is not
        None, and the channel.

        :param channel: ``"radio_map"`` or ``"rayleigh"``
        :param overrides: settings to use instead of the recorded ones (None: the recorded one)
        :return: the keyword arguments (``channel`` first; settings neither recorded nor given are left out; the
            scenario is the recorded file's path where the model was trained on a scenario file other than the
            built-in of its name)
        :raises ValueError: the model was trained on a scenario of a file that no longer holds it (changed, moved),
            or of no file, and no ``scenario`` override is given; or on observations of a wrapper (e.g.
            ``RelativeGoalObservation``) and no ``observation`` override is given
        """
        settings = self.settings or {}
        kwargs: dict[str, Any] = {"channel": channel}
        for key in CHECKED:  # the settings that shape the env (the channel is the caller's)
            value = overrides.get(key)
            if value is None:
                value = self._recorded_scenario() if key == "scenario" else settings.get(key)
            if key == "observation" and split_observation(value)[1]:
                raise ValueError(
                    f"the model {self.path} was trained on observations of a wrapper ({value}); the CLI builds "
                    "unwrapped envs only: wrap the env in Python and use the model there"
                )
            if value is not None:
                kwargs[key] = value
        return kwargs

    def _recorded_scenario(self) -> str | None:
        """
        The ``scenario`` argument that builds the recorded scenario: its built-in name, or the file it was read from.

        :return: the name or the path (None: none recorded)
        :raises ValueError: naming the scenario, its file and what became of it, when neither builds it
        """
        from noma_radiomap import load_scenario

        settings = self.settings or {}
        name, digest, file = settings.get("scenario"), settings.get("scenario_digest"), settings.get("scenario_file")
        if not digest:  # a model saved before the digest was recorded: its name, as then (or a run's unreadable file)
            return name if name is not None else file
        if name is not None and builtin_scenario_digest(str(name)) == digest:
            return str(name)
        recorded = f"content sha256 {digest[:12]}, recorded in {self.source}"
        if not file and digest in RETIRED_BUILTINS:
            raise ValueError(
                f"the model {self.path} was trained on scenario {name!r}: {describe_scenario(settings)}; give "
                f"--scenario {RETIRED_BUILTINS[digest]} (its path in a clone of the repository)"
            )
        if not file:
            raise ValueError(
                f"the model {self.path} was trained on a scenario {name!r} of its own ({recorded}), not the built-in "
                f"scenario of that name and not read from a file; give --scenario with a YAML file of that scenario"
            )
        try:
            current = scenario_digest(load_scenario(Path(file)))
        except ValueError as error:
            problem = f"cannot be loaded now ({error})"
        else:
            if current == digest:
                return str(file)
            problem = f"holds another scenario now (content sha256 {current[:12]})"
        raise ValueError(
            f"the model {self.path} was trained on scenario {name!r} from {file} ({recorded}), but that file {problem}; "
            "give --scenario with a YAML file of the scenario it was trained on"
        )

    def load(self, env: Any) -> Any:
        """:return: the model, loaded onto ``env`` after checking the env's settings against the recorded ones"""
        from sb3_dtdpg.baselines import load_model

        check_settings(self.settings, env, f"the model {self.path}")
        # verbose 0: a model saved with verbose=1 (the RL Zoo's) would print SB3's env-wrapping notice on load
        custom_objects = {"verbose": 0, **self.custom_objects}
        try:
            model = load_model(self.algo, self.path, env=env, device="cpu", custom_objects=custom_objects)
        except ValueError as error:
            if self.settings or "spaces do not match" not in str(error):
                raise
            # No mission settings recorded (SB3's own model.save): most likely not a model of the mission envs
            raise ValueError(
                f"{error}: the model {self.path} records no NomaRadioMap settings; if it was not trained on a mission "
                "env, evaluate and enjoy cannot test it (they run the NomaRadioMap test missions)"
            ) from None
        from sb3_dtdpg.experiments.run_callbacks import non_finite

        broken = non_finite(model.policy.state_dict().items())  # the running statistics of batch norm too
        if broken:
            raise ValueError(
                f"the model {self.path} holds non-finite weights (NaN or inf) in {shortened(broken, 3)}: it was saved "
                "after its training diverged"
            )
        return model

    def observations_as_trained(self, env: Any) -> Any:
        """
        :param env: the model's test env (a Gymnasium env)
        :return: ``env`` with its observations normalized by the model's RL Zoo statistics (``normalize: true``
            trains the model on normalized observations), or ``env`` itself for a model without them
        :raises ValueError: naming the statistics file when it cannot be read
        """
        if self.normalization is None:
            return env
        import pickle

        import gymnasium as gym
        from stable_baselines3.common.running_mean_std import RunningMeanStd
        from stable_baselines3.common.vec_env import VecNormalize

        try:
            with open(self.normalization, "rb") as file:
                statistics = pickle.load(file)
        except Exception as error:  # a damaged pickle raises many kinds of errors
            raise ValueError(f"{self.normalization}: unreadable ({type(error).__name__}: {error})") from None
        if not isinstance(statistics, VecNormalize) or not isinstance(statistics.__dict__.get("obs_rms"), RunningMeanStd):
            raise ValueError(f"{self.normalization}: not the RL Zoo's VecNormalize statistics of a flat observation")
        if not statistics.norm_obs:  # rewards only
            return env
        return gym.wrappers.TransformObservation(env, _Normalizer(statistics), env.observation_space)


class _Normalizer:
    """
    The observation normalisation of saved ``VecNormalize`` statistics (its ``normalize_obs``: the running mean and
    variance, clipped to ``clip_obs``), without the ``VecNormalize`` itself, which has no env once unpickled and then
    cannot be copied with the test env.

    :param statistics: the unpickled ``VecNormalize``
    """

    def __init__(self, statistics: Any) -> None:
        self.mean, self.var = statistics.obs_rms.mean, statistics.obs_rms.var
        self.clip_obs, self.epsilon = statistics.clip_obs, statistics.epsilon

    def __call__(self, observation: Any) -> Any:
        scaled = (observation - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(scaled, -self.clip_obs, self.clip_obs).astype(np.float32)


def _model_path(path: str | Path) -> Path:
    path = Path(path)
    if path.is_dir():
        if not (path / "model.zip").is_file():
            raise ValueError(f"{path} is a folder without a model.zip (give the model file, e.g. <run folder>/model.zip)")
        path = path / "model.zip"
    elif not path.is_file():
        raise ValueError(f"{path}: no such model file")
    return path


def read_saved_model(path: str | Path, algo: str | None = None) -> SavedModel:
    """
    :param path: a model zip, or a run folder holding ``model.zip``
    :param algo: the algorithm (None: from the run's ``result.json``, else from the zip's policy class and, for a
        TD3 policy, the settings that tell SB3's DDPG from TD3); refused when the run record or the policy class
        names another one
    :return: the model file's description
    :raises ValueError: a missing file, a file that is not an SB3 model zip, an unknown algorithm, an ``algo`` that
        contradicts the model, or a damaged ``result.json`` beside the model (one that contradicts the model)
    """
    from stable_baselines3.common.buffers import NStepReplayBuffer
    from stable_baselines3.common.save_util import load_from_zip_file

    path = _model_path(path)
    try:
        data, parameters, _ = load_from_zip_file(path, load_data=True, device="cpu")
    except Exception as error:  # zipfile, pickle and torch raise many kinds of errors for a file that is not a model
        raise ValueError(f"{path}: not a Stable-Baselines3 model file ({type(error).__name__}: {error})") from None
    if not data or "policy" not in (parameters or {}):
        missing = "data" if not data else "policy.pth"
        raise ValueError(
            f"{path}: not a Stable-Baselines3 model file (no {missing!r} in it; a policy alone, saved with "
            "model.policy.save(), is not one: give the file of model.save())"
        )
    result_file = path.parent / "result.json"
    spec, content = _run_spec(result_file) if result_file.is_file() else ({}, None)
    policy_class = getattr(data.get("policy_class"), "__name__", "")
    algo = _algorithm(path, data, policy_class, spec, result_file, algo)
    settings, source = data.get("env_settings"), "the model file"
    if settings is not None and spec and not settings.get("scenario_digest"):
        # saved before the scenario's content was recorded: its run record tells which room of that name it was
        known = _spec_scenario(spec.get("scenario") or "mall", content)
        if known.get("scenario_digest") and known.get("scenario") == settings.get("scenario"):
            settings = {**settings, "scenario_digest": known["scenario_digest"], "scenario_file": known["scenario_file"]}
            source = f"the model file and {result_file}"
    if settings is None and spec:
        settings = {
            **_spec_scenario(spec.get("scenario") or "mall", content),
            "observation": spec.get("observation", "paper"),
            "multiple_access": spec.get("multiple_access"),
            "channel": spec.get("channel"),
            "task": spec.get("task") or _task_of(spec.get("env_id")),
            "power_mapping": spec.get("power_mapping"),  # None: a run recorded before power mappings, not checked
        }
        source = str(result_file)
    guessed = settings is None
    if guessed:
        settings, source = _settings_from_space(data.get("observation_space")), "the observation length"
    custom_objects = {}
    if data.get("replay_buffer_class") is NStepReplayBuffer and data.get("n_steps", 1) > 1:
        # SB3 chose this buffer itself for n_steps > 1; handed back as a custom class on load, it warns that n_steps
        # is ignored (the warning of DLR-RM/stable-baselines3#2275, which load trips). Left to SB3, it is rebuilt
        # the same way.
        custom_objects["replay_buffer_class"] = None
    # the RL Zoo keeps a run's VecNormalize statistics in <run folder>/<env id>/vecnormalize.pkl, beside its models
    statistics = sorted(path.parent.glob("*/vecnormalize.pkl"))
    if len(statistics) > 1:
        raise ValueError(
            f"{path}: several observation statistics beside it ({', '.join(map(str, statistics))}); move the model "
            "into its own RL Zoo run folder"
        )
    normalization = statistics[0] if statistics else None
    return SavedModel(path, algo, settings, spec.get("env_id"), source, custom_objects, normalization, guessed)


def _algorithm(
    path: Path, data: dict[str, Any], policy_class: str, spec: dict[str, Any], result_file: Path, algo: str | None
) -> str:
    """
    The algorithm of a model: the run record's, else its policy class's, checked against the one asked for.

    :param path: the model zip
    :param data: its saved attributes
    :param policy_class: the name of its policy class
    :param spec: its run record's ``spec`` (empty: none)
    :param result_file: the run record, for messages
    :param algo: the algorithm asked for (``--algo``; None: the recorded one)
    :return: the algorithm to load the model with
    :raises ValueError: the run record and the policy class disagree, ``algo`` contradicts them, or neither tells
    """
    family = _POLICY_FAMILIES.get(policy_class)  # None: a policy class of its own (a custom or zoo policy)
    recorded = spec.get("algo")
    if recorded is not None and family is not None and recorded not in family:
        raise ValueError(
            f"{result_file}: records algo {recorded!r}, but the model {path} beside it has a {policy_class} "
            f"({' or '.join(family)}): the file is not this model's run record; move it or the model elsewhere"
        )
    if recorded is None and family is not None:
        recorded = _POLICY_ALGOS[policy_class]
        if recorded == "td3" and _is_ddpg(data):
            recorded = "ddpg"
    if algo is not None:
        allowed = (spec["algo"],) if spec.get("algo") else family
        if allowed is not None and algo not in allowed:
            where = f"{result_file} records algo {recorded!r}" if spec.get("algo") else f"its policy class is {policy_class}"
            raise ValueError(
                f"--algo {algo}: the model {path} is a {recorded} model ({where}); leave --algo out or give "
                f"--algo {' or --algo '.join(allowed)}"
            )
        return algo
    if recorded is None:
        raise ValueError(f"{path}: cannot tell the algorithm from its policy class {policy_class!r}; give --algo")
    return recorded


def _spec_scenario(given: str, content: Any) -> dict[str, Any]:
    """
    The scenario settings of a run whose model records none, like :func:`sb3_dtdpg.env_settings.settings_of`'s.

    :param given: the run's ``spec.scenario``: a built-in name or a YAML path
    :param content: the scenario the run trained on, as its record's ``identity.scenario`` stores it (None: not stored)
    :return: ``scenario`` (a built-in name: it alone, as before; a file: the scenario's name, None where neither the
        record nor the file tells), ``scenario_digest`` and ``scenario_file``
    """
    from noma_radiomap import list_scenarios, load_scenario

    if given in list_scenarios():
        return {"scenario": given}
    file = os.path.abspath(given)
    if isinstance(content, dict) and isinstance(content.get("name"), str):  # the content trained on, even if edited since
        return {"scenario": content["name"], "scenario_digest": scenario_digest(content), "scenario_file": file}
    try:
        scenario = load_scenario(Path(given))
    except ValueError:  # gone: the test env's gymnasium.make names the file, unless --scenario is given
        return {"scenario": None, "scenario_file": file}
    return {"scenario": scenario.name, "scenario_digest": scenario_digest(scenario), "scenario_file": file}


def _run_spec(result_file: Path) -> tuple[dict[str, Any], Any]:
    """
    The ``spec`` of a run's record beside a model (``train``/``compare``/``reproduce`` write ``result.json``).

    A JSON object without a ``spec`` is not a run record (e.g. a file of the user's) and is ignored.

    :param result_file: the ``result.json`` beside the model
    :return: its ``spec`` (empty: none) and the scenario its ``identity`` stores (None: none)
    :raises ValueError: naming the file and what is wrong: not JSON, not a JSON object, a ``spec`` that is not an
        object, or a field of it that cannot be a setting (:data:`_SPEC_FIELDS`)
    """
    import gymnasium as gym

    import noma_radiomap  # noqa: F401  (registers the env ids)
    from noma_radiomap.registration import POWER_MAPPINGS
    from sb3_dtdpg.baselines import ALGORITHMS

    def damaged(reason: str) -> ValueError:
        return ValueError(
            f"{result_file}, the run record beside the model, {reason}; repair it, or move it or the model elsewhere "
            "(evaluate and enjoy read the model's settings from it)"
        )

    try:
        record = json.loads(result_file.read_text())
    except (OSError, ValueError) as error:  # ValueError: JSONDecodeError, UnicodeDecodeError
        raise damaged(f"is unreadable ({type(error).__name__}: {str(error)[:200]})") from None
    if not isinstance(record, dict):
        raise damaged(f"is a JSON {type(record).__name__}, not an object")
    spec = record.get("spec", {})
    if not isinstance(spec, dict):
        raise damaged(f"has a spec that is a JSON {type(spec).__name__}, not an object")
    for key in _SPEC_FIELDS:
        value = spec.get(key)
        if value is not None and not isinstance(value, str):
            raise damaged(f"has spec.{key} = {str(json.dumps(value))[:100]}, expected a string")
    if spec.get("algo") is not None and spec["algo"] not in ALGORITHMS:
        raise damaged(f"has spec.algo = {spec['algo']!r}, expected one of {', '.join(ALGORITHMS)}")
    if spec.get("env_id") is not None:
        try:
            gym.spec(spec["env_id"])
        except gym.error.Error:
            raise damaged(f"has spec.env_id = {spec['env_id']!r}, not a registered env id") from None
    if spec.get("power_mapping") is not None and spec["power_mapping"] not in POWER_MAPPINGS:
        raise damaged(f"has spec.power_mapping = {spec['power_mapping']!r}, expected one of {', '.join(POWER_MAPPINGS)}")
    identity = record.get("identity")
    return spec, identity.get("scenario") if isinstance(identity, dict) else None


def check_output_file(option: str, value: str | Path, model: str | Path) -> None:
    """
    Refuse an output file of ``evaluate``/``enjoy`` that would overwrite the model or a record of a run.

    A run folder's records (:data:`RUN_RECORDS`, the curriculum's ``phase_*.zip``) are refused in the model's folder
    whether or not it is a run folder (:func:`read_saved_model` reads a ``result.json`` beside any model as its
    run's), and in any run folder (``<out>/runs/<run id>/`` holding a record).

    :param option: the option, for the message (``--json``)
    :param value: the output file
    :param model: the model zip, or a run folder holding ``model.zip``
    :raises ValueError: naming the option and the file
    """
    target, model_path = Path(value), _model_path(model)
    if target.resolve() == model_path.resolve() or (target.exists() and os.path.samefile(target, model_path)):
        raise ValueError(f"{option} {value}: that is the model file itself; write the results elsewhere")
    folders = {model_path.resolve().parent}
    if model_path.resolve().parent.parent.name == "checkpoints":  # <run folder>/checkpoints/episode_<n>/model.zip
        folders.add(model_path.resolve().parents[2])
    name = target.name.lower()
    owned = name in RUN_RECORDS or (name.startswith("phase_") and name.endswith(".zip"))
    parent = target.resolve().parent
    another_run = parent.parent.name == "runs" and any((parent / record).exists() for record in RUN_RECORDS)
    if owned and (parent in folders or another_run):
        raise ValueError(
            f"{option} {value}: {target.name} is a record of the run folder {target.parent} (train, compare "
            "and reproduce own it); write the results elsewhere"
        )


def check_not_input(option: str, value: str | Path, source: str | Path | None, what: str) -> None:
    """
    Refuse an output file of ``evaluate``/``enjoy`` that is a file the command reads.

    :param option: the option, for the message (``--json``)
    :param value: the output file
    :param source: the file read (None, or a name that is no file: nothing to refuse)
    :param what: what that file is, for the message
    :raises ValueError: naming the option and the file
    """
    if source is not None and Path(value).exists() and Path(source).is_file() and os.path.samefile(value, source):
        raise ValueError(f"{option} {value}: that is {what}; write the results elsewhere")


def _task_of(env_id: str | None) -> str | None:
    """:return: the task of a registered env id (``missions`` where the id names none), None without an id"""
    import gymnasium as gym

    return None if env_id is None else gym.spec(env_id).kwargs.get("task", "missions")


def _is_ddpg(data: dict[str, Any]) -> bool:
    """Whether a TD3-policy model was SB3's ``DDPG``: TD3 with one actor update per critic update and no target noise."""
    return data.get("policy_delay") == 1 and data.get("target_noise_clip") == 0.0


def _settings_from_space(space: Any) -> dict[str, Any] | None:
    """The observation layout of a flat Box observation on the default scenario (``mall``), where its length tells."""
    from noma_radiomap import load_scenario
    from sb3_dtdpg.env_settings import infer_observation

    shape = getattr(space, "shape", None)
    if not shape or len(shape) != 1:
        return None
    observation = infer_observation(int(shape[0]), len(load_scenario("mall").robots))
    return None if observation is None else {"observation": observation}
