"""The runs of ``reproduce`` / ``compare`` spread over machines through an Optuna storage (docs/SCALING.md).

Every run (algorithm x mode x seed x experiment) is independent. A worker on any machine builds the same run
list, joins one Optuna study on a shared storage (JournalFile on a shared disk, or PostgreSQL, as for the zoo's
hyperparameter search in docs/ZOO.md) whose ``GridSampler`` hands each run to one worker, and runs it into a
shared output folder (``<out>/runs/<run_id>/result.json``, written last). Finished runs are skipped, so a
restarted worker resumes. ``sb3-dtdpg reproduce --report-only --out <out>`` (or ``compare`` again) then draws
the tables from the gathered results.

Usage, on every machine::

    python -m sb3_dtdpg.experiments.distributed reproduce --budget paper --out /shared/reproduce \\
        --storage postgresql://optuna@dbhost:5432/optuna --study-name reproduce-paper
"""

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sb3_dtdpg.experiments.runs import RunSpec, get_budget, load_result, run_one


def study_specs(job: str, budget: str = "paper", seeds: int | None = None, hyperparams: str = "paper") -> list[RunSpec]:
    """
    The runs of a job, in the order ``reproduce`` / ``compare`` run them (the same list on every machine).

    :param job: ``"reproduce"`` or ``"compare"`` (with its default algorithms and modes)
    :param budget: a budget name
    :param seeds: seeds per configuration (None: the budget's)
    :param hyperparams: ``"paper"`` or ``"tuned"``
    :return: the unique runs
    """
    plan = get_budget(budget)
    seeds = plan.seeds if seeds is None else seeds
    if job == "reproduce":
        from sb3_dtdpg.experiments.reproduce import reproduce_specs

        experiments = reproduce_specs(plan, seeds, hyperparams)
        unique = list({spec.run_id: spec for specs in experiments.values() for spec in specs}.values())
        return sorted(unique, key=lambda spec: spec.seed)
    if job == "compare":
        from sb3_dtdpg.baselines import DEFAULT_ENV_ID
        from sb3_dtdpg.experiments.compare import compare_specs

        return compare_specs(plan, seeds, ["dtdpg", "ddpg"], ["noma", "oma"], DEFAULT_ENV_ID, hyperparams)
    raise ValueError(f"job must be 'reproduce' or 'compare', got {job!r}")


def run_study_worker(
    specs: list[RunSpec],
    out: str | Path,
    storage: Any,
    study_name: str,
    n_runs: int | None = None,
    run: Callable[[RunSpec, str | Path], Any] = run_one,
) -> list[str]:
    """
    Take runs from a shared Optuna study (a ``GridSampler`` over the run indices) until none is left.

    :param specs: the runs (:func:`study_specs`; the same list on every worker)
    :param out: the shared output folder
    :param storage: an Optuna storage or its URL (a ``.log`` path: a ``JournalFileStorage``)
    :param study_name: the study shared by the workers of one job
    :param n_runs: stop after this many runs (None: until the grid is exhausted)
    :param run: the function that runs one spec (tests pass a cheap one)
    :return: the run ids this worker ran (a run found finished is not run again)
    """
    import optuna

    if isinstance(storage, str) and storage.endswith(".log"):
        from optuna.storages import JournalStorage
        from optuna.storages.journal import JournalFileBackend

        storage = JournalStorage(JournalFileBackend(storage))
    indices = list(range(len(specs)))
    sampler = optuna.samplers.GridSampler({"run": indices}, seed=0)
    study = optuna.create_study(storage=storage, study_name=study_name, sampler=sampler, load_if_exists=True)
    done: list[str] = []
    taken = {trial.params.get("run") for trial in study.get_trials(deepcopy=False) if trial.state.is_finished()}
    if taken >= set(indices):
        return done  # every run was handed out (GridSampler would re-run one)

    def objective(trial: optuna.Trial) -> float:
        spec = specs[trial.suggest_categorical("run", indices)]
        trial.set_user_attr("run_id", spec.run_id)
        if load_result(out, spec) is None:
            run(spec, out)
            done.append(spec.run_id)
        return 0.0

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study.optimize(objective, n_trials=n_runs)
    return done


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("job", choices=("reproduce", "compare"))
    parser.add_argument("--budget", default=None, help="budget name (default: paper for reproduce, default for compare)")
    parser.add_argument("--seeds", type=int, default=None)
    parser.add_argument("--hyperparams", default="paper")
    parser.add_argument("--out", required=True, help="the output folder shared by the workers")
    parser.add_argument("--storage", required=True, help="Optuna storage URL, or a .log path (JournalFile)")
    parser.add_argument("--study-name", required=True)
    args = parser.parse_args(argv)
    budget = args.budget or ("paper" if args.job == "reproduce" else "default")
    specs = study_specs(args.job, budget, args.seeds, args.hyperparams)
    done = run_study_worker(specs, args.out, args.storage, args.study_name)
    print(f"{len(done)} runs of {len(specs)} done by this worker")


if __name__ == "__main__":
    main()
