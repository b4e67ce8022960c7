"""The runs of ``reproduce`` / ``compare`` spread over machines through an Optuna storage (docs/SCALING.md).

Every run (algorithm x mode x seed x experiment) is independent. A worker on any machine builds the same run
list, joins one Optuna study on a shared storage (JournalFile on a shared disk, or PostgreSQL, as for the zoo's
hyperparameter search in docs/ZOO.md) whose ``GridSampler`` hands each run to one worker, and runs it into a
shared output folder (``<out>/runs/<run_id>/result.json``, written last). Finished runs are skipped, so a
restarted worker resumes. ``sb3-dtdpg reproduce --report-only --out <out>`` (or ``compare`` again) then draws
the tables from the gathered results.

Usage, on every machine (the options and defaults of ``sb3-dtdpg reproduce`` / ``compare``, so that the same
options on the CLI later find the same runs)::

    python -m sb3_dtdpg.experiments.distributed reproduce --budget paper --out /shared/reproduce \\
        --storage postgresql://optuna@dbhost:5432/optuna --study-name reproduce-paper
"""

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sb3_dtdpg.experiments.runs import RunSpec, get_budget, load_result, run_one


def study_specs(
    job: str,
    budget: str = "paper",
    seeds: int | None = None,
    hyperparams: str = "tuned",
    observation: str | None = "goal",
    experiments: Sequence[str] | None = None,
    multiple_access: Sequence[str] | None = None,
    algos: Sequence[str] | None = None,
    env_id: str | None = None,
    scenario: str | None = None,
) -> list[RunSpec]:
    """
    The runs of a job, in the order ``reproduce`` / ``compare`` run them (the same list on every machine).

    :param job: ``"reproduce"`` or ``"compare"`` (with its default algorithms)
    :param budget: a budget name
    :param seeds: seeds per configuration (None: the budget's)
    :param hyperparams: ``"tuned"`` (the CLI's default) or ``"paper"``
    :param observation: ``"goal"``, ``"destinations"`` or ``"paper"`` (None, ``compare`` only: the env id's)
    :param experiments: ``reproduce`` only: the runs of these experiments (None: those ``sb3-dtdpg reproduce``
        trains by default, all but ``paper_task_reality``)
    :param multiple_access: the downlink modes (None: ``noma`` and ``oma``)
    :param algos: ``compare`` only: the algorithms (None: ``dtdpg`` and ``ddpg``)
    :param env_id: ``compare`` only: the env id (None: ``NomaRadioMap-v0``)
    :param scenario: ``compare`` only: the scenario (None: the budget's)
    :return: the unique runs
    """
    plan = get_budget(budget)
    seeds = plan.seeds if seeds is None else seeds
    modes = list(dict.fromkeys(multiple_access or ("noma", "oma")))
    if job == "reproduce":
        from sb3_dtdpg.experiments.reproduce import DEFAULT_EXPERIMENTS, reproduce_specs

        by_experiment = reproduce_specs(plan, seeds, hyperparams, observation)
        chosen = [spec for name in (experiments or DEFAULT_EXPERIMENTS) for spec in by_experiment[name]]
        unique = list({spec.run_id: spec for spec in chosen if spec.multiple_access in modes}.values())
        return sorted(unique, key=lambda spec: spec.seed)
    if experiments is not None:
        raise ValueError("experiments: only the reproduce job has experiments")
    if job == "compare":
        from sb3_dtdpg.baselines import DEFAULT_ENV_ID
        from sb3_dtdpg.experiments.compare import compare_job

        algos = algos or ("dtdpg", "ddpg")
        return compare_job(plan, seeds, algos, modes, env_id or DEFAULT_ENV_ID, scenario, hyperparams, observation).specs
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


