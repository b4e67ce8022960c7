"""What a run is (:class:`RunSpec`) and its identity: everything that determines its result (:func:`run_identity`).

A stored result or checkpoint is used only when its identity is the one asked for (:func:`check_identity`);
otherwise the run is refused loudly (:class:`RunMismatchError`) instead of reporting another experiment's
result under this one's name.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sb3_dtdpg.common.files import json_default

__all__ = ["RUN_FORMAT_VERSION", "RunDivergedError", "RunMismatchError", "RunSpec", "check_identity", "run_identity"]

#: Version of what a run is and what its result file holds; results of another version are not reused.
RUN_FORMAT_VERSION = 2


@dataclass(frozen=True)
class RunSpec:
    """
    One training run and its evaluation.

    :param algo: one of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param multiple_access: ``"noma"`` or ``"oma"``
    :param seed: training seed
    :param episodes: training budget in episodes
    :param channel: training channel, ``"radio_map"`` (the paper's method) or ``"rayleigh"`` ("reality")
    :param learning_rate: overrides the algorithm's learning rate (None: its default)
    :param destination_episodes: DT-DPG's destination-phase budget (None: 60 % of ``episodes``)
    :param env_id: registered env id
    :param scenario: scenario name or path (None: the env's default)
    :param eval_episodes: number of test episodes
    :param eval_seed: seed of the test episodes, the same for every run so that runs are compared on the
        same missions and fading draws
    :param eval_channel: test channel (the paper tests with Rayleigh fading)
    :param tag: suffix of the run id that tells apart runs of the same algorithm, mode and seed
    :param inducing: the env's inducing reward, ``"euclidean"`` (the paper's) or ``"geodesic"`` (None: the env's default)
    :param eval_before_transfer: DT-DPG only: also evaluate the network saved at the end of the destination
        phase (the "before transfer" trajectories of the paper's Fig. 5b)
    :param hyperparams: hyperparameter set of :func:`sb3_dtdpg.baselines.make_model` (``"paper"`` or ``"tuned"``)
    :param timesteps: train for this many timesteps instead of ``episodes`` episodes (None: by episodes)
    :param observation: the env's observation, ``"paper"`` (the paper's state) or ``"goal"`` (the goal-conditioned
        extension, :class:`noma_radiomap.wrappers.RelativeGoalObservation`)
    :param overrides: single hyperparameters over the set, ``(name, Python literal)`` pairs (``sb3-dtdpg train
        --hyperparams``; :mod:`sb3_dtdpg.overrides`); a run with overrides gets ``_hp<digest>`` in its id
    """

    algo: str
    multiple_access: str
    seed: int
    episodes: int
    channel: str = "radio_map"
    learning_rate: float | None = None
    destination_episodes: int | None = None
    env_id: str = "NomaRadioMap-v0"
    scenario: str | None = None
    eval_episodes: int = 20
    eval_seed: int = 10_000
    eval_channel: str = "rayleigh"
    tag: str = ""
    inducing: str | None = None
    eval_before_transfer: bool = True
    hyperparams: str = "paper"
    timesteps: int | None = None
    observation: str = "paper"
    overrides: tuple[tuple[str, str], ...] = ()

    @property
    def _suffix(self) -> str:
        return (
            (f"_{self.tag}" if self.tag else "")
            + (f"_{self.hyperparams}" if self.hyperparams != "paper" else "")
            + (f"_{self.observation}" if self.observation != "paper" else "")
            + (f"_hp{hashlib.sha256(repr(self.overrides).encode()).hexdigest()[:8]}" if self.overrides else "")
        )

    @property
    def override_kwargs(self) -> dict[str, Any]:
        """:return: :attr:`overrides` as constructor keyword arguments"""
        from sb3_dtdpg.overrides import parse_value

        return {name: parse_value(text) for name, text in self.overrides}

    @property
    def run_id(self) -> str:
        """``<algo>_<mode>_s<seed>[_<tag>][_<hyperparams>]``: the run's folder name under ``tb/`` and ``runs/``."""
        return f"{self.algo}_{self.multiple_access}_s{self.seed}{self._suffix}"

    @property
    def group(self) -> str:
        """The run id without the seed: runs of one group are the seeds of one configuration."""
        return f"{self.algo}_{self.multiple_access}{self._suffix}"

    @property
    def env_kwargs(self) -> dict[str, Any]:
        kwargs: dict[str, Any] = {} if self.scenario is None else {"scenario": self.scenario}
        if self.inducing is not None:
            kwargs["inducing"] = self.inducing
        if self.observation != "paper":
            kwargs["observation"] = self.observation
        return kwargs


class RunDivergedError(ValueError):
    """A run's training diverged (non-finite network weights): its settings cannot train, its checkpoints are removed."""


class RunMismatchError(ValueError):
    """A stored result or checkpoint belongs to another run than the one asked for (same run id, other identity)."""


def _hyperparameters(spec: RunSpec) -> dict[str, Any]:
    """What :func:`sb3_dtdpg.baselines.make_model` builds the algorithm with: the class defaults and the set's values."""
    from sb3_dtdpg import baselines

    cls = baselines.algorithm_class(spec.algo)
    values: dict[str, Any] = {
        name: repr(parameter.default)
        for name, parameter in inspect.signature(cls).parameters.items()
        if parameter.default is not inspect.Parameter.empty
    }
    if spec.algo == "ddpg":
        values.update(baselines.DDPG_KWARGS, ou_sigma=baselines.DDPG_OU_SIGMA)
    elif spec.algo == "td3":
        values["noise_sigma"] = baselines.TD3_NOISE_SIGMA
    if spec.hyperparams == "tuned":
        values.update(baselines.TUNED_KWARGS)
    values.update(spec.override_kwargs)
    return values


def run_identity(spec: RunSpec) -> dict[str, Any]:
    """
    Everything that determines a run's result, as stored in its result file: :data:`RUN_FORMAT_VERSION`, the
    spec (algorithm, mode, seed, budget in episodes, channel, evaluation, ...), the full content of the
    scenario (a scenario file edited since is another run) and the hyperparameters of the algorithm.

    :param spec: the run
    :return: a JSON-ready mapping (lists, not tuples: compare it with a stored one as is)
    """
    import gymnasium as gym

    import noma_radiomap
    from sb3_dtdpg.baselines import check_hyperparams

    check_hyperparams(spec.algo, spec.hyperparams)
    scenario = spec.scenario
    if scenario is None:
        scenario = gym.spec(spec.env_id).kwargs.get("scenario", "mall")
    identity = {
        "format": RUN_FORMAT_VERSION,
        # without overrides the spec is stored as before they existed, so earlier results stay this run's
        "spec": {k: v for k, v in dataclasses.asdict(spec).items() if k != "overrides" or spec.overrides},
        "scenario": noma_radiomap.load_scenario(scenario).to_dict(),
        "hyperparameters": _hyperparameters(spec),
    }
    return json.loads(json.dumps(identity, default=json_default))


def _differences(stored: Any, expected: Any, path: str = "") -> list[str]:
    if isinstance(stored, dict) and isinstance(expected, dict):
        found = []
        order = ("format", "spec", "scenario", "hyperparameters")  # the telling differences first
        keys = sorted(set(stored) | set(expected), key=lambda k: (order.index(k) if k in order else len(order), str(k)))
        for key in keys:
            where = f"{path}.{key}" if path else str(key)
            if key not in stored or key not in expected:
                found.append(
                    f"{where}: {'missing' if key not in stored else repr(stored[key])[:60]} stored, "
                    f"{'missing' if key not in expected else repr(expected[key])[:60]} now"
                )
            else:
                found.extend(_differences(stored[key], expected[key], where))
        return found
    if stored != expected:
        return [f"{path}: {repr(stored)[:60]} stored, {repr(expected)[:60]} now"]
    return []


def check_identity(stored: dict[str, Any], expected: dict[str, Any], what: Path) -> None:
    """
    :param stored: a stored record (a result or a checkpoint pointer) with its ``identity``
    :param expected: the identity of the run asked for (:func:`run_identity`)
    :param what: the stored record's file, named in the error
    :raises RunMismatchError: naming the first differences when the identities differ
    """
    differences = _differences(stored.get("identity", {"format": 1}), expected)
    if differences:
        shown = "; ".join(differences[:4]) + (f"; and {len(differences) - 4} more" if len(differences) > 4 else "")
        raise RunMismatchError(
            f"{what} belongs to another run with the same id ({shown}). Use another output folder "
            f"or delete {what.parent} to run this one"
        )
