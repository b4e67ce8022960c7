"""What a run is (:class:`RunSpec`) and its identity: everything that determines its result (:func:`run_identity`).

A stored result or checkpoint is used only when its identity is the one asked for (:func:`check_identity`);
otherwise the run is refused loudly (:class:`RunMismatchError`) instead of reporting another experiment's
result under this one's name.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sb3_dtdpg.arguments import MAX_SEED
from sb3_dtdpg.common.checks import shortened
from sb3_dtdpg.common.files import json_default, safe_name

__all__ = [
    "RUN_FORMAT_VERSION",
    "RunDivergedError",
    "RunMismatchError",
    "RunSpec",
    "check_identity",
    "identity_digest",
    "run_identity",
]

#: Version of what a run is and what its result file holds; results of another version are not reused.
#: 3: the hyperparameters are read back from the built model (:func:`sb3_dtdpg.presets.model_settings`).
RUN_FORMAT_VERSION = 3


#: The integer fields of a :class:`RunSpec`: (name, smallest value, None allowed)
_COUNTS = (
    ("seed", 0, False),
    ("episodes", 1, True),
    ("timesteps", 1, True),
    ("destination_episodes", 1, True),
    ("eval_episodes", 1, False),
    ("eval_seed", 0, False),
)
_CHANNELS = ("radio_map", "rayleigh")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


@dataclass(frozen=True)
class RunSpec:
    """
    One training run and its evaluation.

    :param algo: one of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param multiple_access: ``"noma"`` or ``"oma"``
    :param seed: training seed
    :param episodes: training budget in episodes (None: a budget in ``timesteps``; one of the two, not both)
    :param channel: training channel, ``"radio_map"`` (the paper's method) or ``"rayleigh"`` ("reality")
    :param learning_rate: overrides the algorithm's learning rate (None: its default)
    :param destination_episodes: DT-DPG's destination-phase budget (None: 60 % of ``episodes``, or of the episodes
        ``timesteps`` holds when every episode runs to the mission's ``max_steps``)
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
    :param observation: the env's observation layout (docs/MODEL.md, "Observations"): ``"goal"`` (the default of every
        entry point: positions, destinations, gains, arrived flags, direction and distance to the destination),
        ``"destinations"`` (the same without the goal features) or ``"paper"`` (Eq. (24): positions and gains only).
        The run id names it unless it is ``"paper"`` (so the ids of runs stored before the layouts were renamed stay)
    :param overrides: single hyperparameters over the set, ``(name, Python literal)`` pairs (``sb3-dtdpg train
        --hyperparams``; :mod:`sb3_dtdpg.overrides`), kept in name order; a run with overrides gets ``_hp<digest>``
        in its id
    :param power_mapping: how the power actions become powers, in training and in the test
        (:data:`noma_radiomap.registration.POWER_MAPPINGS`): ``"paper"`` (the env's own) or ``"shares"`` (shares of
        ``P_max``, :class:`noma_radiomap.wrappers.PowerShares`; the run id ends in ``_shares``)
    """

    algo: str
    multiple_access: str
    seed: int
    episodes: int | None
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
    observation: str = "goal"
    overrides: tuple[tuple[str, str], ...] = ()
    power_mapping: str = "paper"

    def __post_init__(self) -> None:
        """:raises ValueError: naming the first field that no run can have (before anything is trained)"""
        for name, low, optional in _COUNTS:
            value = getattr(self, name)
            if (value is not None or not optional) and not (_is_int(value) and low <= value <= MAX_SEED):
                what = f"an integer from {low:,} to {MAX_SEED:,}" + (" or None" if optional else "")
                raise ValueError(f"RunSpec.{name}: expected {what}, got {value!r}")
        if (self.episodes is None) == (self.timesteps is None):  # the record names the budget the run trains for
            raise ValueError(
                f"RunSpec.episodes and RunSpec.timesteps: a run trains for episodes or for timesteps, give one "
                f"(the other None), got episodes={self.episodes!r} and timesteps={self.timesteps!r}"
            )
        for name in ("channel", "eval_channel"):
            if getattr(self, name) not in _CHANNELS:
                raise ValueError(f"RunSpec.{name}: expected one of {_CHANNELS}, got {getattr(self, name)!r}")
        pairs = tuple(self.overrides) if isinstance(self.overrides, (tuple, list)) else None
        if pairs is None or not all(
            isinstance(pair, tuple) and len(pair) == 2 and all(isinstance(text, str) for text in pair) for pair in pairs
        ):
            raise ValueError(f"RunSpec.overrides: expected (name, Python literal) pairs of strings, got {self.overrides!r}")
        if len({name for name, _ in pairs}) != len(pairs):
            raise ValueError(f"RunSpec.overrides: each hyperparameter once, got {self.overrides!r}")
        # in name order, so that the run id and identity do not depend on the order they were given in
        object.__setattr__(self, "overrides", tuple(sorted(pairs)))
        if not isinstance(self.tag, str) or (self.tag and safe_name(self.tag) != self.tag):
            raise ValueError(f"RunSpec.tag: expected letters, digits and ._+- (part of a folder name), got {self.tag!r}")

    @property
    def _suffix(self) -> str:
        return (
            (f"_{self.tag}" if self.tag else "")
            + (f"_{self.hyperparams}" if self.hyperparams != "paper" else "")
            + (f"_{self.observation}" if self.observation != "paper" else "")
            + (f"_hp{hashlib.sha256(repr(self.overrides).encode()).hexdigest()[:8]}" if self.overrides else "")
            + (f"_{self.power_mapping}" if self.power_mapping != "paper" else "")
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
        kwargs["observation"] = self.observation
        if self.power_mapping != "paper":
            kwargs["power_mapping"] = self.power_mapping
        return kwargs


class RunDivergedError(ValueError):
    """A run's training diverged (non-finite network weights): its settings cannot train, its checkpoints are removed."""


