"""The runs of ``reproduce`` / ``compare`` spread over machines through an Optuna storage (docs/SCALING.md).

Every run (algorithm x mode x seed x experiment) is independent. A worker on any machine builds the same run
list, joins one Optuna study on a shared storage (JournalFile on a shared disk, or PostgreSQL, as for the zoo's
hyperparameter search in docs/ZOO.md) whose ``GridSampler`` hands each run to one worker, and runs it into a
shared output folder (``<out>/runs/<run_id>/result.json``, written last). A run's lock in the folder keeps a
second worker out of a run in training; a run without a result (interrupted, or its worker died) is taken again.
``sb3-dtdpg reproduce --report-only --out <out>`` (or ``compare`` again) then draws the tables from the results.

Usage, on every machine (the options and defaults of ``sb3-dtdpg reproduce`` / ``compare``, so that the same
options on the CLI later find the same runs)::

    python -m sb3_dtdpg.experiments.distributed reproduce --budget paper --out /shared/reproduce \\
        --storage postgresql://optuna@dbhost:5432/optuna --study-name reproduce-paper
"""

import argparse
import dataclasses
import functools
import hashlib
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sb3_dtdpg.common.files import json_default
from sb3_dtdpg.common.warning_lines import warnings_as_lines
from sb3_dtdpg.experiments.runs import (
    CHECKPOINT_EVERY,
    OutputBusyError,
    RunSpec,
    get_budget,
    load_result,
    result_path,
    run_one,
)
from sb3_dtdpg.experiments.storage import (  # output_lock's OS locks, held apart
    FOLDER_LOCK,
    hold_lock,
    load_results,
    run_lock_name,
)


class StudyError(ValueError):
    """The study cannot hand out this job's runs: its storage cannot be opened, or it holds another job's runs."""


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
    paper_task_presets: Sequence[str] | None = None,
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
    :param paper_task_presets: ``reproduce`` only: the paper-task experiments' runs of these hyperparameter sets
        (None: both)
    :return: the unique runs
    """
    plan = get_budget(budget)
    seeds = plan.seeds if seeds is None else seeds
    modes = list(dict.fromkeys(multiple_access or ("noma", "oma")))
    if job == "reproduce":
        from sb3_dtdpg.experiments.reproduce import job_specs

        return job_specs(plan, seeds, hyperparams, observation, experiments, modes, paper_task_presets)
    for name, value in (("experiments", experiments), ("paper_task_presets", paper_task_presets)):
        if value is not None:
            raise ValueError(f"{name}: only the reproduce job has {name.replace('_', ' ')}")
    if job == "compare":
        from sb3_dtdpg.baselines import DEFAULT_ENV_ID
        from sb3_dtdpg.experiments.compare import compare_job

        algos = algos or ("dtdpg", "ddpg")
        return compare_job(plan, seeds, algos, modes, env_id or DEFAULT_ENV_ID, scenario, hyperparams, observation).specs
    raise ValueError(f"job must be 'reproduce' or 'compare', got {job!r}")


def _run_lock(out: Path, spec: RunSpec) -> Path:
    """:return: a run's lock file, the one ``sb3-dtdpg train`` holds"""
    return out / run_lock_name(spec.run_id)


def _lock_is_free(path: Path) -> bool:
    """:return: whether no process holds the lock ``path`` (a file left by a killed holder is free)"""
    with hold_lock(path, shared=False) as free:
        return free


#: How a worker runs one spec: checkpointed; a run interrupted in training goes on from its last checkpoint, one
#: interrupted in its evaluations is evaluated again, not trained again.
_retest_or_run = functools.partial(run_one, retest=True, checkpoint_every=CHECKPOINT_EVERY)


