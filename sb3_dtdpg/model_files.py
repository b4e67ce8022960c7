"""Reading a saved model for ``sb3-dtdpg evaluate`` / ``enjoy``: its algorithm, its env settings, the env to use.

A model may come from ``sb3-dtdpg train``/``compare`` (``<out>/runs/<run id>/model.zip``, beside a
``result.json`` that names the run's settings), from the RL Zoo (``logs/<algo>/<env>_<n>/<env>.zip``) or from
``model.save`` in Python. The settings come from, in order: the zip's ``env_settings`` (every DT-DPG model,
:mod:`sb3_dtdpg.env_settings`), the run's ``result.json``, and the observation length (the layout that has it).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sb3_dtdpg.env_settings import CHECKED, check_settings

__all__ = ["SavedModel", "read_saved_model"]

#: The algorithm of a policy class name (SB3 stores the policy class in the zip).
_POLICY_ALGOS = {"DTDPGPolicy": "dtdpg", "TD3Policy": "td3", "SACPolicy": "sac", "TQCPolicy": "tqc"}


class SavedModel:
    """
    A model file and what it says about itself.

    :param path: the zip
    :param algo: one of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param settings: the env settings it was trained with (:data:`sb3_dtdpg.env_settings.SETTINGS`), None where unknown
    :param env_id: the env id it was trained on, where known
    :param source: where the settings come from, for messages
    :param custom_objects: saved attributes to replace on loading (SB3's ``custom_objects``)
    """

    def __init__(
        self,
        path: Path,
        algo: str,
        settings: dict[str, Any] | None,
        env_id: str | None,
        source: str,
        custom_objects: dict[str, Any] | None = None,
    ) -> None:
        self.path, self.algo, self.settings, self.env_id, self.source = path, algo, settings, env_id, source
        self.custom_objects = dict(custom_objects or {})

    def env_kwargs(self, channel: str, **overrides: Any) -> dict[str, Any]:
        """
        The ``gymnasium.make`` keyword arguments of a test env for this model: its recorded settings that shape the
        env (:data:`sb3_dtdpg.env_settings.CHECKED`), each replaced by an override that is not
        None, and the channel.

        :param channel: ``"radio_map"`` or ``"rayleigh"``
        :param overrides: settings to use instead of the recorded ones (None: the recorded one)
        :return: the keyword arguments (``channel`` first; settings neither recorded nor given are left out)
        """
        settings = self.settings or {}
        kwargs: dict[str, Any] = {"channel": channel}
        for key in CHECKED:  # the settings that shape the env (the channel is the caller's)
            value = overrides.get(key)
            value = settings.get(key) if value is None else value
            if value is not None:
                kwargs[key] = value
        return kwargs

    def load(self, env: Any) -> Any:
        """:return: the model, loaded onto ``env`` after checking the env's settings against the recorded ones"""
        from sb3_dtdpg.baselines import algorithm_class

        check_settings(self.settings, env, f"the model {self.path}")
        # verbose 0: a model saved with verbose=1 (the RL Zoo's) would print SB3's env-wrapping notice on load
        custom_objects = {"verbose": 0, **self.custom_objects}
        try:
            return algorithm_class(self.algo).load(self.path, env=env, device="cpu", custom_objects=custom_objects)
        except ValueError as error:
            if self.settings or "spaces do not match" not in str(error):
                raise
            # No mission settings recorded (SB3's own model.save): most likely not a model of the mission envs
            raise ValueError(
                f"{error}: the model {self.path} records no NomaRadioMap settings; if it was not trained on a mission "
                "env, evaluate and enjoy cannot test it (they run the NomaRadioMap test missions)"
            ) from None


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
        TD3 policy, the settings that tell SB3's DDPG from TD3)
    :return: the model file's description
    :raises ValueError: a missing file, a file that is not an SB3 model zip, or an unknown algorithm
    """
    from stable_baselines3.common.buffers import NStepReplayBuffer
    from stable_baselines3.common.save_util import load_from_zip_file

    path = _model_path(path)
    try:
        data, _, _ = load_from_zip_file(path, load_data=True, device="cpu")
    except Exception as error:  # zipfile, pickle and torch raise many kinds of errors for a file that is not a model
        raise ValueError(f"{path}: not a Stable-Baselines3 model file ({type(error).__name__}: {error})") from None
    data = data or {}
    result_file = path.parent / "result.json"
    spec: dict[str, Any] = {}
    if result_file.is_file():
        spec = json.loads(result_file.read_text()).get("spec", {})
    policy_class = getattr(data.get("policy_class"), "__name__", "")
    algo = algo or spec.get("algo") or _POLICY_ALGOS.get(policy_class)
    if algo == "td3" and _is_ddpg(data):
        algo = "ddpg"
    if algo is None:
        raise ValueError(f"{path}: cannot tell the algorithm from its policy class {policy_class!r}; give --algo")
    settings, source = data.get("env_settings"), "the model file"
    if settings is None and spec:
        settings = {
            "scenario": spec.get("scenario") or "mall",
            "observation": spec.get("observation", "paper"),
            "multiple_access": spec.get("multiple_access"),
            "channel": spec.get("channel"),
            "task": spec.get("task"),
        }
        source = str(result_file)
    if settings is None:
        settings, source = _settings_from_space(data.get("observation_space")), "the observation length"
    custom_objects = {}
    if data.get("replay_buffer_class") is NStepReplayBuffer and data.get("n_steps", 1) > 1:
        # SB3 chose this buffer itself for n_steps > 1; handed back as a custom class on load, it warns that n_steps
        # is ignored (the warning of DLR-RM/stable-baselines3#2275, which load trips). Left to SB3, it is rebuilt
        # the same way.
        custom_objects["replay_buffer_class"] = None
    return SavedModel(path, algo, settings, spec.get("env_id"), source, custom_objects)


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
