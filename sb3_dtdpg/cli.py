"""The ``sb3-dtdpg`` command line.

Subcommands:

- ``map``: the power and SINR maps of a scenario (the paper's Fig. 4);
- ``train``: one training run on any registered env id, with TensorBoard logging, then its test evaluation; on
  the NomaRadioMap envs with periodic checkpoints (the same command resumes it);
- ``compare``: the main job: DT-DPG vs DDPG in NOMA and OMA, several seeds in parallel, the results
  table (printed, Markdown, CSV) with the planners as references, learning curves and trajectories;
- ``reproduce``: every experiment of the paper's Section V, resumable.

Conventions: ``--out`` is always an output *folder* (created if missing); ``--n-seeds`` is a number of seeds,
``--seed`` the seed of one run; ``--multiple-access`` takes the mode(s), ``noma`` and/or ``oma``. A user error
(an unknown scenario or env id, a bad YAML file, a budget that cannot train) is one ``error:`` line after the
usage, with exit status 2, as argparse reports a bad option.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = ["build_parser", "main"]

_PUBLIC_BUDGETS = ("tiny", "default", "small", "reduced", "paper")
_HYPERPARAMS_HELP = (
    "tuned: the best measured DT-DPG settings, for DT-DPG and DDPG alike (docs/BENCHMARKS.md; the default); "
    "paper: Table I (the default of td3, sac and tqc, which have no tuned set)"
)
_MODES = ("noma", "oma")
_OBSERVATION_HELP = (
    "goal: the paper's state plus each robot's direction and distance to its destination (an extension, "
    "docs/BENCHMARKS.md: what makes DT-DPG learn the mission in the paper's budget); paper: the paper's state only"
)


@contextlib.contextmanager
def _user_errors(args: argparse.Namespace) -> Iterator[None]:
    """Report a ``ValueError`` of the enclosed checks as a usage error of the subcommand (exit status 2)."""
    try:
        yield
    except ValueError as error:
        args.error(str(error))


def _hyperparams(args: argparse.Namespace, algos: Sequence[str]) -> str:
    """The hyperparameter set of a command: ``--hyperparams``, else ``tuned`` where every algorithm has it."""
    if args.hyperparams is not None:
        return args.hyperparams
    if all(algo in ("dtdpg", "ddpg") for algo in algos):
        return "tuned"
    if len(algos) > 1:
        print(
            f"{args.prog}: note: --hyperparams paper (Table I) for every algorithm, as {', '.join(algos)} have no "
            "common tuned set",
            file=sys.stderr,
        )
    return "paper"


def _cmd_map(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from noma_radiomap import RadioMap, load_scenario
    from sb3_dtdpg.common.files import safe_name

    scenario = load_scenario(args.scenario)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    radio_map = RadioMap.for_scenario(scenario)
    path = out / f"maps_{safe_name(scenario.name)}.png"  # the name is user text: never a path
    radio_map.plot_maps(str(path))
    print(f"wrote {path} (outage share with full power to one robot: {100 * radio_map.outage_share():.1f} % of free cells)")
    return 0


def _train_env(args: argparse.Namespace) -> tuple[Any, bool]:
    """The training env of ``train``: mission options for the mission envs only, checked before anything runs."""
    from sb3_dtdpg.baselines import is_mission_env, make_env

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
        args.observation = args.observation or "goal"
        env_kwargs["observation"] = args.observation
    with _user_errors(args):
        env = make_env(args.algo, args.env, args.multiple_access, args.channel, env_kwargs)
    return env, mission


def _cmd_train(args: argparse.Namespace) -> int:
    import torch as th

    from sb3_dtdpg.baselines import check_hyperparams, check_training_budget, hyperparameter

    args.hyperparams = _hyperparams(args, [args.algo])
    args.tb = args.tb or str(Path(args.out) / "tb")  # a run's logs live with its results, under its lock
    with _user_errors(args):
        check_hyperparams(args.algo, args.hyperparams)
    if args.threads:
        th.set_num_threads(args.threads)
    env, mission = _train_env(args)
    max_steps = int(env.unwrapped.scenario.mission.max_steps) if mission else env.spec.max_episode_steps
    if args.timesteps is None and max_steps is None:
        args.error(f"--episodes: {args.env} has no episode step limit to turn episodes into steps; give --timesteps")
    if args.timesteps is not None:
        total, budget = args.timesteps, f"--timesteps {args.timesteps}"
    else:
        total, budget = args.episodes * max_steps, f"--episodes {args.episodes} (at most {args.episodes * max_steps} steps)"
    with _user_errors(args):
        learning_starts = int(hyperparameter(args.algo, "learning_starts", args.hyperparams))
        check_training_budget(total, learning_starts, budget, "give more --episodes or --timesteps")
    if mission:
        multiple_access, channel = env.unwrapped.multiple_access, env.unwrapped.channel
        env.close()
        return _train_mission(args, multiple_access, channel)
    return _train_any_env(args, env)


def _train_mission(args: argparse.Namespace, multiple_access: str, channel: str) -> int:
    """``train`` on a NomaRadioMap env: a run of :func:`sb3_dtdpg.experiments.runs.run_one`, checkpointed."""
    from sb3_dtdpg.experiments.runs import RunSpec, output_lock, read_checkpoint, run_one

    spec = RunSpec(
        args.algo,
        multiple_access,
        args.seed,
        args.episodes,
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
    )
    out = Path(args.out)
    run_dir = out / "runs" / spec.run_id
    try:
        with output_lock(out, f".{spec.run_id}.lock"):
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
    except KeyboardInterrupt:
        checkpoint = read_checkpoint(run_dir)
        if checkpoint is None:
            saved = f"nothing saved yet (the first checkpoint comes after {args.checkpoint_every} episodes)"
        else:
            saved = f"the checkpoint after {checkpoint['episodes']} episodes is in {checkpoint['path']}"
        print(f"interrupted: {saved}; run the same command again to resume from there", file=sys.stderr)
        return 130
    summary = result["eval"]["summary"]
    resumed = result["train"].get("resumed_at_episode")
    reward_phase = result["reward_phases"]["evaluated"]  # the one it finished training on
    print(
        f"{spec.run_id}: {result['train']['timesteps']} steps, {result['train']['episodes']} episodes"
        + (f" (resumed after episode {resumed})" if resumed is not None else "")
        + f", last reward phase {reward_phase!r}; test ({spec.eval_episodes} Rayleigh episodes, {reward_phase!r} "
        f"reward): success {100 * summary['success_rate']:.0f} %, MQI {summary['mqi']:.1f} ± {summary['mqi_ci']:.1f}; "
        f"model: {run_dir / 'model.zip'}, result: {run_dir / 'result.json'}, TensorBoard: {Path(args.tb) / spec.run_id}"
    )
    return 0


def _train_any_env(args: argparse.Namespace, env: Any) -> int:
    """``train`` on any other registered env id: SB3's ``learn``, then ``evaluate_policy``."""
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
    from stable_baselines3.common.evaluation import evaluate_policy

    from sb3_dtdpg.baselines import make_model, mission_callbacks
    from sb3_dtdpg.experiments.runs import EpisodeReturnLogger

    model = make_model(
        args.algo,
        env,
        seed=args.seed,
        tensorboard_log=args.tb,
        learning_rate=args.learning_rate,
        verbose=args.verbose,
        hyperparams=args.hyperparams,
    )
    callbacks = [EpisodeReturnLogger(), *mission_callbacks(model)]
    if args.timesteps is not None:
        total = args.timesteps
    else:
        total = args.episodes * env.spec.max_episode_steps
        callbacks.append(StopTrainingOnMaxEpisodes(args.episodes))
    run_name = f"{args.algo}_{re.sub(r'[^A-Za-z0-9_.-]', '_', args.env)}_s{args.seed}"
    model.learn(
        total_timesteps=total, callback=callbacks, log_interval=1, tb_log_name=run_name, progress_bar=not args.no_progress
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / f"{run_name}.zip")
    mean, std = evaluate_policy(model, env, n_eval_episodes=args.eval_episodes, deterministic=True)
    print(
        f"{run_name}: {model.num_timesteps} steps; test ({args.eval_episodes} episodes): reward {mean:.1f} ± {std:.1f}; "
        f"model saved to {out / (run_name + '.zip')}"
    )
    env.close()
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.baselines import check_hyperparams, is_mission_env
    from sb3_dtdpg.experiments.compare import compare_specs, run_compare
    from sb3_dtdpg.experiments.runs import BUDGETS, check_budget

    if not is_mission_env(args.env):
        args.error(f"--env: compare runs on the NomaRadioMap envs, got {args.env}")
    args.hyperparams = _hyperparams(args, args.algos)
    with _user_errors(args):
        for algo in args.algos:
            check_hyperparams(algo, args.hyperparams)
        budget = BUDGETS[args.budget]
        if args.scenario is not None:
            budget = _replace(budget, scenario=args.scenario)
        n_seeds = budget.seeds if args.n_seeds is None else args.n_seeds
        for spec in compare_specs(
            budget, n_seeds, args.algos, args.multiple_access, args.env, args.hyperparams, args.observation
        ):
            check_budget(spec)
    run_compare(
        args.out,
        scenario=args.scenario,
        budget=args.budget,
        seeds=args.n_seeds,
        algos=args.algos,
        modes=args.multiple_access,
        n_workers=args.workers,
        progress=not args.no_progress,
        env_id=args.env,
        hyperparams=args.hyperparams,
        observation=args.observation,
    )
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.baselines import check_hyperparams
    from sb3_dtdpg.experiments.reproduce import reproduce_specs, run_reproduce
    from sb3_dtdpg.experiments.runs import BUDGETS, check_budget

    budget = BUDGETS[args.budget]
    args.hyperparams = _hyperparams(args, ("dtdpg", "ddpg"))
    with _user_errors(args):
        check_hyperparams("dtdpg", args.hyperparams)
        if not args.report_only:
            n_seeds = budget.seeds if args.n_seeds is None else args.n_seeds
            for specs in reproduce_specs(budget, n_seeds, args.hyperparams, args.observation).values():
                for spec in specs:
                    check_budget(spec)
    run_reproduce(
        args.out,
        budget=args.budget,
        seeds=args.n_seeds,
        n_workers=args.workers,
        progress=not args.no_progress,
        train=not args.report_only,
        hyperparams=args.hyperparams,
        observation=args.observation,
        experiments=args.experiments,
    )
    if args.budget != "paper":
        paper = BUDGETS["paper"]
        print(
            f"This was the {args.budget!r} budget ({budget.episodes} training episodes per run). The paper's scale "
            f"({paper.episodes} and {paper.long_episodes} episodes, {paper.seeds} seeds; about an hour on 2 cores): "
            f"sb3-dtdpg reproduce --budget paper --out <folder>"
        )
    return 0