def build_parser() -> argparse.ArgumentParser:
    """:return: the worker's parser: per job, the options of ``sb3-dtdpg <job>`` that pick its runs, same defaults"""
    from sb3_dtdpg import cli

    parser = argparse.ArgumentParser(
        prog="python -m sb3_dtdpg.experiments.distributed", description=__doc__.splitlines()[0], allow_abbrev=False
    )
    jobs = parser.add_subparsers(dest="job", required=True, metavar="{reproduce,compare}")
    for job, budget in (("reproduce", "tiny"), ("compare", "default")):
        p = jobs.add_parser(
            job,
            help=f"the runs of sb3-dtdpg {job}",
            description=f"Take runs of sb3-dtdpg {job} from a shared Optuna study; the options and defaults are "
            f"those of sb3-dtdpg {job}, so that it finds the same runs in --out.",
            allow_abbrev=False,
        )
        p.set_defaults(error=p.error)
        p.add_argument("--budget", type=cli._budget, default=budget, help=f"budget name (default: {budget}, as for the CLI)")
        cli._add_seeds(p)  # --n-seeds (and the deprecated --seeds)
        where = "" if job == "reproduce" else " where every algorithm has it, else paper"
        preset_help = f"hyperparameter set (default: tuned{where})"
        p.add_argument("--preset", choices=cli._PRESETS, default="tuned" if job == "reproduce" else None, help=preset_help)
        p.add_argument(
            "--hyperparams",
            choices=cli._PRESETS,
            dest="preset",
            action=cli._DeprecatedOption,
            replacement="--preset",
            help=argparse.SUPPRESS,
        )
        if job == "compare":
            p.add_argument(
                "--algos", nargs="+", choices=cli._ALGORITHMS, default=None, help="algorithms (default: dtdpg ddpg)"
            )
            p.add_argument(
                "--env", type=cli._env_id, default=None, help=f"a NomaRadioMap env id (default: {cli._DEFAULT_ENV_ID})"
            )
            p.add_argument(
                "--scenario", type=cli._scenario, default=None, help="scenario name or YAML path (default: the budget's)"
            )
        observation = "goal" if job == "reproduce" else None
        p.add_argument(
            "--observation",
            choices=cli._OBSERVATIONS,
            default=observation,
            help="observation (default: goal" + ("" if observation else "; paper for the paper task's env id") + ")",
        )
        p.add_argument(
            "--multiple-access", nargs="+", choices=cli._MODES, default=None, help="downlink modes (default: noma oma)"
        )
        if job == "reproduce":
            p.add_argument(
                "--experiments",
                nargs="+",
                choices=cli._EXPERIMENTS,
                default=None,
                help="the runs of these experiments (default: all but paper_task_reality, as for the CLI)",
            )
        p.add_argument("--out", type=cli._output_folder, required=True, help="the output folder shared by the workers")
        p.add_argument("--storage", required=True, help="Optuna storage URL, or a .log path (JournalFile)")
        p.add_argument("--study-name", required=True)
    return parser


def main(argv: list[str] | None = None) -> None:
    from sb3_dtdpg import cli
    from sb3_dtdpg.experiments.runs import DamagedRecordError, RunDivergedError, RunMismatchError, check_budget

    args = build_parser().parse_args(argv)
    try:
        import optuna  # noqa: F401
    except ModuleNotFoundError:
        args.error("the workers need the 'zoo' extra (optuna is not installed): pip install -e \".[zoo]\" in your clone")
    try:
        specs = study_specs(
            args.job,
            args.budget,
            args.n_seeds,
            args.preset or cli.default_preset(args.algos or ("dtdpg", "ddpg")),
            args.observation,
            getattr(args, "experiments", None),
            args.multiple_access,
            getattr(args, "algos", None),
            getattr(args, "env", None),
            getattr(args, "scenario", None),
        )
        for spec in specs:
            check_budget(spec)
    except ValueError as error:
        args.error(str(error))
    try:
        done = run_study_worker(specs, args.out, args.storage, args.study_name)
    except (RunMismatchError, RunDivergedError, DamagedRecordError) as error:  # what the CLI reports as one line
        args.error(str(error))
    print(f"{len(done)} runs of {len(specs)} done by this worker")


if __name__ == "__main__":
    main()