class RunMismatchError(ValueError):
    """A stored result or checkpoint belongs to another run than the one asked for (same run id, other identity)."""


def build_model(spec: RunSpec, env: Any, **kwargs: Any) -> Any:
    """
    :param spec: the run
    :param env: its training env (:func:`sb3_dtdpg.baselines.make_env` of the spec)
    :param kwargs: further constructor arguments (verbosity, DT-DPG's ``curriculum_save_path``)
    :return: the untrained model of the run, as :func:`sb3_dtdpg.baselines.make_model` builds it
    """
    from sb3_dtdpg.baselines import make_model

    destination_episodes = None
    if spec.algo == "dtdpg":
        episodes = spec.episodes
        if spec.timesteps is not None:  # the episodes the budget holds at least (every one at the mission's longest)
            episodes = spec.timesteps // int(env.unwrapped.scenario.mission.max_steps)
        destination_episodes = spec.destination_episodes or max(1, round(0.6 * episodes))
    return make_model(
        spec.algo,
        env,
        seed=spec.seed,
        learning_rate=spec.learning_rate,
        destination_episodes=destination_episodes,
        hyperparams=spec.hyperparams,
        **kwargs,
        **spec.override_kwargs,
    )


def _hyperparameters(spec: RunSpec) -> dict[str, Any]:
    """
    The settings the run trains with, read back from the model built for it (:func:`build_model`,
    :func:`sb3_dtdpg.presets.model_settings`), never re-derived from the presets.
    """
    from sb3_dtdpg.baselines import algorithm_class, make_env
    from sb3_dtdpg.overrides import check_constructor_kwargs
    from sb3_dtdpg.presets import model_settings

    check_constructor_kwargs(algorithm_class(spec.algo), spec.override_kwargs, " (RunSpec.overrides)")
    env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
    try:
        return model_settings(build_model(spec, env))
    finally:
        env.close()


#: Fields added to :class:`RunSpec` after results were stored, with their defaults: a spec at a field's default is
#: stored without it, as before the field existed, so earlier results stay this run's.
_LATER_FIELDS: dict[str, Any] = {"overrides": (), "power_mapping": "paper"}


