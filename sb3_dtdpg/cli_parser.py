"""The argument parser of the ``sb3-dtdpg`` command line (:func:`build_parser`), for :mod:`sb3_dtdpg.cli`.

It holds what parsing needs and nothing the commands run: the subcommands and their options, the options' choices
and help texts, and the argument types that check a value while parsing (a scenario YAML file is loaded, an output
folder must be writable, ...), so that a value an option cannot use is one ``error:`` line after the subcommand's
usage (exit status 2) before anything runs. The parser stores the subcommand's name in ``command``; ``sb3_dtdpg.cli``
runs the command of that name. Building the parser and ``--help`` import neither torch nor Stable-Baselines3.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import Any

from sb3_dtdpg.arguments import MAX_SEED as _MAX_SEED
from sb3_dtdpg.arguments import checked, positive_int
from sb3_dtdpg.arguments import seed_count as _seed_count
from sb3_dtdpg.arguments import seed_int as _seed

#: The parser, and what the distributed workers' parser (:mod:`sb3_dtdpg.experiments.distributed`) shares with it: the
#: options' choices, the argument types and the option groups.
__all__ = [
    "ALGORITHMS",
    "DEFAULT_ENV_ID",
    "EXPERIMENTS",
    "MODES",
    "OBSERVATIONS",
    "PAPER_TASK_PRESET_NOTE",
    "PRESETS",
    "DeprecatedOption",
    "add_common_run_options",
    "add_seeds",
    "budget_name",
    "build_parser",
    "output_folder",
    "registered_env_id",
    "scenario_name",
]

# The choices of the options, spelled here so that --help needs no heavy import (tests/test_cli_errors.py checks
# them against sb3_dtdpg.baselines, sb3_dtdpg.experiments.reproduce and noma_radiomap.registration).
ALGORITHMS = ("dtdpg", "ddpg", "td3", "sac", "tqc")
PRESETS = ("paper", "tuned")
OBSERVATIONS = ("goal", "destinations", "paper")
DEFAULT_ENV_ID = "NomaRadioMap-v0"
EXPERIMENTS = ("table_ii", "ddpg_vs_dtdpg", "learning_rates", "paper_task", "paper_task_reality")
#: What ``--preset`` does to reproduce's paper-task experiments, which train both sets unless told otherwise.
PAPER_TASK_PRESET_NOTE = (
    "; the paper_task experiments train both sets, which they compare, unless --preset is given: then only its runs"
)
_PRESET_HELP = (
    "hyperparameter set. tuned: the best measured DT-DPG settings, for DT-DPG and DDPG alike (docs/BENCHMARKS.md; "
    "the default); paper: Table I (the default of td3, sac and tqc, which have no tuned set)"
)
_OVERRIDES_HELP = (
    "override single hyperparameters, RL Zoo style: key:value ... (e.g. learning_rate:3e-4 batch_size:256 "
    "policy_kwargs:'dict(net_arch=[64, 64], activation_fn=nn.Tanh)'); values are Python literals or torch's module "
    "and optimizer classes (nn.Tanh, th.optim.Adam)"
)
MODES = ("noma", "oma")
_OBSERVATION_HELP = (
    "goal: each robot's position, destination, channel gain and arrived flag plus its direction and distance to "
    "its destination (an extension, docs/BENCHMARKS.md: what makes DT-DPG learn the mission in the paper's budget; "
    "the default everywhere); destinations: the same without direction and distance; paper: the paper's state, "
    "Eq. (24), position and gain only (for the paper's task, fixed destinations)"
)

#: The default of ``--observation`` where the command takes ``--env``: what ``gymnasium.make(env id)`` gives.
_ENV_OBSERVATION_NOTE = "default: the env id's, paper on NomaRadioMapPaper-v0 and NomaRadioMapPaperOMA-v0, else goal"


# ---------------------------------------------------------------------------------------------- argument types
def budget_name(value: str) -> str:
    from sb3_dtdpg.experiments.budgets import BUDGET_ALIASES, BUDGETS, PUBLIC_BUDGETS

    if value not in BUDGETS:
        raise argparse.ArgumentTypeError(f"budget must be one of {', '.join(PUBLIC_BUDGETS)}, got {value!r}")
    if value in BUDGET_ALIASES:
        print(f"sb3-dtdpg: warning: --budget {value} is deprecated, use --budget {BUDGET_ALIASES[value]}", file=sys.stderr)
        value = BUDGET_ALIASES[value]
    return value


_learning_rate = checked(float, lambda x: math.isfinite(x) and x > 0, "a positive finite learning rate")
_threads = checked(int, lambda n: n >= 0, "0 (torch's default) or a positive number of threads")


def _check_no_file_on_the_way(value: str, folder: Path) -> None:
    """:raises argparse.ArgumentTypeError: a file stands where ``folder`` (of the option's ``value``) or a folder above
    it would be, or the nearest folder that exists is not writable (an error before any work, not after it)"""
    for part in (folder, *folder.parents):
        if part.exists():
            if not part.is_dir():
                raise argparse.ArgumentTypeError(f"{value!r}: {str(part)!r} is a file, expected a folder")
            if not os.access(part, os.W_OK | os.X_OK):
                raise argparse.ArgumentTypeError(f"{value!r}: the folder {str(part)!r} is not writable")
            return


def _output_file(suffixes: tuple[str, ...]) -> Any:
    def check(value: str) -> str:
        if Path(value).suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"expected a {' or '.join(suffixes)} file, got {value!r}")
        if Path(value).is_dir():
            raise argparse.ArgumentTypeError(f"{value!r} is a folder, expected a file name")
        _check_no_file_on_the_way(value, Path(value).parent)
        return value

    return check


def output_folder(value: str) -> str:
    """An output folder: it may not exist yet, but no part of its path may be a file (nor may it be empty: the
    current folder is written as ``.``)."""
    if not value.strip():
        raise argparse.ArgumentTypeError(f"expected a folder, got {value!r} (write . for the current folder)")
    _check_no_file_on_the_way(value, Path(value))
    return value


def run_tag(value: str) -> str:
    """A variant's name, part of a folder name: letters, digits and ``._+-`` (:func:`sb3_dtdpg.common.files.safe_name`
    keeps it as it is); empty for none."""
    from sb3_dtdpg.common.files import safe_name

    if value and safe_name(value) != value:
        raise argparse.ArgumentTypeError(
            f"expected a name of letters, digits and ._+- (part of a folder name: no '..', '__' or leading '.'), got {value!r}"
        )
    return value


def scenario_name(value: str) -> str:
    """
    A built-in scenario name or a scenario YAML file, loaded (so validated) once while parsing.

    The rule (:func:`noma_radiomap.load_scenario`): a bare built-in name (``small``) is the built-in scenario;
    write a path (``./small``, ``small.yaml``) for a file. A note says so when a file of that bare name exists.
    """
    from noma_radiomap import list_scenarios, load_scenario

    try:
        load_scenario(value)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    if value in list_scenarios() and os.path.exists(value):
        print(
            f"sb3-dtdpg: note: --scenario {value} is the built-in scenario; for the file {value!r} here write ./{value}",
            file=sys.stderr,
        )
    return value


def registered_env_id(value: str) -> str:
    """A registered Gymnasium env id (the NomaRadioMap ids are registered by importing ``noma_radiomap``)."""
    import gymnasium as gym

    import noma_radiomap  # noqa: F401

    try:
        gym.spec(value)
    except gym.error.Error as error:
        raise argparse.ArgumentTypeError(f"{value!r} is not a registered env id ({error})") from None
    return value


class DeprecatedOption(argparse.Action):
    """The old spelling of an option: stores its value like the new one and says which one to use."""

    def __init__(self, option_strings: list[str], dest: str, replacement: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, **kwargs)
        self.replacement = replacement

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option_string: Any = None):
        print(f"{parser.prog}: warning: {option_string} is deprecated, use {self.replacement}", file=sys.stderr)
        setattr(namespace, self.dest, values)


class _HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, with the budgets' details filled in when help is shown (not when the parser is built)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help
        if text and "%(budgets)s" in text:
            from sb3_dtdpg.experiments.budgets import BUDGETS, PUBLIC_BUDGETS

            budgets = "; ".join(
                f"{name}: {BUDGETS[name].episodes} episodes on {BUDGETS[name].scenario or 'mall'}, "
                f"{BUDGETS[name].seeds} seed{'s' if BUDGETS[name].seeds != 1 else ''}"
                + (
                    " (the paper's scale, --budget paper: compare 15-30 min on 2 cores, reproduce longer; docs/RESULTS.md)"
                    if name == "paper"
                    else ""
                )
                for name in PUBLIC_BUDGETS
            )
            text = text.replace("%(budgets)s", budgets)
        return text


def _budget_help(default: str) -> str:
    return f"experiment scale (default: {default}). %(budgets)s"


def add_seeds(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--n-seeds",
        type=_seed_count,
        default=None,
        metavar="N",
        help="seeds per configuration, 0..N-1 (default: the budget's)",
    )
    p.add_argument(
        "--seeds", type=_seed_count, dest="n_seeds", action=DeprecatedOption, replacement="--n-seeds", help=argparse.SUPPRESS
    )


def _add_hyperparameter_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", choices=PRESETS, default=None, help=_PRESET_HELP)
    p.add_argument("--hyperparams", nargs="+", default=None, metavar="KEY:VALUE", help=_OVERRIDES_HELP)


def add_common_run_options(
    p: argparse.ArgumentParser, observation_default: str | None, observation_note: str, preset_note: str = ""
) -> None:
    p.add_argument("--preset", choices=PRESETS, default=None, help=_PRESET_HELP + preset_note)
    p.add_argument(  # compare and reproduce take whole presets: their run identities name the preset
        "--hyperparams",
        choices=PRESETS,
        dest="preset",
        action=DeprecatedOption,
        replacement="--preset",
        help=argparse.SUPPRESS,
    )
    p.add_argument(
        "--observation", choices=OBSERVATIONS, default=observation_default, help=f"{_OBSERVATION_HELP} ({observation_note})"
    )
    p.add_argument("--workers", type=positive_int, default=None, help="parallel processes (default: number of CPUs)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars; a line per finished run instead")


def _add_saved_model_options(p: argparse.ArgumentParser, seed_help: str) -> None:
    p.add_argument("model", help="a model zip (train/compare: <out>/runs/<run id>/model.zip; the RL Zoo's; model.save's)")
    p.add_argument(
        "--algo", choices=ALGORITHMS, default=None, help="the model's algorithm (default: from the run or the model file)"
    )
    p.add_argument("--env", type=registered_env_id, default=None, help=f"env id (default: the run's, else {DEFAULT_ENV_ID})")
    p.add_argument("--scenario", type=scenario_name, default=None, help="scenario (default: the one the model was trained on)")
    p.add_argument(
        "--multiple-access", choices=MODES, default=None, help="downlink mode (default: the one the model was trained on)"
    )
    p.add_argument(
        "--observation", choices=OBSERVATIONS, default=None, help="observation (default: the one the model was trained on)"
    )
    p.add_argument(
        "--channel",
        choices=("rayleigh", "radio_map"),
        default="rayleigh",
        help="test channel (default: rayleigh, the paper's random fading)",
    )
    p.add_argument("--seed", type=_seed, default=10_000, help=seed_help)


def build_parser() -> argparse.ArgumentParser:
    """:return: the argument parser of ``sb3-dtdpg`` (built without importing torch or Stable-Baselines3)"""
    from sb3_dtdpg import __version__

    parser = argparse.ArgumentParser(
        prog="sb3-dtdpg",
        description="DT-DPG on the NOMA indoor radio-map environment. --out is always an output folder.",
        epilog="RL Zoo training (any zoo flag): python -m sb3_dtdpg.train --algo dtdpg --env NomaRadioMap-v0 (docs/ZOO.md)",
        allow_abbrev=False,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    names = "map,train,compare,reproduce,evaluate,enjoy"
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="{" + names + "}", help="sb3-dtdpg <command> -h: its options"
    )

    def command(name: str, help_text: str) -> argparse.ArgumentParser:
        sub = commands.add_parser(
            name, help=help_text, description=help_text, allow_abbrev=False, formatter_class=_HelpFormatter
        )
        sub.set_defaults(error=sub.error, prog=sub.prog)
        return sub

    p = command("map", "write the power and SINR maps of a scenario (paper Fig. 4)")
    p.add_argument(
        "--scenario",
        type=scenario_name,
        default="mall",
        help="built-in scenario name, or a YAML path (write ./name for a file named like a built-in) (default: mall)",
    )
    p.add_argument(
        "--out",
        type=output_folder,
        default="results/maps",
        help="output folder; the figure is maps_<scenario>.png (default: results/maps)",
    )

    p = command("train", "one training run with TensorBoard logging, then a test evaluation")
    p.add_argument("--algo", required=True, choices=ALGORITHMS, help="the algorithm")
    p.add_argument(
        "--env",
        type=registered_env_id,
        default=DEFAULT_ENV_ID,
        help=f"any registered Gymnasium env id (default: {DEFAULT_ENV_ID}); --scenario, --multiple-access and "
        "--channel apply to the NomaRadioMap envs only",
    )
    p.add_argument(
        "--scenario", type=scenario_name, default=None, help="scenario name or YAML path (default: the env's, mall)"
    )
    budget = p.add_mutually_exclusive_group()
    budget.add_argument("--episodes", type=positive_int, default=500, help="training episodes (default: 500, the paper's)")
    budget.add_argument("--timesteps", type=positive_int, default=None, help="training timesteps instead of episodes")
    p.add_argument("--seed", type=_seed, default=0, help=f"seed of the run, 0..{_MAX_SEED} (default: 0)")
    p.add_argument("--multiple-access", choices=MODES, default=None, help="NOMA or OMA downlink (default: the env id's)")
    p.add_argument(
        "--channel", choices=("radio_map", "rayleigh"), default=None, help="training channel (default: the env id's)"
    )
    p.add_argument("--learning-rate", type=_learning_rate, default=None, help="override the algorithm's learning rate")
    _add_hyperparameter_options(p)
    p.add_argument(
        "--tag",
        type=run_tag,
        default="",
        help="a name for this variant (e.g. no_curriculum), part of the run's folder name, so of its TensorBoard "
        "label: runs of other --hyperparams are told apart by a hash otherwise",
    )
    p.add_argument(
        "--observation",
        choices=OBSERVATIONS,
        default=None,
        help=f"{_OBSERVATION_HELP} ({_ENV_OBSERVATION_NOTE})",
    )
    p.add_argument("--tb", type=output_folder, default=None, help="TensorBoard log folder (default: <out>/tb)")
    p.add_argument(
        "--out",
        type=output_folder,
        default="results/train",
        help="output folder: on the NomaRadioMap envs <out>/runs/<run id>/ gets the model, checkpoints and result; "
        "on other envs the model is <algo>_<env id>_s<seed>.zip, its checkpoints in <algo>_<env id>_s<seed>_checkpoints/ "
        "while it trains (default: results/train)",
    )
    p.add_argument(
        "--checkpoint-every",
        type=positive_int,
        default=10,
        help="save a checkpoint (model, replay buffer, env and random state) every N episodes (other envs: at the end "
        "of the first episode after every N x their step limit steps; none without a limit); the same command resumes "
        "from the last one, as the uninterrupted run would go on (default: 10)",
    )
    p.add_argument("--eval-episodes", type=positive_int, default=20, help="test episodes after training (default: 20)")
    p.add_argument("--eval-seed", type=_seed, default=10_000, help="seed of the first test episode (default: 10000)")
    p.add_argument(
        "--threads",
        type=_threads,
        default=1,
        help="torch threads (default: 1, fastest for these small networks; 0: torch's default)",
    )
    p.add_argument("--verbose", type=int, choices=(0, 1, 2), default=0, help="SB3 verbosity: 0, 1 or 2 (default: 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    p = command("compare", "the main job: DT-DPG vs DDPG, NOMA and OMA, several seeds, table and figures")
    p.add_argument("--budget", type=budget_name, default="default", help=_budget_help("default"))
    add_seeds(p)
    p.add_argument("--out", type=output_folder, default="results/compare", help="output folder (default: results/compare)")
    p.add_argument(
        "--algos", nargs="+", choices=ALGORITHMS, default=["dtdpg", "ddpg"], help="algorithms (default: dtdpg ddpg)"
    )
    p.add_argument(
        "--multiple-access", nargs="+", choices=MODES, default=list(MODES), help="downlink mode(s) (default: noma oma)"
    )
    p.add_argument(
        "--modes",
        nargs="+",
        choices=MODES,
        dest="multiple_access",
        action=DeprecatedOption,
        replacement="--multiple-access",
        help=argparse.SUPPRESS,
    )
    env_help = f"a NomaRadioMap env id (default: {DEFAULT_ENV_ID})"
    p.add_argument("--env", type=registered_env_id, default=DEFAULT_ENV_ID, help=env_help)
    p.add_argument("--scenario", type=scenario_name, default=None, help="scenario name or YAML path (default: the budget's)")
    add_common_run_options(p, None, _ENV_OBSERVATION_NOTE)

    p = command("reproduce", "every experiment of the paper's Section V; finished runs are not re-run")
    p.add_argument(
        "--budget",
        type=budget_name,
        default="tiny",
        help=_budget_help("tiny, the whole pipeline in minutes, too short to learn; smoke shows learning"),
    )
    add_seeds(p)
    p.add_argument("--out", type=output_folder, default="results/reproduce", help="output folder (default: results/reproduce)")
    p.add_argument("--report-only", action="store_true", help="only re-draw tables and figures from the finished runs")
    p.add_argument(
        "--experiments",
        nargs="+",
        choices=EXPERIMENTS,
        default=None,
        help="train only the runs of these experiments (default: all but paper_task_reality; at the paper's scale about "
        "45 minutes on 2 cores without the paper task, which takes about 5 hours more); the tables use every finished run",
    )
    p.add_argument(
        "--multiple-access",
        nargs="+",
        choices=MODES,
        default=None,
        help="train only the runs of these downlink modes (default: noma oma); the tables use every finished run",
    )
    add_common_run_options(
        p,
        "goal",
        "default: goal; the paper_task experiment always runs on the paper's state",
        PAPER_TASK_PRESET_NOTE,
    )

    p = command("evaluate", "test a saved model on the test missions and print the table of compare")
    _add_saved_model_options(p, "seed of the first test episode; episode i uses seed + i (default: 10000, as compare)")
    p.add_argument("--n-episodes", type=positive_int, default=20, help="test episodes (default: 20, the paper's)")
    p.add_argument("--json", type=_output_file((".json",)), default=None, help="also write summary and episodes as JSON")
    p.add_argument("--csv", type=_output_file((".csv",)), default=None, help="also write one row per episode as CSV")

    p = command("enjoy", "run one mission of a saved model; --record writes it as an animation (no display needed)")
    _add_saved_model_options(p, "seed of the mission (default: 10000, test episode 0 of evaluate and compare)")
    p.add_argument(
        "--record",
        type=_output_file((".gif", ".mp4")),
        default=None,
        metavar="FILE",
        help="write the mission as an animated .gif (or .mp4, needs ffmpeg): paths, power split, outage",
    )
    p.add_argument("--fps", type=positive_int, default=10, help="frames per second (default: 10; at most 50 for a .gif)")
    p.add_argument(
        "--max-frames",
        type=positive_int,
        default=120,
        help="at most this many frames; long missions skip steps (default: 120)",
    )
    return parser