def run_study_worker(
    specs: list[RunSpec],
    out: str | Path,
    storage: Any,
    study_name: str,
    n_runs: int | None = None,
    run: Callable[[RunSpec, str | Path], Any] = _retest_or_run,
) -> list[str]:
    """
    Take runs from a shared Optuna study until every run is finished, trained by another worker, or failed.

    A run is finished when its result file exists. The worker holds a shared hold of the folder's lock while it
    lives (a ``compare`` / ``reproduce`` job on the folder is refused, and refuses it), and a run's lock
    (``<out>/.<run_id>.lock``, that of ``sb3-dtdpg train``) while it trains the run: OS locks, released when
    the process ends, even when killed. While some run has no trial yet, the ``GridSampler`` hands one out; then
    the worker enqueues a trial for the first unfinished run whose lock is free (one that a worker was interrupted
    on, or whose worker died), and ends when none is left. A run whose attempt failed with an error (user
    attribute ``error`` of its failed trial) is not taken again: it would fail again.

    :param specs: the runs (:func:`study_specs`; the same list on every worker)
    :param out: the shared output folder
    :param storage: an Optuna storage or its URL (a ``.log`` path: a ``JournalFileStorage``)
    :param study_name: the study shared by the workers of one job
    :param n_runs: stop after training this many runs (None: until no run is left to take)
    :param run: the function that runs one spec, ``run(spec, out)`` (default: :func:`run_one` with ``retest=True``,
        which evaluates a run interrupted in its evaluations again instead of training it again; a function given
        here decides that itself; tests pass a cheap one)
    :return: the run ids this worker trained
    :raises OutputBusyError: a ``compare`` / ``reproduce`` job holds the folder
    :raises RunMismatchError: stored results in the folder are other runs' (checked for every run first, as
        ``compare`` / ``reproduce`` check them)
    :raises StudyError: the storage cannot be opened, or the study was made for another run list
    """
    import optuna

    if isinstance(storage, str):
        storage = _open_storage(storage)
    out, indices = Path(out), list(range(len(specs)))
    done: list[str] = []
    state: dict[str, Any] = {"failed": set(), "picked": None}

    def objective(trial: optuna.Trial) -> float:
        index = state["picked"] = trial.suggest_categorical("run", indices)
        spec = specs[index]
        trial.set_user_attr("run_id", spec.run_id)
        with hold_lock(_run_lock(out, spec), shared=False) as free:
            if not free or index in state["failed"] or load_result(out, spec) is not None:
                why = "another worker trains it" if not free else "failed before" if index in state["failed"] else "done"
                raise optuna.TrialPruned(f"{spec.run_id}: {why}")
            try:
                run(spec, out)
            except Exception as error:  # not a KeyboardInterrupt: an interrupted run is taken again
                trial.set_user_attr("error", f"{type(error).__name__}: {error}"[:500])
                raise
        done.append(spec.run_id)
        return 0.0

    handing_out = True  # the GridSampler still has runs that no trial took
    with hold_lock(out / FOLDER_LOCK, shared=True) as free:
        if not free:
            raise OutputBusyError(f"{out} is in use by another job (lock {out / FOLDER_LOCK}); wait for it to end")
        load_results(out, specs)  # a stored run of other settings is refused before anything trains
        sampler = optuna.samplers.GridSampler({"run": indices}, seed=0)
        study = optuna.create_study(storage=storage, study_name=study_name, sampler=sampler, load_if_exists=True)
        _check_study_runs(study, specs, study_name)
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        while n_runs is None or len(done) < n_runs:
            trials = study.get_trials(deepcopy=False)
            state["failed"] = {trial.params.get("run") for trial in trials if "error" in trial.user_attrs}
            left = [i for i in indices if i not in state["failed"] and not result_path(out, specs[i]).exists()]
            taken = {trial.params["run"] for trial in trials if "run" in trial.params}
            handing_out = handing_out and any(index not in taken for index in left)
            if not handing_out:  # every run left was handed out: take one that no live worker trains
                free_run = next((i for i in left if _lock_is_free(_run_lock(out, specs[i]))), None)
                if free_run is None:
                    break  # every run is finished, failed, or trained by another worker
                study.enqueue_trial({"run": free_run})
            state["picked"] = None
            study.optimize(objective, n_trials=1)
            handing_out = handing_out and state["picked"] not in taken  # a grid point handed out again: exhausted
    return done


def _open_storage(url: str) -> Any:
    """
    :param url: a ``.log`` path (a ``JournalFileStorage``) or a database URL
    :return: the Optuna storage
    :raises StudyError: naming ``--storage`` when it cannot be opened (a missing folder, a bad URL, no driver)
    """
    import optuna
    from optuna.storages import JournalStorage, RDBStorage
    from optuna.storages.journal import JournalFileBackend

    try:
        return JournalStorage(JournalFileBackend(url)) if url.endswith(".log") else RDBStorage(url)
    except (OSError, ValueError, ImportError, optuna.exceptions.OptunaError) as error:
        raise StudyError(f"--storage {url}: cannot open it ({type(error).__name__}: {error})") from None
    except Exception as error:  # SQLAlchemy's own errors (an unknown dialect, a refused connection)
        if type(error).__module__.startswith("sqlalchemy"):
            raise StudyError(f"--storage {url}: cannot open it ({type(error).__name__}: {error})") from None
        raise


def _runs_digest(specs: list[RunSpec]) -> str:
    """:return: a digest of every setting of every run (run ids alone do not name the budget or the room)"""
    text = json.dumps([dataclasses.asdict(spec) for spec in specs], sort_keys=True, default=json_default)
    return hashlib.sha256(text.encode()).hexdigest()


