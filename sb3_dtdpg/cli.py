"""The ``sb3-dtdpg`` command line.

Subcommands:

- ``map``: the power and SINR maps of a scenario (the paper's Fig. 4);
- ``train``: one training run with TensorBoard logging, then its test evaluation;
- ``compare``: the main job: DT-DPG vs DDPG in NOMA and OMA, several seeds in parallel, the results
  table (printed, Markdown, CSV) with the planners as references, learning curves and trajectories;
- ``reproduce``: every experiment of the paper (the paper's Section V), resumable.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main"]

_PUBLIC_BUDGETS = ("tiny", "default", "small", "reduced", "paper")
_HYPERPARAMS_HELP = (
    "paper: Table I (default); tuned: the best measured DT-DPG settings, for DT-DPG and DDPG alike (docs/BENCHMARKS.md)"
)


def _cmd_map(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from noma_radiomap import RadioMap, load_scenario

    scenario = load_scenario(args.scenario)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    radio_map = RadioMap.for_scenario(scenario)
    path = out / f"maps_{scenario.name}.png"
    radio_map.plot_maps(str(path))
    print(f"wrote {path} (outage share with full power to one robot: {100 * radio_map.outage_share():.1f} % of free cells)")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    import torch as th
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

    import noma_radiomap  # noqa: F401
    from sb3_dtdpg.baselines import make_env, make_model, mission_callbacks
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.experiments.runs import EpisodeReturnLogger

    if args.threads:
        th.set_num_threads(args.threads)
    env_kwargs = {} if args.scenario is None else {"scenario": args.scenario}
    env = make_env(args.algo, args.env, args.multiple_access, args.channel, env_kwargs)
    model = make_model(
        args.algo,
        env,
        seed=args.seed,
        tensorboard_log=args.tb,
        learning_rate=args.learning_rate,
        verbose=args.verbose,
        hyperparams=args.hyperparams,
    )
    max_steps = int(env.unwrapped.scenario.mission.max_steps)
    callbacks = [EpisodeReturnLogger(), *mission_callbacks(model)]
    if args.timesteps is not None:
        total = args.timesteps
    else:
        total = args.episodes * max_steps
        callbacks.append(StopTrainingOnMaxEpisodes(args.episodes))
    run_name = f"{args.algo}_{args.multiple_access}_s{args.seed}"
    model.learn(
        total_timesteps=total, callback=callbacks, log_interval=1, tb_log_name=run_name, progress_bar=not args.no_progress
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / f"{run_name}.zip")
    result = evaluate(
        model,
        args.env,
        n_episodes=args.eval_episodes,
        seed=args.eval_seed,
        channel="rayleigh",
        multiple_access=args.multiple_access,
        env_kwargs=env_kwargs,
    )
    summary = result.summary()
    print(
        f"{run_name}: {model.num_timesteps} steps; test ({args.eval_episodes} Rayleigh episodes): "
        f"success {100 * summary['success_rate']:.0f} %, MQI {summary['mqi']:.1f} ± {summary['mqi_ci']:.1f}; "
        f"model saved to {out / (run_name + '.zip')}"
    )
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.experiments.compare import run_compare

    run_compare(
        args.out,
        scenario=args.scenario,
        budget=args.budget,
        seeds=args.seeds,
        algos=args.algos,
        modes=args.modes,
        n_workers=args.workers,
        progress=not args.no_progress,
        env_id=args.env,
        hyperparams=args.hyperparams,
    )
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    from sb3_dtdpg.experiments.reproduce import run_reproduce

    run_reproduce(
        args.out,
        budget=args.budget,
        seeds=args.seeds,
        n_workers=args.workers,
        progress=not args.no_progress,
        train=not args.report_only,
        hyperparams=args.hyperparams,
    )
    return 0


def _budget(value: str) -> str:
    from sb3_dtdpg.experiments.runs import BUDGETS

    if value not in BUDGETS:
        raise argparse.ArgumentTypeError(f"budget must be one of {', '.join(_PUBLIC_BUDGETS)}, got {value!r}")
    return value


def _positive(value: str) -> int:
    number = int(value)
    if number < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value!r}")
    return number


def build_parser() -> argparse.ArgumentParser:
    """:return: the argument parser of ``sb3-dtdpg``"""
    from sb3_dtdpg.baselines import ALGORITHMS, DEFAULT_ENV_ID, HYPERPARAMS

    parser = argparse.ArgumentParser(prog="sb3-dtdpg", description="DT-DPG on the NOMA indoor radio-map environment.")
    commands = parser.add_subparsers(dest="command", required=True)

    p = commands.add_parser("map", help="write the power and SINR maps of a scenario (paper Fig. 4)")
    p.add_argument("--scenario", default="mall", help="built-in scenario name or YAML path (default: mall)")
    p.add_argument("--out", default="results/maps", help="output folder (default: results/maps)")
    p.set_defaults(func=_cmd_map)

    p = commands.add_parser("train", help="one training run with TensorBoard logging, then a test evaluation")
    p.add_argument("--algo", required=True, choices=ALGORITHMS)
    p.add_argument("--env", default=DEFAULT_ENV_ID, help=f"env id (default: {DEFAULT_ENV_ID})")
    p.add_argument("--scenario", default=None, help="scenario name or YAML path (default: the env's, mall)")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--episodes", type=_positive, default=500, help="training episodes (default: 500, the paper's)")
    budget.add_argument("--timesteps", type=_positive, default=None, help="training timesteps instead of episodes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--multiple-access", choices=("noma", "oma"), default="noma")
    p.add_argument("--channel", choices=("radio_map", "rayleigh"), default="radio_map", help="training channel")
    p.add_argument("--learning-rate", type=float, default=None, help="override the algorithm's learning rate")
    p.add_argument("--hyperparams", choices=HYPERPARAMS, default="paper", help=_HYPERPARAMS_HELP)
    p.add_argument("--tb", default="runs", help="TensorBoard folder (default: runs)")
    p.add_argument("--out", default="results/train", help="where the model is saved (default: results/train)")
    p.add_argument("--eval-episodes", type=_positive, default=20)
    p.add_argument("--eval-seed", type=int, default=10_000)
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads (default: 1, fastest for these small networks; 0: torch's default)",
    )
    p.add_argument("--verbose", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_cmd_train)

    p = commands.add_parser("compare", help="the main job: DT-DPG vs DDPG, NOMA and OMA, several seeds, table and figures")
    p.add_argument("--budget", type=_budget, default="default", help=f"one of {', '.join(_PUBLIC_BUDGETS)} (default: default)")
    p.add_argument("--seeds", type=_positive, default=None, help="seeds per configuration (default: the budget's)")
    p.add_argument("--out", default="results/compare", help="output folder (default: results/compare)")
    p.add_argument("--algos", nargs="+", choices=ALGORITHMS, default=["dtdpg", "ddpg"])
    p.add_argument("--modes", nargs="+", choices=("noma", "oma"), default=["noma", "oma"])
    p.add_argument("--env", default=DEFAULT_ENV_ID)
    p.add_argument("--scenario", default=None, help="scenario name or YAML path (default: the budget's; mall)")
    p.add_argument("--hyperparams", choices=HYPERPARAMS, default="paper", help=_HYPERPARAMS_HELP)
    p.add_argument("--workers", type=_positive, default=None, help="parallel processes (default: number of CPUs)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_cmd_compare)

    p = commands.add_parser(
        "reproduce", help="every experiment of the paper (the paper's Sec. V); finished runs are not re-run"
    )
    p.add_argument("--budget", type=_budget, default="paper", help=f"one of {', '.join(_PUBLIC_BUDGETS)} (default: paper)")
    p.add_argument("--seeds", type=_positive, default=None, help="seeds per configuration (default: the budget's)")
    p.add_argument("--out", default="results/reproduce", help="output folder (default: results/reproduce)")
    p.add_argument("--report-only", action="store_true", help="only re-draw tables and figures from the finished runs")
    p.add_argument("--hyperparams", choices=HYPERPARAMS, default="paper", help=_HYPERPARAMS_HELP)
    p.add_argument("--workers", type=_positive, default=None, help="parallel processes (default: number of CPUs)")
    p.add_argument("--no-progress", action="store_true")
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
