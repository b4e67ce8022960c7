"""The paper-task tables of ``reproduce`` from the per-run CSVs of several output folders.

A job that ran some seeds and a later one that ran the others (each writes ``paper_task_runs.csv``) give one
table over all of them, with the same statistics as ``reproduce``'s (mean and 95 % CI over seeds, DT-DPG - DDPG
paired by seed) and the reference planners' rows on the same test missions::

    python benchmarks/paper_task_merge.py results/paper_task_a/paper_task_runs.csv \\
        results/paper_task_b/paper_task_runs.csv --out results/paper_task_merged

Merge runs of one budget and room only: the planners' rows are those of ``--budget``'s room today. The CSVs
record each run's room (``scenario``), test missions (``eval_episodes``) and ``configuration`` (a digest of
everything that decides its result but the seed), and runs of two budgets with the same training episodes (the
same run ids) are refused rather than merged as one; CSVs written before those columns existed do not say which
room their runs trained on (docs/csv/mall_2026-12-03/ holds runs of the room before its last calibration).

The runs trained with Rayleigh fading (``paper_task_reality_runs.csv``) merge the same way into
``paper_task_reality*`` tables: the training channel is read from the runs' ``training`` column, and runs of
both channels are not merged into one table.

The training-success figure needs the runs' TensorBoard folders and is drawn by ``reproduce`` per folder.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pandas as pd

from sb3_dtdpg.experiments.budgets import PUBLIC_BUDGETS, Budget, get_budget
from sb3_dtdpg.experiments.paper_task import (
    BUDGET_COLUMNS,
    merge_runs,
    recorded_values,
    table_name,
    task_episodes,
    write_tables,
)

#: The columns of ``paper_task_runs.csv`` that the merge and the tables read
REQUIRED_COLUMNS = (
    "group",
    "preset",
    "algorithm",
    "multiple_access",
    "training",
    "episodes",
    "seed",
    "success_rate",
    "mqi",
    "train_success",
    "train_success_first",
    "train_success_last",
)


def read_runs(path: Path) -> pd.DataFrame:
    """
    :param path: a ``paper_task_runs.csv`` or ``paper_task_reality_runs.csv`` of ``reproduce``
    :return: its per-run records
    :raises ValueError: naming the file when it is no CSV or lacks columns of those files
    """
    try:
        records = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not a CSV file ({error})") from error
    missing = [column for column in REQUIRED_COLUMNS if column not in records]
    if missing:
        raise ValueError(
            f"{path}: no column {', '.join(missing)} (give the paper_task_runs.csv or paper_task_reality_runs.csv "
            "of a reproduce folder)"
        )
    return records


def _budget_value(budget: Budget, column: str) -> Any:
    """:return: what the runs of ``budget`` record in a column of :data:`BUDGET_COLUMNS`"""
    return (budget.scenario or "mall") if column == "scenario" else getattr(budget, column)


def check_budget_episodes(name: str, records: pd.DataFrame, channel: str) -> None:
    """
    :param name: the ``--budget`` given
    :param records: the merged runs, all trained on ``channel``
    :param channel: their training channel
    :raises ValueError: naming the budget, its training episodes, room or test missions, and the runs' where they
        differ (the room and the test missions where the runs record them: CSVs of earlier versions do not)
    """
    budget = get_budget(name)
    expected = task_episodes(budget, channel)
    episodes = sorted(int(value) for value in records["episodes"].unique())
    if episodes != [expected]:
        matching = [other for other in PUBLIC_BUDGETS if [task_episodes(get_budget(other), channel)] == episodes]
        hint = f"give --budget {' or '.join(matching)}" if matching else "no budget trains that many; merge runs of one budget"
        raise ValueError(
            f"--budget {name}: {expected} training episodes per {channel} run, but the runs trained "
            f"{', '.join(map(str, episodes))} ({hint})"
        )
    for column in BUDGET_COLUMNS:
        found = recorded_values(records, column)
        if found and found != [_budget_value(budget, column)]:
            matching = [
                other
                for other in PUBLIC_BUDGETS
                if task_episodes(get_budget(other), channel) == expected
                and all(
                    c not in records or records[c].dropna().eq(_budget_value(get_budget(other), c)).all()
                    for c in BUDGET_COLUMNS
                )
            ]
            hint = f"give --budget {' or '.join(matching)}" if matching else "no budget has these runs' settings"
            raise ValueError(
                f"--budget {name}: {column} {_budget_value(budget, column)!r}, but the runs have {column} "
                f"{', '.join(map(repr, found))} ({hint})"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    parser.add_argument(
        "runs", type=Path, nargs="+", help="paper_task_runs.csv or paper_task_reality_runs.csv files of reproduce"
    )
    parser.add_argument("--out", type=Path, required=True, help="folder for the merged tables (not an input's folder)")
    parser.add_argument("--budget", default="paper", help="the runs' budget (default: paper)")
    args = parser.parse_args()
    try:
        budget = get_budget(args.budget)
    except ValueError as error:
        parser.error(f"--budget: {error}")
    for path in args.runs:
        if not path.is_file():
            parser.error(f"{path}: no such file (give the paper_task_runs.csv of a reproduce folder)")
        # The merged tables have the names of the inputs' (paper_task_runs.csv, paper_task.md): they would replace them
        if args.out.resolve() == path.parent.resolve():
            parser.error(f"--out {args.out}: the folder of the input {path}; the merged tables would overwrite its tables")
    try:
        records = merge_runs([read_runs(path) for path in args.runs])
    except ValueError as error:
        parser.error(str(error))
    channels = sorted(records["training"].unique())
    if len(channels) != 1:
        parser.error(f"the runs were trained on several channels ({', '.join(channels)}): merge each channel's files alone")
    try:
        check_budget_episodes(args.budget, records, channels[0])
    except ValueError as error:
        parser.error(str(error))
    args.out.mkdir(parents=True, exist_ok=True)
    write_tables(args.out, budget, records, channel=channels[0])
    print(f"\n{len(records)} runs from {len(args.runs)} files; tables {table_name(channels[0])}* in {args.out}")


if __name__ == "__main__":
    main()