def _check_study_runs(study: Any, specs: list[RunSpec], study_name: str) -> None:
    """
    Record the job's runs (the digest of their settings) in a new study, and refuse a study made for other runs: its
    trials' run indices would name other runs (or the grid's choices would not fit).

    :raises StudyError: naming the study
    """
    digest = _runs_digest(specs)
    recorded = study.user_attrs.get("runs_digest")
    if recorded is None:
        study.set_user_attr("runs_digest", digest)
        study.set_user_attr("n_runs", len(specs))
    elif recorded != digest:
        raise StudyError(
            f"--study-name {study_name}: the study hands out the runs of another job ({study.user_attrs.get('n_runs')} "
            "runs, other options: budget, seeds, preset, ...): give each job, with its options, a study name of its own"
        )


def build_parser() -> argparse.ArgumentParser:
    """:return: the worker's parser: per job, the options of ``sb3-dtdpg <job>`` that pick its runs, same defaults"""
    from sb3_dtdpg import cli_parser

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
        p.set_defaults(error=p.error, prog=p.prog)
        p.add_argument(
            "--budget", type=cli_parser.budget_name, default=budget, help=f"budget name (default: {budget}, as for the CLI)"
        )
        cli_parser.add_seeds(p)  # --n-seeds (and the deprecated --seeds)
        where = cli_parser.PAPER_TASK_PRESET_NOTE if job == "reproduce" else " where every algorithm has it, else paper"
        preset_help = f"hyperparameter set (default: tuned{where})"
        p.add_argument("--preset", choices=cli_parser.PRESETS, default=None, help=preset_help)
        p.add_argument(
            "--hyperparams",
            choices=cli_parser.PRESETS,
            dest="preset",
            action=cli_parser.DeprecatedOption,
            replacement="--preset",
            help=argparse.SUPPRESS,
        )
        if job == "compare":
            p.add_argument(
                "--algos", nargs="+", choices=cli_parser.ALGORITHMS, default=None, help="algorithms (default: dtdpg ddpg)"
            )
            p.add_argument(
                "--env",
                type=cli_parser.registered_env_id,
                default=None,
                help=f"a NomaRadioMap env id (default: {cli_parser.DEFAULT_ENV_ID})",
            )
            p.add_argument(
                "--scenario",
                type=cli_parser.scenario_name,
                default=None,
                help="scenario name or YAML path (default: the budget's)",
            )
        observation = "goal" if job == "reproduce" else None
        p.add_argument(
            "--observation",
            choices=cli_parser.OBSERVATIONS,
            default=observation,
            help="observation (default: goal" + ("" if observation else "; paper for the paper task's env id") + ")",
        )
        p.add_argument(
            "--multiple-access", nargs="+", choices=cli_parser.MODES, default=None, help="downlink modes (default: noma oma)"
        )
        if job == "reproduce":
            p.add_argument(
                "--experiments",
                nargs="+",
                choices=cli_parser.EXPERIMENTS,
                default=None,
                help="the runs of these experiments (default: all but paper_task_reality, as for the CLI)",
            )
        p.add_argument("--out", type=cli_parser.output_folder, required=True, help="the output folder shared by the workers")
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
            args.preset or cli.default_preset(getattr(args, "algos", None) or ("dtdpg", "ddpg")),
            args.observation,
            getattr(args, "experiments", None),
            args.multiple_access,
            getattr(args, "algos", None),
            getattr(args, "env", None),
            getattr(args, "scenario", None),
            [args.preset] if args.job == "reproduce" and args.preset else None,
        )
        for spec in specs:
            check_budget(spec)
    except ValueError as error:
        args.error(str(error))
    try:
        with warnings_as_lines(args.prog):  # one line each, the workers' too, as the sb3-dtdpg commands show them
            done = run_study_worker(specs, args.out, args.storage, args.study_name)
    except (RunMismatchError, RunDivergedError, DamagedRecordError, OutputBusyError, StudyError) as error:  # one line
        args.error(str(error))
    except KeyboardInterrupt:
        print(
            f"interrupted: when a worker takes the run again, it goes on from its last checkpoint (every "
            f"{CHECKPOINT_EVERY} episodes), or is only tested again if it was in its test episodes",
            file=sys.stderr,
        )
        raise SystemExit(130) from None
    left = sum(not result_path(args.out, spec).exists() for spec in specs)
    print(
        f"{len(done)} runs of {len(specs)} done by this worker"
        + (f"; {left} not finished (training in other workers, or failed: the study's trials say which)" if left else "")
    )


if __name__ == "__main__":
    main()
