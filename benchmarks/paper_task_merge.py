"""The paper-task tables of ``reproduce`` from the per-run CSVs of several output folders.

A job that ran some seeds and a later one that ran the others (each writes ``paper_task_runs.csv``) give one
table over all of them, with the same statistics as ``reproduce``'s (mean and 95 % CI over seeds, DT-DPG - DDPG
paired by seed) and the reference planners' rows on the same test missions::

    python benchmarks/paper_task_merge.py results/paper_task_a/paper_task_runs.csv \\
        results/paper_task_b/paper_task_runs.csv --out results/paper_task_merged

Merge runs of one room only: the planners' rows are those of today's room, and the CSVs do not say which room
their runs trained on (docs/csv/mall_2026-12-03/ holds runs of the room before its last calibration).

The runs trained with Rayleigh fading (``paper_task_reality_runs.csv``) merge the same way into
``paper_task_reality*`` tables: the training channel is read from the runs' ``training`` column, and runs of
both channels are not merged into one table.

The training-success figure needs the runs' TensorBoard folders and is drawn by ``reproduce`` per folder.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from sb3_dtdpg.experiments.budgets import get_budget
from sb3_dtdpg.experiments.paper_task import merge_runs, write_tables


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    parser.add_argument(
        "runs", type=Path, nargs="+", help="paper_task_runs.csv or paper_task_reality_runs.csv files of reproduce"
    )
    parser.add_argument("--out", type=Path, required=True, help="folder for the merged tables")
    parser.add_argument("--budget", default="paper", help="the runs' budget (default: paper)")
    args = parser.parse_args()
    try:
        budget = get_budget(args.budget)
    except ValueError as error:
        parser.error(str(error))
    for path in args.runs:
        if not path.is_file():
            parser.error(f"{path}: no such file (give the paper_task_runs.csv of a reproduce folder)")
    try:
        records = merge_runs([pd.read_csv(path) for path in args.runs])
    except ValueError as error:
        parser.error(str(error))
    channels = sorted(records["training"].unique())
    if len(channels) != 1:
        parser.error(f"the runs were trained on several channels ({', '.join(channels)}): merge each channel's files alone")
    args.out.mkdir(parents=True, exist_ok=True)
    write_tables(args.out, budget, records, channel=channels[0])
    print(f"\n{len(records)} runs from {len(args.runs)} files; tables in {args.out}")


if __name__ == "__main__":
    main()
