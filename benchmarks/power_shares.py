"""DT-DPG with the power actions read as shares of the AP's power, against the env's own mapping, paired by seed.

Under the env's mapping (paper Eq. (15e)) a robot's power is ``P_max (a_u + 1) / 2``, scaled down when the robots
ask for more than ``P_max`` and never up; with ``power_mapping="shares"``
(:class:`noma_radiomap.wrappers.PowerShares`) the robots under way always share the whole ``P_max`` in the ratio of
their ``(a_u + 1) / 2``; this measures what the mapping changes (docs/RESULTS.md, "Power as shares of ``P_max``"). For each
seed and mode, one DT-DPG run (``--algos``: also DDPG) with each mapping at the budget's scale (the tuned settings
and goal observation of ``compare``), tested on the 20 Rayleigh test missions of ``compare``; printed: each arm's
mean test MQI (95 % t-interval over the seeds), the paired difference shares - paper, and the two planners on the
same missions.
Finished runs are reused, so the command can be interrupted and run again.

Usage::

    python benchmarks/power_shares.py [--budget paper] [--seeds 5] [--modes noma oma] [--out results/power_shares]
    python benchmarks/power_shares.py --budget paper-x4 --channel rayleigh --modes noma --out results/power_shares_x4
    python benchmarks/power_shares.py --algos ddpg --out results/power_shares   # the same for plain DDPG
    python benchmarks/learner_gap.py results/power_shares   # where each arm loses: its paths or its split
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pandas as pd

from sb3_dtdpg.arguments import positive_int, seed_count
from sb3_dtdpg.evaluation import format_ci, mean_ci
from sb3_dtdpg.experiments.compare import BEST_PLANNER, SHORTEST_PATH_PLANNER, compare_specs, evaluate_planners
from sb3_dtdpg.experiments.runs import (
    DamagedRecordError,
    OutputBusyError,
    RunDivergedError,
    RunMismatchError,
    RunSpec,
    get_budget,
    load_result,
    output_lock,
    run_many,
)
from sb3_dtdpg.experiments.tables import ALGO_LABELS

#: The two arms: the env's own mapping and the shares
MAPPINGS = ("paper", "shares")


def specs(
    budget: str, seeds: int, modes: list[str], channel: str = "radio_map", algos: tuple[str, ...] = ("dtdpg",)
) -> list[RunSpec]:
    """:return: one run per algorithm, seed, mode and mapping (the runs of ``compare --budget <budget>``, trained on
    ``channel``)"""
    base = compare_specs(
        get_budget(budget), seeds, algos=algos, modes=modes, hyperparams="tuned", observation="goal", channel=channel
    )
    return [dataclasses.replace(spec, power_mapping=mapping) for mapping in MAPPINGS for spec in base]


def run_rows(out: Path, runs: list[RunSpec]) -> pd.DataFrame:
    """:return: one row per finished run: algorithm, mode, mapping, seed, test MQI and success (Rayleigh test missions)"""
    rows = []
    for spec in runs:
        result = load_result(out, spec)
        if result is not None:
            summary = result["eval"]["summary"]
            rows.append(
                {
                    "algo": spec.algo,
                    "multiple_access": spec.multiple_access,
                    "power_mapping": spec.power_mapping,
                    "seed": spec.seed,
                    "run": spec.run_id,
                    "mqi": summary["mqi"],
                    "success_rate": summary["success_rate"],
                }
            )
    return pd.DataFrame(rows)


def summary_lines(rows: pd.DataFrame, planners: dict[tuple[str, str], float], missions: int) -> list[str]:
    """:return: the markdown table: per algorithm and mode, each arm's test MQI and the paired difference shares -
    paper; then the planners' MQI on the ``missions`` test missions"""
    lines = [
        "| algorithm | MA | power mapping | seeds | test MQI (Rayleigh) | of best / of shortest | success (%) |",
        "|---|---|---|---|---|---|---|",
    ]
    for (algo, mode), group in rows.groupby(["algo", "multiple_access"], sort=False):
        best, shortest = planners[(BEST_PLANNER, mode.upper())], planners[(SHORTEST_PATH_PLANNER, mode.upper())]
        label = f"| {ALGO_LABELS.get(algo, algo)} | {mode.upper()} |"
        for mapping in MAPPINGS:
            arm = group[group["power_mapping"] == mapping]
            if arm.empty:
                continue
            mqi, ci = mean_ci(arm["mqi"])
            lines.append(
                f"{label} {mapping} | {len(arm)} | {format_ci(mqi, ci)} | {mqi / best:.3f} / {mqi / shortest:.3f} | "
                f"{100 * arm['success_rate'].mean():.0f} |"
            )
        paired = group.pivot(index="seed", columns="power_mapping", values="mqi").dropna()
        if set(MAPPINGS) <= set(paired.columns) and len(paired):
            difference, ci = mean_ci(paired["shares"] - paired["paper"])
            ahead = int((paired["shares"] > paired["paper"]).sum())
            lines.append(
                f"{label} shares - paper, paired | {len(paired)} | {_signed(format_ci(difference, ci))} "
                f"(shares ahead on {ahead} of {len(paired)} seeds) | | |"
            )
    for mode in rows["multiple_access"].unique():
        best, shortest = planners[(BEST_PLANNER, mode.upper())], planners[(SHORTEST_PATH_PLANNER, mode.upper())]
        lines.append(
            f"| best / shortest-path planner | {mode.upper()} | | {missions} missions | {best:.1f} / {shortest:.1f} | | |"
        )
    return lines