def run_identity(spec: RunSpec) -> dict[str, Any]:
    """
    Everything that determines a run's result, as stored in its result file: :data:`RUN_FORMAT_VERSION`, the
    spec (algorithm, mode, seed, budget in episodes, channel, evaluation, ...), the full content of the
    scenario (a scenario file edited since is another run) and the hyperparameters of the algorithm.

    :param spec: the run
    :return: a JSON-ready mapping (lists, not tuples: compare it with a stored one as is)
    """
    import noma_radiomap
    from noma_radiomap.registration import check_power_mapping, default_scenario
    from sb3_dtdpg.baselines import check_hyperparams

    check_hyperparams(spec.algo, spec.hyperparams)
    check_power_mapping(spec.power_mapping)
    scenario = spec.scenario
    if scenario is None:
        scenario = default_scenario(spec.env_id)
    identity = {
        "format": RUN_FORMAT_VERSION,
        "spec": {k: v for k, v in dataclasses.asdict(spec).items() if k not in _LATER_FIELDS or v != _LATER_FIELDS[k]},
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


#: Settings that choose how a model computes, not what: DTDPG's lean step and its written-out backward passes give
#: the same weights bit for bit as SB3's generic step (``tests/test_lean_step.py``). They are recorded but not compared,
#: so results stored before they existed, or with them switched off, stay this run's.
_SAME_RESULT_SETTINGS = ("lean", "backprop")
#: Algorithms recorded by their class that give another class's weights bit for bit: SB3's DDPG and TD3 with the lean
#: step (:class:`~sb3_dtdpg.dtdpg.lean.LeanDDPG`, the algorithm set's ``ddpg``, and ``LeanTD3``). They are compared as
#: SB3's class, so that runs stored before the set used them stay this run's.
_SAME_RESULT_ALGORITHMS = {
    "sb3_dtdpg.dtdpg.lean.LeanDDPG": "stable_baselines3.ddpg.ddpg.DDPG",
    "sb3_dtdpg.dtdpg.lean.LeanTD3": "stable_baselines3.td3.td3.TD3",
}


def _compared(identity: dict[str, Any]) -> dict[str, Any]:
    """
    :return: the identity without :data:`_SAME_RESULT_SETTINGS` (and the algorithms of :data:`_SAME_RESULT_ALGORITHMS`
        as the classes they give the weights of), and without the name the scenario was given by
        where the identity holds the scenario's content, which decides (None for the env id's default, ``"mall"``,
        or a file of the same content are one run), and without the episodes count of a run of a budget in
        timesteps (it trains for those; runs stored with the CLI's unused ``--episodes`` default stay this run's)
    """
    spec = identity.get("spec")
    if isinstance(spec, dict) and isinstance(identity.get("scenario"), dict):
        identity = {**identity, "spec": {k: v for k, v in spec.items() if k != "scenario"}}
    if isinstance(spec, dict) and spec.get("timesteps") is not None:
        identity = {**identity, "spec": {k: v for k, v in identity["spec"].items() if k != "episodes"}}
    hyperparameters = identity.get("hyperparameters")
    if not isinstance(hyperparameters, dict):
        return identity
    kept = {k: v for k, v in hyperparameters.items() if k not in _SAME_RESULT_SETTINGS}
    if kept.get("algorithm") in _SAME_RESULT_ALGORITHMS:
        kept["algorithm"] = _SAME_RESULT_ALGORITHMS[kept["algorithm"]]
    return {**identity, "hyperparameters": kept}


def identity_digest(identity: dict[str, Any], seed: bool = True) -> str:
    """
    :param identity: a run's identity (:func:`run_identity`, or as stored in its result)
    :param seed: include the seed (False: one digest for the seeds of one configuration)
    :return: 12 hex digits of it as :func:`check_identity` compares it: another for a run of other settings under the
        same id (e.g. another budget's, or one in a room recalibrated since)
    """
    compared = _compared(identity)
    for part in () if seed else ("spec", "hyperparameters"):  # the spec's seed, and the model's
        if isinstance(compared.get(part), dict):
            compared = {**compared, part: {k: v for k, v in compared[part].items() if k != "seed"}}
    text = json.dumps(compared, sort_keys=True, default=json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def check_identity(stored: dict[str, Any], expected: dict[str, Any], what: Path) -> None:
    """
    :param stored: a stored record (a result or a checkpoint pointer) with its ``identity``
    :param expected: the identity of the run asked for (:func:`run_identity`)
    :param what: the stored record's file, named in the error
    :raises RunMismatchError: naming the first differences when the identities differ
    """
    differences = _differences(_compared(stored.get("identity", {"format": 1})), _compared(expected))
    rooms = stored.get("identity", {}).get("scenario"), expected.get("scenario")
    if all(isinstance(room, dict) for room in rooms) and rooms[0] != rooms[1]:  # the rooms' names first, then the fields
        first = next(i for i, text in enumerate(differences) if text.startswith("scenario."))
        names = rooms[0].get("name"), rooms[1].get("name")
        other = " (another room of that name)" if names[0] == names[1] else ""
        differences.insert(first, f"scenario: {names[0]!r} stored, {names[1]!r} now{other}")
    if differences:
        raise RunMismatchError(
            f"{what} belongs to another run with the same id ({shortened(differences, 4, separator='; ')}). "
            f"Use another output folder or delete {what.parent} to run this one"
        )
