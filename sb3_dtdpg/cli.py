"""The ``sb3-dtdpg`` command line.

Subcommands:

- ``map``: the power and SINR maps of a scenario (the paper's Fig. 4);
- ``train``: one training run on any registered env id, with TensorBoard logging, then its test evaluation; on
  the NomaRadioMap envs with periodic checkpoints (the same command resumes it);
- ``compare``: the main job: DT-DPG vs DDPG in NOMA and OMA, several seeds in parallel, the results
  table (printed, Markdown, CSV) with the planners as references, learning curves and trajectories;
- ``reproduce``: every experiment of the paper's Section V, resumable;
- ``evaluate``: a saved model on the test missions (the paper's 20 Rayleigh episodes), the table of ``compare``;
- ``enjoy``: one mission of a saved model, printed, or ``--record``-ed as a GIF/MP4 (headless).

Conventions: ``--out`` is always an output *folder* (created if missing); ``--n-seeds`` is a number of seeds,
``--seed`` the seed of one run; ``--multiple-access`` takes the mode(s), ``noma`` and/or ``oma``. A user error
(an unknown scenario or env id, a bad YAML file, a budget that cannot train, a seed or learning rate out of
range, a folder in use by another job) is one ``error:`` line after the subcommand's usage, with exit status 2,
as argparse reports a bad option, before anything is created. Abbreviated options are not accepted.

``--preset`` picks a hyperparameter set (``tuned``, ``paper``); ``--hyperparams key:value ...`` overrides single
values, as in the RL Zoo. ``sb3-dtdpg --help`` imports neither torch nor Stable-Baselines3: the commands import
what they need when they run.

The parser (the options, their types and help texts) is :func:`sb3_dtdpg.cli_parser.build_parser`; this module holds
the commands, and :func:`main` runs the one the parser's ``command`` names.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from sb3_dtdpg.cli_parser import DEFAULT_ENV_ID, PRESETS, build_parser
from sb3_dtdpg.common.warning_lines import warnings_as_lines

__all__ = ["build_parser", "main"]


@contextlib.contextmanager
def _user_errors(args: argparse.Namespace) -> Iterator[None]:
    """Report a ``ValueError`` of the enclosed checks as a usage error of the subcommand (exit status 2)."""
    try:
        yield
    except ValueError as error:
        args.error(str(error))


def _not_enough_memory(args: argparse.Namespace, error: MemoryError) -> None:
    """Report a ``MemoryError`` of building or training a model as a usage error (the settings ask too much)."""
    args.error(f"not enough memory for this run ({error or 'MemoryError'}): lower buffer_size or batch_size")


def _busy_folder_errors(args: argparse.Namespace) -> contextlib.AbstractContextManager[None]:
    """
    A folder in use by another job (``OutputBusyError``), one holding another run under the same id
    (``RunMismatchError``), a run record or checkpoint damaged from outside (``DamagedRecordError``, naming the
    file and what to delete) or a run whose training diverged (``RunDivergedError``, e.g. a learning rate far too
    large) as one ``error:`` line of the subcommand (exit status 2). Other errors (a ``ValueError`` of training
    itself, say) keep their traceback.
    """
    from sb3_dtdpg.experiments.runs import DamagedRecordError, OutputBusyError, RunDivergedError, RunMismatchError

    @contextlib.contextmanager
    def guard() -> Iterator[None]:
        try:
            yield
        except (OutputBusyError, RunMismatchError, DamagedRecordError, RunDivergedError) as error:
            args.error(str(error))

    return guard()


def _failed_runs_status(args: argparse.Namespace, job: Callable[[argparse.Namespace], None]) -> int:
    """
    Run a ``compare`` or ``reproduce`` job; runs that failed (``RunsFailedError``, raised after the tables of the others
    are written) are one ``error:`` line and exit status 1.

    :return: the exit status
    """
    from sb3_dtdpg.experiments.runs import RunsFailedError

    try:
        job(args)
    except RunsFailedError as error:
        print(f"{args.prog}: error: {error}", file=sys.stderr)
        return 1
    return 0


def _split_hyperparams(args: argparse.Namespace) -> None:
    """
    ``--hyperparams`` holds ``key:value`` overrides; a lone preset name there (the old meaning) is taken as
    ``--preset`` with a deprecation warning. Sets ``args.preset`` and ``args.overrides``.
    """
    from sb3_dtdpg.overrides import parse_overrides

    items = list(getattr(args, "hyperparams", None) or [])
    if len(items) == 1 and items[0] in PRESETS:
        if args.preset is not None and args.preset != items[0]:
            args.error(f"--hyperparams {items[0]} and --preset {args.preset}: give the preset once, with --preset")
        print(f"{args.prog}: warning: --hyperparams {items[0]} is deprecated, use --preset {items[0]}", file=sys.stderr)
        args.preset, items = items[0], []
    with _user_errors(args):
        args.overrides = parse_overrides(items)


def default_preset(algos: Sequence[str]) -> str:
    """:return: the hyperparameter set of the algorithms when none is given: ``tuned`` where every one has it"""
    return "tuned" if all(algo in ("dtdpg", "ddpg") for algo in algos) else "paper"


def _hyperparams(args: argparse.Namespace, algos: Sequence[str]) -> str:
    """The hyperparameter set of a command: ``--preset``, else ``tuned`` where every algorithm has it."""
    _split_hyperparams(args)
    if args.preset is not None:
        return args.preset
    if default_preset(algos) == "tuned":
        return "tuned"
    if len(algos) > 1:
        print(
            f"{args.prog}: note: --preset paper (Table I) for every algorithm, as {', '.join(algos)} have no common tuned set",
            file=sys.stderr,
        )
    return "paper"


def _cmd_map(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from noma_radiomap import RadioMap, load_scenario
    from sb3_dtdpg.common.files import safe_name
    from sb3_dtdpg.experiments.plots import save_and_close

    scenario = load_scenario(args.scenario)
    out = Path(args.out)
    path = out / f"maps_{safe_name(scenario.name)}.png"  # the name is user text: never a path
    if path.is_dir():
        args.error(f"--out: {str(path)!r} is a folder, where the figure of scenario {scenario.name!r} goes")
    out.mkdir(parents=True, exist_ok=True)
    radio_map = RadioMap.for_scenario(scenario)
    save_and_close(radio_map.plot_maps(), path)
    print(f"wrote {path} (outage share with full power to one robot: {100 * radio_map.outage_share():.1f} % of free cells)")
    return 0


def _train_env(args: argparse.Namespace) -> tuple[Any, bool]:
    """The training env of ``train``: mission options for the mission envs only, checked before anything runs."""
    from sb3_dtdpg.baselines import default_observation_of, is_mission_env, make_env

    mission = is_mission_env(args.env)
    options = {
        "--scenario": args.scenario,
        "--multiple-access": args.multiple_access,
        "--channel": args.channel,
        "--observation": args.observation,
    }
    given = [name for name, value in options.items() if value is not None]
    if not mission and given:
        args.error(f"{', '.join(given)}: {args.env} is not a NomaRadioMap env; these options apply to the mission envs only")
    env_kwargs = {} if args.scenario is None else {"scenario": args.scenario}
    if mission:
        args.observation = args.observation or default_observation_of(args.env)
        env_kwargs["observation"] = args.observation
    import gymnasium as gym

    with _user_errors(args):
        try:
            env = make_env(args.algo, args.env, args.multiple_access, args.channel, env_kwargs)
        except gym.error.Error as error:  # e.g. DependencyNotInstalled: a registered id whose package is missing
            args.error(f"--env {args.env} cannot be made here: {type(error).__name__}: {error}")
    return env, mission


#: Constructor arguments that ``train`` sets from its own options, never from ``--hyperparams``.
_SET_BY_OPTIONS = {"seed": "--seed", "verbose": "--verbose", "tensorboard_log": "--tb"}
#: Set by a mission run of ``train`` too (the other envs train outside the run folders and take them as given).
_SET_BY_MISSION_RUNS = {
    "curriculum_save_path": "--out (each run saves its phase models in its own folder, <out>/runs/<run id>)",
}


def _is_mission_id(env_id: str) -> bool:
    """Whether ``env_id`` is a mission env; False for an id that is not registered (refused with its own message)."""
    import gymnasium as gym

    from sb3_dtdpg.baselines import is_mission_env

    try:
        return is_mission_env(env_id)
    except gym.error.Error:
        return False


def _cmd_train(args: argparse.Namespace) -> int:
    import torch as th

    from sb3_dtdpg.baselines import algorithm_class, check_hyperparams, check_training_budget, hyperparameter, make_model
    from sb3_dtdpg.overrides import check_constructor_kwargs

    args.hyperparams = _hyperparams(args, [args.algo])
    args.tb = args.tb or str(Path(args.out) / "tb")  # a run's logs live with its results, under its lock
    with _user_errors(args):
        check_hyperparams(args.algo, args.hyperparams)
        reserved = {**_SET_BY_OPTIONS, **(_SET_BY_MISSION_RUNS if _is_mission_id(args.env) else {})}
        check_constructor_kwargs(algorithm_class(args.algo), args.overrides, " (--hyperparams)", reserved=reserved)
    if "learning_rate" in args.overrides:
        if args.learning_rate is not None:
            args.error("--learning-rate and --hyperparams learning_rate:...: give the learning rate once")
        args.learning_rate = args.overrides.pop("learning_rate")
    if args.threads:
        th.set_num_threads(args.threads)
    env, mission = _train_env(args)
    given = ",".join(f"{name}:{value!r}" for name, value in args.overrides.items())
    with _user_errors(args):  # what the constructor refuses, before anything is written
        try:
            make_model(
                args.algo,
                env,
                learning_rate=args.learning_rate,
                hyperparams=args.hyperparams,
                _init_setup_model=bool(args.overrides),  # the networks and buffer with what the user gave
                **args.overrides,
            )
        except TypeError as error:
            if not args.overrides:
                raise
            args.error(f"--hyperparams {given}: the model cannot be built with these ({error})")
        except MemoryError as error:
            _not_enough_memory(args, error)
    max_steps = int(env.unwrapped.scenario.mission.max_steps) if mission else env.spec.max_episode_steps
    if args.timesteps is None and max_steps is None:
        args.error(f"--episodes: {args.env} has no episode step limit to turn episodes into steps; give --timesteps")
    if args.timesteps is not None:
        total, budget = args.timesteps, f"--timesteps {args.timesteps}"
    else:
        total, budget = args.episodes * max_steps, f"--episodes {args.episodes} (at most {args.episodes * max_steps} steps)"
    with _user_errors(args):
        learning_starts = int(
            args.overrides.get("learning_starts", hyperparameter(args.algo, "learning_starts", args.hyperparams))
        )
        check_training_budget(total, learning_starts, budget, "give more --episodes or --timesteps")
    if mission:
        multiple_access, channel = env.unwrapped.multiple_access, env.unwrapped.channel
        env.close()
        return _train_mission(args, multiple_access, channel)
    return _train_any_env(args, env)


def _train_mission(args: argparse.Namespace, multiple_access: str, channel: str) -> int:
    """``train`` on a NomaRadioMap env: a run of :func:`sb3_dtdpg.experiments.runs.run_one`, checkpointed."""
    from sb3_dtdpg.evaluation import format_ci
    from sb3_dtdpg.experiments.runs import DamagedRecordError, RunSpec, output_lock, read_checkpoint, run_one
    from sb3_dtdpg.experiments.storage import TRAINED_RECORD, run_lock_name
    from sb3_dtdpg.overrides import override_text

    spec = RunSpec(
        args.algo,
        multiple_access,
        args.seed,
        None if args.timesteps is not None else args.episodes,  # the budget it trains for, not --episodes' default
        channel=channel,
        learning_rate=args.learning_rate,
        env_id=args.env,
        scenario=args.scenario,
        eval_episodes=args.eval_episodes,
        eval_seed=args.eval_seed,
        eval_before_transfer=False,
        hyperparams=args.hyperparams,
        timesteps=args.timesteps,
        observation=args.observation,
        overrides=tuple((name, override_text(value)) for name, value in args.overrides.items()),
        tag=args.tag,
    )
    out = Path(args.out)
    run_dir = out / "runs" / spec.run_id
    try:
        with _busy_folder_errors(args), output_lock(out, run_lock_name(spec.run_id)):
            result = run_one(
                spec,
                out,
                tensorboard_dir=args.tb,
                checkpoint_every=args.checkpoint_every,
                resume=True,
                threads=args.threads or None,
                progress_bar=not args.no_progress,
                verbose=args.verbose,
            )
    except MemoryError as error:
        _not_enough_memory(args, error)
    except KeyboardInterrupt:
        try:
            checkpoint = read_checkpoint(run_dir)
        except DamagedRecordError as error:  # changed from outside while the run trained
            print(f"interrupted: {error}", file=sys.stderr)
            return 130
        if (run_dir / TRAINED_RECORD).is_file() and (run_dir / "model.zip").is_file():
            saved = f"training had finished and the model is in {run_dir / 'model.zip'}"
            print(f"interrupted in the test episodes: {saved}; run the same command again to test it", file=sys.stderr)
            return 130
        if checkpoint is None:
            saved = f"nothing saved yet (the first checkpoint comes after {args.checkpoint_every} episodes)"
        else:
            saved = f"the checkpoint after {checkpoint['episodes']} episodes is in {checkpoint['path']}"
        print(f"interrupted: {saved}; run the same command again to resume from there", file=sys.stderr)
        return 130
    summary = result["eval"]["summary"]
    resumed = result["train"].get("resumed_at_episode")
    # False: resumed from a checkpoint without a training state (an earlier version's), on a fresh env
    exact = result["train"].get("same_as_uninterrupted", False)
    reward_phase = result["reward_phases"]["evaluated"]  # the one it finished training on
    print(
        f"{spec.run_id}: {result['train']['timesteps']} steps, {result['train']['episodes']} episodes"
        + (f" (resumed after episode {resumed}{'' if exact else ', on a fresh env'})" if resumed is not None else "")
        + f", last reward phase {reward_phase!r}; test ({spec.eval_episodes} Rayleigh episodes, {reward_phase!r} "
        f"reward): success {100 * summary['success_rate']:.0f} %, MQI {format_ci(summary['mqi'], summary['mqi_ci'])}; "
        f"model: {run_dir / 'model.zip'}, result: {run_dir / 'result.json'}, TensorBoard: {Path(args.tb) / spec.run_id}"
    )
    return 0


def _train_any_env(args: argparse.Namespace, env: Any) -> int:
    """
    ``train`` on any other registered env id: SB3's ``learn`` with a checkpoint every ``--checkpoint-every``
    episodes' steps, from which the same command resumes (:mod:`sb3_dtdpg.experiments.env_runs`), then
    ``evaluate_policy``.
    """
    from sb3_dtdpg.common.files import safe_name
    from sb3_dtdpg.experiments.runs import output_lock
    from sb3_dtdpg.experiments.storage import run_lock_name

    run_name = f"{args.algo}_{safe_name(args.env)}_s{args.seed}" + (f"_{args.tag}" if args.tag else "")
    out = Path(args.out)
    if (out / f"{run_name}.zip").exists():  # a trained run: a new one would replace it
        args.error(
            f"--out {out} holds {run_name}.zip, the model of an earlier train of {args.algo} on {args.env} with seed "
            f"{args.seed}; move it, or use another --out, --seed or --tag"
        )
    try:
        with _busy_folder_errors(args), output_lock(out, run_lock_name(run_name)):
            return _train_any_env_run(args, env, run_name)
    finally:
        env.close()


def _any_env_settings(args: argparse.Namespace) -> dict[str, Any]:
    """What a run of ``train`` on another env trains with, by option dest: a resume must give the same."""
    from sb3_dtdpg.overrides import override_text

    return {
        "algo": args.algo,
        "env": args.env,
        "seed": args.seed,
        "preset": args.hyperparams,
        "hyperparams": " ".join(f"{name}:{override_text(value)}" for name, value in args.overrides.items()) or None,
        "learning_rate": args.learning_rate,
        "timesteps": args.timesteps,
        "episodes": None if args.timesteps is not None else args.episodes,
    }


def _any_env_logger(args: argparse.Namespace, run_name: str, resumed_at: int | None) -> Any:
    """
    The logger of a ``train`` run on another env: TensorBoard and ``progress.csv`` in ``<tb>/<run>_<N>``, a new
    ``N`` for a fresh run (SB3's numbering) and the last one for a resumed run, which keeps its logs up to the
    checkpoint and hides the interrupted attempt's after it (:func:`sb3_dtdpg.experiments.storage.run_logger`).
    """
    from stable_baselines3.common.utils import get_latest_run_id

    from sb3_dtdpg.experiments.storage import run_logger

    latest = get_latest_run_id(args.tb, run_name)
    resumed = resumed_at is not None and latest > 0
    folder = Path(args.tb) / f"{run_name}_{latest if resumed else latest + 1}"
    return run_logger(folder, args.verbose, resumed_at if resumed else None)


def _train_any_env_run(args: argparse.Namespace, env: Any, run_name: str) -> int:
    """:func:`_train_any_env` under the run's lock."""
    from stable_baselines3.common.evaluation import evaluate_policy

    from sb3_dtdpg.baselines import algorithm_class, make_model, mission_callbacks
    from sb3_dtdpg.common.checkpoints import checkpoint_steps
    from sb3_dtdpg.common.files import atomic_write, unused_path
    from sb3_dtdpg.experiments import env_runs
    from sb3_dtdpg.experiments.runs import EpisodeReturnLogger

    out = Path(args.out)
    max_steps = env.spec.max_episode_steps  # None: episodes never end on a limit, no checkpoint
    folder = env_runs.checkpoint_folder(out, run_name)
    model = None if max_steps is None else env_runs.resume(folder, _any_env_settings(args), env, algorithm_class(args.algo))
    resumed_at = None if model is None else model.num_timesteps
    if model is None:
        model = make_model(
            args.algo,
            env,
            seed=args.seed,
            tensorboard_log=args.tb,
            learning_rate=args.learning_rate,
            verbose=args.verbose,
            hyperparams=args.hyperparams,
            **args.overrides,
        )
    else:
        model.verbose = args.verbose
        print(f"{run_name}: resuming after {resumed_at} steps ({model._episode_num} episodes) from {folder}")
    model.set_logger(_any_env_logger(args, run_name, resumed_at))
    done = model._episode_num  # episodes trained before the checkpoint (0: a fresh run)
    if args.timesteps is not None:
        total, to_go = args.timesteps, args.timesteps - model.num_timesteps
        episodes = EpisodeReturnLogger(start=done)
    else:
        total, to_go = args.episodes * max_steps, args.episodes - done
        episodes = EpisodeReturnLogger(start=done, max_episodes=to_go)  # stops the training at --episodes
    callbacks = [episodes, *mission_callbacks(model)]
    if max_steps is not None:
        callbacks.append(env_runs.checkpoint_callback(folder, run_name, args.checkpoint_every * max_steps))
    try:
        if to_go > 0:  # 0: the checkpoint was saved as the training ended, before its model
            model.learn(
                total_timesteps=total - model.num_timesteps,
                callback=callbacks,
                log_interval=1,
                reset_num_timesteps=resumed_at is None,
                progress_bar=not args.no_progress,
            )
    except KeyboardInterrupt:  # as the RL Zoo does, the model so far is kept too
        model.logger.close()
        out.mkdir(parents=True, exist_ok=True)
        # A free name: the model of an earlier interruption of the same command stays
        saved = atomic_write(unused_path(out, f"{run_name}_interrupted", ".zip"), model.save)
        latest = None if max_steps is None else env_runs.latest_checkpoint(folder)
        if latest is not None:
            then = f"the same command resumes from the checkpoint after {checkpoint_steps(latest)} steps, {latest}"
        elif max_steps is None:
            then = f"{args.env} has no episode step limit, so no checkpoints: the same command starts afresh"
        else:
            then = f"no checkpoint yet (one every {args.checkpoint_every} episodes): the same command starts afresh"
        print(f"interrupted after {model.num_timesteps} steps: the model so far is in {saved}; {then}", file=sys.stderr)
        return 130
    model.logger.close()
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / f"{run_name}.zip", model.save)
    env_runs.remove_checkpoints(folder)
    eval_env = model.get_env()
    eval_env.seed(args.eval_seed)  # the test episodes' resets, as --eval-seed says (was the training env's next ones)
    try:
        mean, std = evaluate_policy(model, eval_env, n_eval_episodes=args.eval_episodes, deterministic=True)
    except KeyboardInterrupt:
        print(f"interrupted in the test episodes: the trained model is in {out / (run_name + '.zip')}", file=sys.stderr)
        return 130
    print(
        f"{run_name}: {model.num_timesteps} steps"
        + (f" (resumed after step {resumed_at})" if resumed_at is not None else "")
        + f"; test ({args.eval_episodes} episodes): reward {mean:.1f} ± {std:.1f}; model saved to "
        f"{out / (run_name + '.zip')}"
    )
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.experiments.compare import compare_job
    from sb3_dtdpg.experiments.runs import check_budget

    args.hyperparams = _hyperparams(args, args.algos)
    with _user_errors(args):
        job = compare_job(
            args.budget,
            args.n_seeds,
            args.algos,
            args.multiple_access,
            args.env,
            args.scenario,
            args.hyperparams,
            args.observation,
        )
        args.observation = job.observation
        for spec in job.specs:
            check_budget(spec)
    with _busy_folder_errors(args):
        return _failed_runs_status(args, _run_compare)