def _signed(text: str) -> str:
    """:return: a :func:`~sb3_dtdpg.evaluation.format_ci` cell with the mean's sign (``+1.0 ± 0.5``)"""
    return text if text.startswith(("-", "+")) else "+" + text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--budget", default="paper", help="budget of the runs (default: paper, 500 episodes)")
    parser.add_argument(
        "--seeds", type=seed_count, default=5, help="how many seeds per mode and mapping, seeds 0..N-1 (a count; default: 5)"
    )
    parser.add_argument("--modes", nargs="+", default=["noma", "oma"], choices=["noma", "oma"])
    parser.add_argument("--algos", nargs="+", default=["dtdpg"], choices=["dtdpg", "ddpg"], help="default: dtdpg")
    parser.add_argument(
        "--channel", default="radio_map", choices=["radio_map", "rayleigh"], help="training channel (default: radio_map)"
    )
    parser.add_argument("--out", type=Path, default=Path("results/power_shares"), help="output folder")
    parser.add_argument("--workers", type=positive_int, default=2, help="runs at a time (default: 2)")
    parser.add_argument("--csv", type=Path, default=None, help="write one row per run here")
    args = parser.parse_args()
    try:
        budget = get_budget(args.budget)
    except ValueError as error:
        parser.error(f"--budget: {error}")
    if args.csv is not None:  # a folder that cannot be made fails now, not after the training
        try:
            args.csv.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            parser.error(f"--csv {args.csv}: {error}")
    runs = specs(budget.name, args.seeds, args.modes, args.channel, tuple(args.algos))
    try:
        with output_lock(args.out):
            report = run_many(runs, args.out, n_workers=args.workers)
        for run_id, error in report.failed.items():
            print(f"run {run_id} failed: {error}")
        rows = run_rows(args.out, runs)
    except (OutputBusyError, RunMismatchError, DamagedRecordError, RunDivergedError) as error:
        # e.g. --channel or --budget other than those of the runs already in --out: one line, as the CLI's
        parser.error(str(error))
    if rows.empty:
        raise SystemExit(f"no finished runs in {args.out}")
    planner_rows, _ = evaluate_planners(args.modes, budget, names=(BEST_PLANNER, SHORTEST_PATH_PLANNER))
    planners = {(row["algorithm"], row["multiple_access"]): float(row["mqi"]) for row in planner_rows}
    print("\n".join(summary_lines(rows, planners, budget.eval_episodes)))
    if args.csv is not None:
        rows.to_csv(args.csv, index=False)
        print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
