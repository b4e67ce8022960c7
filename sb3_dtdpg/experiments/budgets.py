"""The scale of an experiment (:class:`Budget`, by name in :data:`BUDGETS`) and the check that a run's budget can train."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sb3_dtdpg.arguments import MAX_SEEDS
from sb3_dtdpg.experiments.specs import RunSpec

__all__ = [
    "BUDGETS",
    "BUDGET_ALIASES",
    "CHECKPOINT_EVERY",
    "MAX_SEEDS",
    "PUBLIC_BUDGETS",
    "Budget",
    "check_budget",
    "check_seeds",
    "get_budget",
]

#: Episodes between the checkpoints of the runs of ``compare``, ``reproduce`` and distributed workers: an
#: interrupted run goes on from its last one. Saving one takes about 0.1 s with the tuned settings' 200 000-transition
#: replay buffer.
CHECKPOINT_EVERY = 25


@dataclass(frozen=True)
class Budget:
    """
    The scale of an experiment.

    :param name: budget name (``--budget``)
    :param episodes: training episodes per run (the paper: 500)
    :param long_episodes: the longer "reality" training of Table II (the paper: 700)
    :param eval_episodes: test episodes per run (the paper: 20, with Rayleigh fading)
    :param seeds: default number of seeds per configuration
    :param scenario: scenario name (None: the env's default, ``mall``)
    :param paper_task_episodes: training episodes of the paper-task runs, whose episodes last up to 1000 steps
        (None: ``episodes``)
    """

    name: str
    episodes: int
    long_episodes: int
    eval_episodes: int
    seeds: int
    scenario: str | None = None
    paper_task_episodes: int | None = None

    @property
    def task_episodes(self) -> int:
        """Training episodes of the paper-task runs."""
        return self.episodes if self.paper_task_episodes is None else self.paper_task_episodes

    @property
    def task_long_episodes(self) -> int:
        """Training episodes of the paper-task runs trained in "reality": :attr:`task_episodes` made longer as
        ``long_episodes`` is longer than ``episodes`` (the paper: 700)."""
        return round(self.task_episodes * self.long_episodes / self.episodes)

    def run_spec(self, algo: str, multiple_access: str, seed: int, episodes: int | None = None, **fields: Any) -> RunSpec:
        """
        A run at this scale: on the budget's scenario, tested on its number of test episodes.

        :param algo: the run's algorithm (:attr:`RunSpec.algo`)
        :param multiple_access: ``"noma"`` or ``"oma"``
        :param seed: training seed
        :param episodes: training episodes (None: :attr:`episodes`)
        :param fields: the run's other fields (:class:`RunSpec`)
        :return: the run
        """
        episodes = self.episodes if episodes is None else episodes
        return RunSpec(
            algo, multiple_access, seed, episodes, scenario=self.scenario, eval_episodes=self.eval_episodes, **fields
        )


#: ``tiny`` runs the whole pipeline on the ``small`` scenario in minutes (too short to learn: a check that it runs; its
#: paper-task runs train 3 episodes, since those last up to 1000 steps);
#: ``smoke`` is the shortest budget that shows learning: 150 episodes on ``small``, where DT-DPG brings both robots
#: home on the test missions (measured, docs/BENCHMARKS.md); ``default`` is the main job's (``compare``: 2 min 28 s
#: on a 2-vCPU VM, docs/BENCHMARKS.md); ``mall-200`` and ``small-200`` are the paper's experiments with 200/280
#: episodes instead of 500/700 on ``mall`` and on ``small``, 3 seeds; ``paper`` is the paper's scale; ``paper-x4``
#: four times its training episodes (where the learners begin to use the radio map, docs/RESULTS.md). ``_micro`` is
#: for the tests.
BUDGETS: dict[str, Budget] = {
    "_micro": Budget("_micro", episodes=3, long_episodes=4, eval_episodes=2, seeds=2, scenario="small"),
    "tiny": Budget("tiny", episodes=36, long_episodes=50, eval_episodes=5, seeds=2, scenario="small", paper_task_episodes=3),
    "smoke": Budget("smoke", episodes=150, long_episodes=200, eval_episodes=20, seeds=1, scenario="small"),
    "default": Budget("default", episodes=250, long_episodes=350, eval_episodes=20, seeds=1),
    "mall-200": Budget("mall-200", episodes=200, long_episodes=280, eval_episodes=20, seeds=3),
    "small-200": Budget("small-200", episodes=200, long_episodes=280, eval_episodes=20, seeds=3, scenario="small"),
    "paper": Budget("paper", episodes=500, long_episodes=700, eval_episodes=20, seeds=5),
    "paper-x4": Budget("paper-x4", episodes=2000, long_episodes=2800, eval_episodes=20, seeds=5),
}
#: The old names, which did not say what they run: ``small`` ran on ``mall``, ``reduced`` on ``small``.
BUDGET_ALIASES: dict[str, str] = {"small": "mall-200", "reduced": "small-200"}
BUDGETS.update({old: BUDGETS[new] for old, new in BUDGET_ALIASES.items()})


#: The budgets a user picks by name (``_micro`` is for the tests, the aliases are the old names).
PUBLIC_BUDGETS: tuple[str, ...] = tuple(name for name in BUDGETS if not name.startswith("_") and name not in BUDGET_ALIASES)


def get_budget(budget: str | Budget) -> Budget:
    """
    :param budget: a name of :data:`BUDGETS` or a :class:`Budget`
    :return: the budget
    :raises ValueError: naming the known budgets when the name is unknown
    """
    if isinstance(budget, Budget):
        return budget
    if budget not in BUDGETS:
        raise ValueError(f"budget must be one of {', '.join(PUBLIC_BUDGETS)}, got {budget!r}")
    return BUDGETS[budget]


def check_seeds(seeds: object) -> None:
    """
    :param seeds: the number of seeds per configuration of a job
    :raises ValueError: unless it is an integer in [1, :data:`MAX_SEEDS`]
    """
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= MAX_SEEDS:
        raise ValueError(f"seeds must be an integer from 1 to {MAX_SEEDS:,} (seeds 0..N-1 per configuration), got {seeds!r}")


def check_budget(spec: RunSpec) -> None:
    """
    :param spec: a run on a mission env
    :raises ValueError: when its budget cannot train: at most ``episodes x mission.max_steps`` env steps (or
        ``timesteps``), no more than the algorithm's ``learning_starts`` (:func:`sb3_dtdpg.baselines.check_training_budget`)
    """
    import gymnasium as gym

    from noma_radiomap import load_scenario
    from noma_radiomap.core import task_scenario
    from sb3_dtdpg.baselines import check_training_budget, hyperparameter

    learning_starts = int(
        spec.override_kwargs.get("learning_starts", hyperparameter(spec.algo, "learning_starts", spec.hyperparams))
    )
    if spec.timesteps is not None:
        check_training_budget(spec.timesteps, learning_starts, f"{spec.timesteps} env steps ({spec.run_id})")
        return
    registered = gym.spec(spec.env_id).kwargs
    scenario = spec.scenario or registered.get("scenario", "mall")
    max_steps = int(task_scenario(load_scenario(scenario), registered.get("task", "missions")).mission.max_steps)
    check_training_budget(
        spec.episodes * max_steps,
        learning_starts,
        f"{spec.episodes} episodes of at most {max_steps} steps ({spec.run_id})",
        "train for more episodes (a larger budget)",
    )
