"""The paper-task runs of an output folder of ``sb3-dtdpg train`` as one table: training success and test results.

``reproduce``'s ``paper_task`` experiment tabulates its own runs; this reads runs trained one at a time, e.g. the
Table I preset with a single value changed on the paper's task::

    for seed in 0 1; do for algo in dtdpg ddpg; do
      sb3-dtdpg train --algo $algo --env NomaRadioMapPaper-v0 --preset paper --hyperparams gamma:0.95 \\
          --episodes 500 --seed $seed --out results/paper_task_ablation --no-progress
    done; done
    python benchmarks/paper_task_runs.py results/paper_task_ablation --csv docs/csv/paper_task_gamma.csv

Training success is the share of training episodes in which every robot reached its destination (all episodes,
the first 100, the last 100; :func:`sb3_dtdpg.experiments.paper_task.training_success` on the run's TensorBoard
folder); the test columns are the run's 20 Rayleigh test missions. Below the per-run table: mean and 95 % CI
per configuration (t-interval over seeds) and DT-DPG - DDPG paired by seed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd

from sb3_dtdpg.evaluation import mean_ci
from sb3_dtdpg.experiments.paper_task import training_success
from sb3_dtdpg.experiments.tables import paired_differences

METRICS = ("train_success", "train_success_first100", "train_success_last100", "test_success", "test_mqi")
CONFIGURATION = ["preset", "overrides", "multiple_access"]


def run_rows(out: Path) -> pd.DataFrame:
    """
    :param out: an output folder of ``sb3-dtdpg train`` (``runs/<run id>/result.json``, ``tb/<run id>/``)
    :return: one row per finished run, sorted by overrides, algorithm and seed
    """
    rows = []
    for result_file in sorted((out / "runs").glob("*/result.json")):
        result = json.loads(result_file.read_text())
        spec, test = result["spec"], result["eval"]["summary"]
        run_id = result_file.parent.name
        every, first, last, n_episodes = training_success(out / "tb" / run_id)
        rows.append(
            {
                "run_id": run_id,
                "algo": spec["algo"],
                "preset": spec["hyperparams"],
                "overrides": " ".join(f"{name}:{value}" for name, value in spec.get("overrides") or []),
                "multiple_access": spec["multiple_access"],
                "seed": spec["seed"],
                "episodes": n_episodes,
                "train_success": every,
                "train_success_first100": first,
                "train_success_last100": last,
                "test_success": test["success_rate"],
                "test_mqi": test["mqi"],
                "wall_s": result["train"]["wall_s"],
            }
        )
    frame = pd.DataFrame(rows)
    return frame.sort_values(["overrides", "algo", "seed"], ascending=[True, False, True]) if rows else frame


def summary_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :return: per configuration and algorithm: ``n`` (seeds) and ``<metric> ± <95 % CI>`` text per metric
    """
    rows = []
    for key, group in frame.groupby([*CONFIGURATION, "algo"], sort=False):
        row = dict(zip([*CONFIGURATION, "algo"], key, strict=True))
        row["n"] = len(group)
        for metric in METRICS:
            row[metric] = _with_ci(*mean_ci(group[metric].to_numpy(dtype=float)), metric)
        rows.append(row)
    return pd.DataFrame(rows)


def paired_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :return: DT-DPG - DDPG per configuration on the seeds both have: ``n`` (pairs) and ``<difference> ± <95 % CI>``
    """
    differences = paired_differences(frame, "algo", "dtdpg", "ddpg", by=CONFIGURATION, metrics=METRICS)
    for metric in METRICS:
        differences[metric] = [
            _with_ci(value, half, metric) for value, half in zip(differences[metric], differences[f"{metric}_ci"], strict=True)
        ]
    return differences[[*CONFIGURATION, "contrast", "n", *METRICS]]


def _with_ci(value: float, half: float, metric: str) -> str:
    scale = 1 if metric == "test_mqi" else 100
    return f"{scale * value:.1f} ± {scale * half:.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    parser.add_argument("out", type=Path, help="the output folder of the train runs")
    parser.add_argument("--csv", type=Path, default=None, help="also write the table here")
    args = parser.parse_args()
    if not (args.out / "runs").is_dir():
        parser.error(f"{args.out}: no runs/ folder (give the --out of the train runs)")
    frame = run_rows(args.out)
    if frame.empty:
        parser.error(f"{args.out}: no finished run (runs/*/result.json)")
    if args.csv is not None:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        frame.to_csv(args.csv, index=False)
    shown = frame.drop(columns=["run_id"]).copy()
    for column in ("train_success", "train_success_first100", "train_success_last100", "test_success"):
        shown[column] = (100 * shown[column]).round(1)
    print(shown.to_string(index=False, float_format=lambda value: f"{value:.1f}"))
    print("\nmean ± 95 % CI (t-interval over seeds); success in %")
    print(summary_rows(frame).to_string(index=False))
    paired = paired_rows(frame)
    if not paired.empty:
        print("\npaired by seed: mean difference ± 95 % CI (t-interval over the per-seed differences); success in points")
        print(paired.to_string(index=False))


if __name__ == "__main__":
    main()