def _run_compare(args: argparse.Namespace) -> None:
    from sb3_dtdpg.experiments.compare import run_compare

    run_compare(
        args.out, scenario=args.scenario, algos=args.algos, modes=args.multiple_access, env_id=args.env, **_run_options(args)
    )


def _cmd_reproduce(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.baselines import check_hyperparams
    from sb3_dtdpg.experiments.reproduce import reproduce_specs
    from sb3_dtdpg.experiments.runs import BUDGETS, check_budget

    budget = BUDGETS[args.budget]
    args.hyperparams = _hyperparams(args, ("dtdpg", "ddpg"))
    with _user_errors(args):
        check_hyperparams("dtdpg", args.hyperparams)
        n_seeds = budget.seeds if args.n_seeds is None else args.n_seeds
        groups = reproduce_specs(budget, n_seeds, args.hyperparams, args.observation).values()
        specs = [spec for group in groups for spec in group]
        if args.report_only:
            _check_finished_runs(args, specs)
        else:
            for spec in specs:
                check_budget(spec)
    with _busy_folder_errors(args):
        status = _failed_runs_status(args, _run_reproduce)
    if args.budget != "paper":
        paper = BUDGETS["paper"]
        from noma_radiomap.observations import DEFAULT_OBSERVATION

        given = (  # a --preset given also picks the paper task's runs, even when it names the default set
            ("preset", args.hyperparams, args.preset is not None),
            ("observation", args.observation, args.observation != DEFAULT_OBSERVATION),
        )
        # the user's choices that are not the defaults: the same runs at the paper's scale
        chosen = "".join(f" --{option} {value}" for option, value, is_set in given if is_set)
        print(
            f"This was the {args.budget!r} budget ({budget.episodes} training episodes per run). The paper's scale "
            f"({paper.episodes} and {paper.long_episodes} episodes, {paper.seeds} seeds; on 2 cores about 45 minutes "
            "without the paper-task experiment, which takes about 5 hours more): "
            f"sb3-dtdpg reproduce --budget paper{chosen} --out <folder>"
        )
    return status


def _check_finished_runs(args: argparse.Namespace, specs: Sequence[Any]) -> None:
    """
    ``reproduce --report-only`` draws its tables from the finished runs of ``--out``: refuse a folder (missing or
    not) that holds none of this job's, before anything is created.

    :param args: the command's options
    :param specs: the job's runs (:func:`sb3_dtdpg.experiments.reproduce.reproduce_specs`)
    :raises ValueError: no run of ``specs`` has a result in ``--out``
    """
    from sb3_dtdpg.experiments.reproduce import check_finished_runs

    job = f"--budget {args.budget}, --preset {args.hyperparams}, --observation {args.observation}"
    try:
        check_finished_runs(args.out, specs, job, "run it without --report-only to train them")
    except ValueError as error:
        raise ValueError(f"--out: {error}") from None


def _run_reproduce(args: argparse.Namespace) -> None:
    from sb3_dtdpg.experiments.reproduce import run_reproduce

    run_reproduce(
        args.out,
        train=not args.report_only,
        experiments=args.experiments,
        multiple_access=args.multiple_access,
        paper_task_presets=None if args.preset is None else [args.preset],
        **_run_options(args),
    )


def _run_options(args: argparse.Namespace) -> dict[str, Any]:
    """
    :return: the keyword arguments of ``run_compare`` and ``run_reproduce`` from the options both commands take
        (``--budget``, ``--n-seeds`` and those of :func:`sb3_dtdpg.cli_parser.add_common_run_options`)
    """
    return {
        "budget": args.budget,
        "seeds": args.n_seeds,
        "n_workers": args.workers,
        "progress": not args.no_progress,
        "hyperparams": args.hyperparams,
        "observation": args.observation,
    }


def _saved_model_env(
    args: argparse.Namespace, channel: str, outputs: dict[str, str | None]
) -> tuple[Any, Any, dict[str, Any]]:
    """
    The saved model of ``evaluate``/``enjoy``, its test env (its recorded settings unless overridden, its observations
    normalized as it trained on them) and the settings.

    :param args: the command's options
    :param channel: the test env's channel
    :param outputs: the command's output files by option, refused where one is the scenario file the env is built from
    """
    import gymnasium as gym

    import noma_radiomap  # registers the env ids
    from sb3_dtdpg.baselines import is_mission_env
    from sb3_dtdpg.model_files import check_not_input, read_saved_model

    with _user_errors(args):
        saved = read_saved_model(args.model, args.algo)
        env_id = args.env or saved.env_id or DEFAULT_ENV_ID
        if not is_mission_env(env_id):
            where = "--env" if args.env else f"the model's env ({args.model})"
            raise ValueError(f"{where}: {args.command} runs the NomaRadioMap test missions, got {env_id}")
        settings = dict(saved.settings or {})
        implied = _env_id_settings(args, saved)
        kwargs = saved.env_kwargs(
            channel,
            scenario=args.scenario,
            observation=args.observation or settings.get("observation") or "goal",
            multiple_access=args.multiple_access or implied.get("multiple_access"),
            task=implied.get("task"),
        )
        scenario = kwargs.get("scenario")
        scenario_file = None if scenario is None or str(scenario) in noma_radiomap.list_scenarios() else scenario
        for option, value in outputs.items():
            if value is not None:
                check_not_input(option, value, scenario_file, "the scenario file of the test env")
        guessed = [key for key in ("scenario", "multiple_access") if key not in settings and key not in kwargs]
        if guessed and saved.guessed:
            print(
                f"sb3-dtdpg {args.command}: warning: the model {args.model} records no env settings (only its "
                f"observation length tells its layout): testing it with {env_id}'s default "
                f"{' and '.join(guessed)}; give {' and '.join('--' + key.replace('_', '-') for key in guessed)} if it "
                "was trained on others",
                file=sys.stderr,
            )
        env = gym.make(env_id, **kwargs)
        try:
            env = saved.observations_as_trained(env)
            model = saved.load(env)
        except ValueError:
            env.close()
            raise
    normalized = {} if saved.normalization is None else {"observation_statistics": str(saved.normalization)}
    return model, env, {**settings, **kwargs, "env_id": env_id, "algo": saved.algo, **normalized}


def _env_id_settings(args: argparse.Namespace, saved: Any) -> dict[str, Any]:
    """
    The settings that ``--env`` stands for: its registered downlink mode (unless ``--multiple-access`` is given,
    which wins as in ``gymnasium.make``) and its task (``missions`` where the id names none). The env id the model's
    run recorded stands for the model's recorded settings (a run may have overridden its id's downlink mode).

    :param args: the command's options
    :param saved: the :class:`sb3_dtdpg.model_files.SavedModel`
    :return: the settings (empty without ``--env``), to build the test env with
    :raises ValueError: one of them contradicts the model's recorded settings, naming the option and both values
    """
    import gymnasium as gym

    if args.env is None or args.env == saved.env_id:  # the model's own env id: its recorded settings are what it meant
        return {}
    registered = gym.spec(args.env).kwargs
    implied = {"task": registered.get("task", "missions")}
    if args.multiple_access is None and registered.get("multiple_access") is not None:
        implied["multiple_access"] = registered["multiple_access"]
    recorded = saved.settings or {}
    for key, value in implied.items():
        if recorded.get(key) is not None and recorded[key] != value:
            trained_on = f" on {saved.env_id}" if saved.env_id else ""
            raise ValueError(
                f"--env {args.env}: the env id has {key}={value!r}, but the model {saved.path} was trained{trained_on} "
                f"with {key}={recorded[key]!r} (recorded in {saved.source}); leave --env out to test it on its own settings"
            )
    return implied


def _check_output_files(args: argparse.Namespace, outputs: dict[str, str | None]) -> None:
    """
    Refuse output files of ``evaluate``/``enjoy`` that would overwrite the model or a record of its run (its
    ``result.json``, ...: :func:`sb3_dtdpg.model_files.check_output_file`), before anything runs.

    :param args: the command's options
    :param outputs: the output files by option (None: not given)
    """
    from sb3_dtdpg.model_files import check_output_file

    with _user_errors(args):
        for option, value in outputs.items():
            if value is not None:
                check_output_file(option, value, args.model)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    import pandas as pd

    from sb3_dtdpg.baselines import final_reward_phase
    from sb3_dtdpg.common.files import write_csv, write_json
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.experiments import tables

    _check_output_files(args, {"--json": args.json, "--csv": args.csv})
    model, env, settings = _saved_model_env(args, args.channel, {"--json": args.json, "--csv": args.csv})
    # The episode returns on the reward the model trained on last, as its run's own evaluation (the MQI is the same)
    phase = final_reward_phase(model, settings["algo"])
    if phase is not None and hasattr(env.unwrapped, "set_reward_phase"):
        env.unwrapped.set_reward_phase(phase)
        settings["reward_phase"] = phase
    with _user_errors(args):
        result = evaluate(model, env, n_episodes=args.n_episodes, seed=args.seed, deterministic=True)
    env.close()
    mode = str(settings.get("multiple_access", "noma"))
    row = tables.planner_row(tables.ALGO_LABELS.get(settings["algo"], settings["algo"]), mode, result)
    row["train_timesteps"] = float(model.num_timesteps)
    summary = pd.DataFrame([row])
    title = (
        f"{args.model} on {settings.get('scenario', 'mall')} ({mode.upper()}, {settings['observation']} observation): "
        f"{result.n_episodes} {args.channel} test episodes from seed {args.seed}"
    )
    tables.print_table(summary, title)
    if args.json:
        document = {"model": str(args.model), "settings": settings, "summary": result.summary(), "episodes": result.episodes}
        write_json(args.json, document, indent=2, strict=True)
        print(f"wrote {args.json}")
    if args.csv:
        write_csv(args.csv, pd.DataFrame(result.episodes))
        print(f"wrote {args.csv} (one row per test episode)")
    return 0


def _cmd_enjoy(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.recording import animation_writer, run_mission, save_animation

    if args.record:
        _check_output_files(args, {"--record": args.record})
        with _user_errors(args):
            try:
                animation_writer(args.record, args.fps)  # .mp4 needs ffmpeg: say so before the mission runs
            except ValueError as error:
                raise ValueError(f"--record {error}") from None
    model, env, settings = _saved_model_env(args, args.channel, {"--record": args.record})
    with _user_errors(args):
        trace = run_mission(model, env, args.seed)
    info = trace.info
    arrived = "all robots arrived" if info.get("is_success") else "not all robots arrived"
    outage = [int(steps) for steps in info.get("outage_steps", [])]
    print(
        f"mission (seed {args.seed}, {settings.get('scenario', 'mall')}, {str(settings.get('multiple_access')).upper()}, "
        f"{args.channel}): {len(trace.power_w)} steps, {arrived}, MQI {float(info.get('mqi', float('nan'))):.1f}, "
        f"outage steps per robot {outage}"
    )
    if args.record:
        with _user_errors(args):
            frames = save_animation(env, trace, args.record, fps=args.fps, max_frames=args.max_frames)
        print(f"wrote {args.record} ({frames} frame{'s' if frames != 1 else ''})")
    env.close()
    return 0


def _commands() -> dict[str, Callable[[argparse.Namespace], int]]:
    """:return: the function of each subcommand of :func:`build_parser`, by name"""
    return {
        "map": _cmd_map,
        "train": _cmd_train,
        "compare": _cmd_compare,
        "reproduce": _cmd_reproduce,
        "evaluate": _cmd_evaluate,
        "enjoy": _cmd_enjoy,
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sb3-dtdpg`` console script."""
    args, unknown = build_parser().parse_known_args(argv)
    if unknown:  # argparse reports these with the top-level usage; the subcommand's is the one that helps
        args.error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        with warnings_as_lines(args.prog):
            return _commands()[args.command](args)
    except KeyboardInterrupt:
        if args.command in ("compare", "reproduce"):  # jobs of runs, each written as it finishes
            from sb3_dtdpg.experiments.budgets import CHECKPOINT_EVERY

            print(
                f"interrupted: finished runs are saved, the others checkpointed every {CHECKPOINT_EVERY} episodes; "
                "run the same command again to resume",
                file=sys.stderr,
            )
        elif args.command == "train":
            print("interrupted: finished runs are saved; run the same command again to resume", file=sys.stderr)
        else:  # one piece of work, its output written at its end
            print(f"interrupted: {args.command} stopped before its end (nothing to resume: run it again)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