def _replace(budget: Any, **changes: Any) -> Any:
    import dataclasses

    return dataclasses.replace(budget, **changes)


# ---------------------------------------------------------------------------------------------- argument types
def _budget(value: str) -> str:
    from sb3_dtdpg.experiments.runs import BUDGETS

    if value not in BUDGETS:
        raise argparse.ArgumentTypeError(f"budget must be one of {', '.join(_PUBLIC_BUDGETS)}, got {value!r}")
    return value


def _positive(value: str) -> int:
    try:
        number = int(value)
    except ValueError:
        number = 0
    if number < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value!r}")
    return number


def _scenario(value: str) -> str:
    """A built-in scenario name or a scenario YAML file, loaded (so validated) once while parsing."""
    from noma_radiomap import load_scenario

    try:
        load_scenario(value)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return value


def _env_id(value: str) -> str:
    """A registered Gymnasium env id (the NomaRadioMap ids are registered by importing ``noma_radiomap``)."""
    import gymnasium as gym

    import noma_radiomap  # noqa: F401

    try:
        gym.spec(value)
    except gym.error.Error as error:
        raise argparse.ArgumentTypeError(f"{value!r} is not a registered env id ({error})") from None
    return value


class _DeprecatedOption(argparse.Action):
    """The old spelling of an option: stores its value like the new one and says which one to use."""

    def __init__(self, option_strings: list[str], dest: str, replacement: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.replacement = replacement

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option_string: Any = None):
        print(f"{parser.prog}: warning: {option_string} is deprecated, use {self.replacement}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def _budget_help(default: str) -> str:
    from sb3_dtdpg.experiments.runs import BUDGETS

    scales = "; ".join(
        f"{name}: {BUDGETS[name].episodes} episodes on {BUDGETS[name].scenario or 'mall'}, {BUDGETS[name].seeds} seeds"
        for name in _PUBLIC_BUDGETS
    )
    return f"experiment scale (default: {default}). {scales}; paper is the paper's scale"


def _add_seeds(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--n-seeds", type=_positive, default=None, metavar="N", help="seeds per configuration, 0..N-1 (default: the budget's)"
    )
    p.add_argument(
        "--seeds", type=_positive, dest="n_seeds", action=_DeprecatedOption, replacement="--n-seeds", help=argparse.SUPPRESS
    )


def _add_common_run_options(p: argparse.ArgumentParser, hyperparams: tuple[str, ...]) -> None:
    from noma_radiomap.registration import OBSERVATIONS

    p.add_argument("--hyperparams", choices=hyperparams, default=None, help=_HYPERPARAMS_HELP)
    p.add_argument("--observation", choices=OBSERVATIONS, default="goal", help=_OBSERVATION_HELP + " (default: goal)")
    p.add_argument("--workers", type=_positive, default=None, help="parallel processes (default: number of CPUs)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def build_parser() -> argparse.ArgumentParser:
    """:return: the argument parser of ``sb3-dtdpg``"""
    from noma_radiomap.registration import OBSERVATIONS
    from sb3_dtdpg import __version__
    from sb3_dtdpg.baselines import ALGORITHMS, DEFAULT_ENV_ID, HYPERPARAMS

    parser = argparse.ArgumentParser(
        prog="sb3-dtdpg",
        description="DT-DPG on the NOMA indoor radio-map environment. --out is always an output folder.",
        epilog="RL Zoo training (any zoo flag): python -m sb3_dtdpg.train --algo dtdpg --env NomaRadioMap-v0 (docs/ZOO.md)",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="{map,train,compare,reproduce}", help="sb3-dtdpg <command> -h: its options"
    )

    def command(name: str, help_text: str) -> argparse.ArgumentParser:
        sub = commands.add_parser(name, help=help_text, description=help_text)
        sub.set_defaults(error=sub.error, prog=sub.prog)
        return sub

    p = command("map", "write the power and SINR maps of a scenario (paper Fig. 4)")
    p.add_argument("--scenario", type=_scenario, default="mall", help="built-in scenario name or YAML path (default: mall)")
    p.add_argument(
        "--out", default="results/maps", help="output folder; the figure is maps_<scenario>.png (default: results/maps)"
    )
    p.set_defaults(func=_cmd_map)

    p = command("train", "one training run with TensorBoard logging, then a test evaluation")
    p.add_argument("--algo", required=True, choices=ALGORITHMS, help="the algorithm")
    p.add_argument(
        "--env",
        type=_env_id,
        default=DEFAULT_ENV_ID,
        help=f"any registered Gymnasium env id (default: {DEFAULT_ENV_ID}); --scenario, --multiple-access and "
        "--channel apply to the NomaRadioMap envs only",
    )
    p.add_argument("--scenario", type=_scenario, default=None, help="scenario name or YAML path (default: the env's, mall)")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--episodes", type=_positive, default=500, help="training episodes (default: 500, the paper's)")
    budget.add_argument("--timesteps", type=_positive, default=None, help="training timesteps instead of episodes")
    p.add_argument("--seed", type=int, default=0, help="seed of the run (default: 0)")
    p.add_argument("--multiple-access", choices=_MODES, default=None, help="NOMA or OMA downlink (default: the env id's)")
    p.add_argument(
        "--channel", choices=("radio_map", "rayleigh"), default=None, help="training channel (default: the env id's)"
    )
    p.add_argument("--learning-rate", type=float, default=None, help="override the algorithm's learning rate")
    p.add_argument("--hyperparams", choices=HYPERPARAMS, default=None, help=_HYPERPARAMS_HELP)
    p.add_argument(
        "--observation",
        choices=OBSERVATIONS,
        default=None,
        help=_OBSERVATION_HELP + " (default: goal on the NomaRadioMap envs)",
    )
    p.add_argument("--tb", default=None, help="TensorBoard log folder (default: <out>/tb)")
    p.add_argument(
        "--out",
        default="results/train",
        help="output folder: on the NomaRadioMap envs <out>/runs/<run id>/ gets the model, checkpoints and result; "
        "on other envs the model is <algo>_<env id>_s<seed>.zip (default: results/train)",
    )
    p.add_argument(
        "--checkpoint-every",
        type=_positive,
        default=10,
        help="NomaRadioMap envs: save model and replay buffer every N episodes; the same command resumes from the "
        "last one (default: 10)",
    )
    p.add_argument("--eval-episodes", type=_positive, default=20, help="test episodes after training (default: 20)")
    p.add_argument("--eval-seed", type=int, default=10_000, help="seed of the first test episode (default: 10000)")
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads (default: 1, fastest for these small networks; 0: torch's default)",
    )
    p.add_argument("--verbose", type=int, default=0, help="SB3 verbosity: 0, 1 or 2 (default: 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train)

    p = command("compare", "the main job: DT-DPG vs DDPG, NOMA and OMA, several seeds, table and figures")
    p.add_argument("--budget", type=_budget, default="default", help=_budget_help("default"))
    _add_seeds(p)
    p.add_argument("--out", default="results/compare", help="output folder (default: results/compare)")
    p.add_argument(
        "--algos", nargs="+", choices=ALGORITHMS, default=["dtdpg", "ddpg"], help="algorithms (default: dtdpg ddpg)"
    )
    p.add_argument(
        "--multiple-access", nargs="+", choices=_MODES, default=list(_MODES), help="downlink mode(s) (default: noma oma)"
    )
    p.add_argument(
        "--modes",
        nargs="+",
        choices=_MODES,
        dest="multiple_access",
        action=_DeprecatedOption,
        replacement="--multiple-access",
        help=argparse.SUPPRESS,
    )
    p.add_argument("--env", type=_env_id, default=DEFAULT_ENV_ID, help=f"a NomaRadioMap env id (default: {DEFAULT_ENV_ID})")
    p.add_argument("--scenario", type=_scenario, default=None, help="scenario name or YAML path (default: the budget's)")
    _add_common_run_options(p, HYPERPARAMS)
    p.set_defaults(func=_cmd_compare)

    p = command("reproduce", "every experiment of the paper's Section V; finished runs are not re-run")
    p.add_argument(
        "--budget",
        type=_budget,
        default="tiny",
        help=_budget_help("tiny, the whole pipeline in minutes")
        + " (the paper's scale, about an hour on 2 cores: sb3-dtdpg reproduce --budget paper)",
    )
    _add_seeds(p)
    p.add_argument("--out", default="results/reproduce", help="output folder (default: results/reproduce)")
    p.add_argument("--report-only", action="store_true", help="only re-draw tables and figures from the finished runs")
    p.add_argument(
        "--experiments",
        nargs="+",
        choices=("table_ii", "ddpg_vs_dtdpg", "learning_rates"),
        default=None,
        help="train only the runs of these experiments (default: all); the tables use every finished run",
    )
    _add_common_run_options(p, HYPERPARAMS)
    p.set_defaults(func=_cmd_reproduce)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sb3-dtdpg`` console script."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("interrupted: finished runs are saved; run the same command again to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
