"""Result tables: per-run records, per-configuration summaries with 95 % CIs, Markdown, CSV and rich output.

Learners are summarised over seeds: each seed's test figures (the mean over its test episodes) are one
sample, and the CI is the t-interval over seeds. Planners have no seeds; their CI is over test episodes.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sb3_dtdpg.evaluation import EvaluationResult, mean_ci

__all__ = ["ALGO_LABELS", "format_markdown", "planner_row", "print_table", "run_records", "summarise"]

ALGO_LABELS = {"dtdpg": "DT-DPG", "ddpg": "DDPG", "td3": "TD3", "sac": "SAC", "tqc": "TQC"}
_METRICS = ("success_rate", "mqi", "outage_steps", "mission_time")


def run_records(results: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """
    One row per finished run, from the result dicts written by :func:`sb3_dtdpg.experiments.runs.run_one`.

    :param results: result dicts
    :return: a DataFrame (columns: group, algo, multiple_access, seed, tag, channel, episodes, the test
        metrics, train timesteps and wall time)
    """
    rows = []
    for result in results:
        spec, summary, train = result["spec"], result["eval"]["summary"], result["train"]
        rows.append(
            {
                "group": result["group"],
                "algorithm": ALGO_LABELS.get(spec["algo"], spec["algo"]),
                "algo": spec["algo"],
                "multiple_access": spec["multiple_access"].upper(),
                "training": spec["channel"],
                "episodes": spec["episodes"],
                "learning_rate": spec["learning_rate"],
                "tag": spec["tag"],
                "seed": spec["seed"],
                **{metric: summary[metric] for metric in _METRICS},
                "train_timesteps": train["timesteps"],
                "train_wall_s": train["wall_s"],
            }
        )
    return pd.DataFrame(rows)


def summarise(records: pd.DataFrame, by: Sequence[str] = ("algorithm", "multiple_access")) -> pd.DataFrame:
    """
    Mean and 95 % CI half-width (t-interval over seeds) of every test metric per configuration.

    :param records: output of :func:`run_records`
    :param by: the columns that define a configuration
    :return: one row per configuration: ``n`` (seeds), ``<metric>`` and ``<metric>_ci`` columns,
        ``train_timesteps`` (mean)
    """
    rows = []
    for key, group in records.groupby(list(by), sort=False):
        row: dict[str, Any] = dict(zip(by, key if isinstance(key, tuple) else (key,), strict=False))
        row["n"] = len(group)
        row["ci_over"] = "seeds"
        for metric in _METRICS:
            row[metric], row[f"{metric}_ci"] = mean_ci(group[metric].to_numpy())
        row["train_timesteps"] = float(group["train_timesteps"].mean())
        rows.append(row)
    return pd.DataFrame(rows)


def planner_row(name: str, multiple_access: str, result: EvaluationResult) -> dict[str, Any]:
    """
    A reference row for a planner (CI over test episodes).

    :param name: row label
    :param multiple_access: ``"noma"`` or ``"oma"``
    :param result: the planner's evaluation
    :return: a row compatible with :func:`summarise`'s output
    """
    summary = result.summary()
    row: dict[str, Any] = {"algorithm": name, "multiple_access": multiple_access.upper(), "n": result.n_episodes}
    row["ci_over"] = "episodes"
    success = np.array([float(e["success"]) for e in result.episodes])
    row["success_rate"], row["success_rate_ci"] = mean_ci(success)
    for metric in _METRICS[1:]:
        row[metric], row[f"{metric}_ci"] = summary[metric], summary[f"{metric}_ci"]
    row["train_timesteps"] = math.nan
    return row


def _pm(value: float, half: float, digits: int = 1, scale: float = 1.0) -> str:
    if value is None or not np.isfinite(value):
        return "-"
    text = f"{value * scale:.{digits}f}"
    return text + (f" ± {half * scale:.{digits}f}" if half is not None and np.isfinite(half) else "")


def _display(summary: pd.DataFrame, columns: Sequence[str]) -> tuple[list[str], list[list[str]]]:
    names = {
        "algorithm": "Algorithm",
        "multiple_access": "MA",
        "training": "Training",
        "episodes": "Episodes",
        "learning_rate": "LR",
        "tag": "Run",
    }
    header = [
        *(names.get(c, c) for c in columns),
        "n",
        "Success (%)",
        "Test MQI",
        "Outage steps",
        "Mission time",
        "Train steps",
    ]
    if "paper_mqi" in summary:
        header.append("Paper MQI")
    body = []
    for _, row in summary.iterrows():
        n = f"{int(row['n'])} {'seeds' if row['ci_over'] == 'seeds' else 'ep.'}"
        steps = row.get("train_timesteps", math.nan)
        body.append(
            [
                *(str(row[c]) for c in columns),
                n,
                _pm(row["success_rate"], row["success_rate_ci"], 0, 100.0),
                _pm(row["mqi"], row["mqi_ci"]),
                _pm(row["outage_steps"], row["outage_steps_ci"]),
                _pm(row["mission_time"], row["mission_time_ci"]),
                "-" if not np.isfinite(steps) else f"{steps:,.0f}",
                *([_pm(row["paper_mqi"], math.nan)] if "paper_mqi" in summary else []),
            ]
        )
    return header, body


def format_markdown(summary: pd.DataFrame, columns: Sequence[str] = ("algorithm", "multiple_access")) -> str:
    """
    :param summary: output of :func:`summarise` (plus planner rows)
    :param columns: the label columns to show first
    :return: a Markdown table (mean ± 95 % CI half-width)
    """
    header, body = _display(summary, columns)
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return "\n".join(lines) + "\n"


def print_table(summary: pd.DataFrame, title: str, columns: Sequence[str] = ("algorithm", "multiple_access")) -> None:
    """Print a summary as a rich table."""
    from rich.console import Console
    from rich.table import Table

    header, body = _display(summary, columns)
    table = Table(title=title, caption="mean ± 95 % CI (t-interval over seeds; planners: over test episodes)")
    for k, name in enumerate(header):
        table.add_column(name, justify="left" if k < len(columns) else "right", no_wrap=True)
    for row in body:
        table.add_row(*row)
    Console(width=200).print(table)


def save_tables(
    summary: pd.DataFrame,
    records: pd.DataFrame,
    out: str | Path,
    stem: str,
    title: str,
    columns: Sequence[str] = ("algorithm", "multiple_access"),
) -> None:
    """Write ``<stem>.md`` (Markdown), ``<stem>.csv`` (summary) and ``<stem>_runs.csv`` (one row per run)."""
    out = Path(out)
    (out / f"{stem}.md").write_text(
        f"# {title}\n\n"
        + format_markdown(summary, columns)
        + "\nmean ± 95 % CI (t-interval over seeds; planners: over test episodes)\n"
    )
    summary.to_csv(out / f"{stem}.csv", index=False)
    if not records.empty:
        records.to_csv(out / f"{stem}_runs.csv", index=False)
