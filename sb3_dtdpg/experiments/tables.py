"""Result tables: per-run records, per-configuration summaries with 95 % CIs, Markdown, CSV and rich output.

Learners are summarised over seeds: each seed's test figures (the mean over its test episodes) are one
sample, and the CI is the t-interval over seeds. Planners have no seeds; their CI is over test episodes.
The test MQI also gets the interquartile mean (IQM) with a 95 % stratified-bootstrap CI
(:mod:`sb3_dtdpg.experiments.aggregate`), the RL field's summary for few-seed comparisons, over the same
samples as the mean: where a sample has no finite MQI, neither has a value (``-``). A CI that cannot be
estimated (one seed) is shown as ``n/a``, never as ``nan``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sb3_dtdpg.common.files import write_csv, write_text
from sb3_dtdpg.evaluation import EvaluationResult, format_ci, mean_ci
from sb3_dtdpg.experiments.aggregate import iqm, stratified_bootstrap_ci

__all__ = [
    "ALGO_LABELS",
    "PAPER_MQI_SCALE",
    "add_planner_fractions",
    "format_ci",
    "format_markdown",
    "format_paired_markdown",
    "paired_differences",
    "planner_row",
    "print_table",
    "run_records",
    "summarise",
    "table_notes",
]

ALGO_LABELS = {"dtdpg": "DT-DPG", "ddpg": "DDPG", "td3": "TD3", "sac": "SAC", "tqc": "TQC"}
_METRICS = ("success_rate", "mqi", "outage_steps", "mission_time")
#: The MQI scale of the paper's tables: ``t_total`` of its mall scenario (MQI is at most ``t_total``).
PAPER_MQI_SCALE = 1000.0


def _mqi_scale(scenario: str | None, env_id: str | None = None, content: Any = None) -> float:
    """``t_total`` (the largest possible MQI) of a run's scenario as its env id's task runs it (the paper's task:
    1000): of the scenario content the run stored (its identity's), else of the scenario its spec names; ``nan`` if
    neither can be read."""
    import gymnasium as gym

    from noma_radiomap import Scenario, load_scenario
    from noma_radiomap.core import task_scenario

    try:
        task = gym.spec(env_id).kwargs.get("task", "missions") if env_id else "missions"
    except gym.error.Error:  # an id no longer registered: the missions task, the default of every id
        task = "missions"
    try:  # the stored content: a run is told by it, and it needs no file (one moved since is still this run)
        return float(task_scenario(Scenario.from_dict(content), task).mission.t_total)
    except (TypeError, ValueError, KeyError, AttributeError):
        pass
    try:
        return float(task_scenario(load_scenario(scenario or "mall"), task).mission.t_total)
    except (OSError, ValueError, KeyError):
        return math.nan


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
                "mqi_scale": _mqi_scale(
                    spec.get("scenario"), spec.get("env_id"), (result.get("identity") or {}).get("scenario")
                ),
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
        ``mqi_iqm`` with its bootstrap CI ``mqi_iqm_low`` / ``mqi_iqm_high`` (all ``nan``, like ``mqi``, where a
        run's MQI is not finite), ``mqi_scale`` (the scenario's ``t_total``) and ``train_timesteps`` (mean)
    """
    rows = []
    for key, group in records.groupby(list(by), sort=False, dropna=False):  # a NaN setting is a configuration too
        row: dict[str, Any] = dict(zip(by, key if isinstance(key, tuple) else (key,), strict=False))
        row["n"] = len(group)
        row["ci_over"] = "seeds"
        for metric in _METRICS:
            row[metric], row[f"{metric}_ci"] = mean_ci(group[metric].to_numpy())
        _add_iqm(row, group["mqi"].to_numpy())
        if "mqi_scale" in group:
            row["mqi_scale"] = float(group["mqi_scale"].max())
        row["train_timesteps"] = float(group["train_timesteps"].mean())
        rows.append(row)
    return pd.DataFrame(rows)


def paired_differences(
    records: pd.DataFrame,
    contrast: str,
    first: Any,
    second: Any,
    by: Sequence[str] = (),
    metrics: Sequence[str] = ("success_rate", "mqi"),
) -> pd.DataFrame:
    """
    Differences ``first - second`` of the test metrics, paired by seed: for each configuration of ``by``, the runs
    whose ``contrast`` column is ``first`` against those where it is ``second``, on the seeds both have. The
    CI is the t-interval of the per-seed differences (paired, so the seed's shared luck cancels out).

    :param records: output of :func:`run_records`
    :param contrast: the column that tells the two sides apart (e.g. ``"multiple_access"``)
    :param first: its value on the first side (e.g. ``"NOMA"``)
    :param second: its value on the second side
    :param by: columns that define a configuration (pairs are formed within one)
    :param metrics: the metrics to difference
    :return: one row per configuration with at least one pair: the ``by`` columns, ``contrast`` (text),
        ``n`` (pairs), ``<metric>`` (mean difference) and ``<metric>_ci`` columns
    :raises ValueError: a side has several runs of one seed in a configuration (``by`` misses a column)
    """
    rows = []
    groups = records.groupby(list(by), sort=False, dropna=False) if by else [((), records)]
    for key, group in groups:
        sides = [group[group[contrast] == value].set_index("seed") for value in (first, second)]
        for side, value in zip(sides, (first, second), strict=True):
            if not side.index.is_unique:  # pairs by seed need one run per seed and side
                repeated = sorted(set(side.index[side.index.duplicated()]))
                raise ValueError(
                    f"by: {contrast}={value!r} has several runs of seeds {repeated} in one configuration "
                    f"{dict(zip(by, key if isinstance(key, tuple) else (key,), strict=False))}: add the columns that "
                    "tell them apart to by"
                )
        seeds = sorted(set(sides[0].index) & set(sides[1].index))
        if not seeds:
            continue
        row: dict[str, Any] = dict(zip(by, key if isinstance(key, tuple) else (key,), strict=False))
        row.update(contrast=f"{first} - {second}", n=len(seeds))
        for metric in metrics:
            difference = sides[0].loc[seeds, metric].to_numpy(float) - sides[1].loc[seeds, metric].to_numpy(float)
            row[metric], row[f"{metric}_ci"] = mean_ci(difference)
        rows.append(row)
    return pd.DataFrame(rows)


def format_paired_markdown(differences: pd.DataFrame, columns: Sequence[str]) -> str:
    """
    :param differences: output of :func:`paired_differences` (several concatenated are fine)
    :param columns: the label columns to show after the contrast
    :return: a Markdown table: contrast, labels, pairs, success difference (points) and MQI difference
    """
    header = ["Contrast", *columns, "Pairs (seeds)", "Success (points)", "Test MQI"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for _, row in differences.iterrows():
        labels = [_label(row.get(c, math.nan)) for c in columns]  # a column no contrast has (one mode, one algorithm)
        cells = [
            str(row["contrast"]),
            *labels,
            str(int(row["n"])),
            format_ci(row["success_rate"], row["success_rate_ci"], 0, 100.0),
            format_ci(row["mqi"], row["mqi_ci"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _label(value: Any) -> str:
    """A label cell: ``-`` where a row has no value for the column (NaN), numbers in their short form."""
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:g}"
    return str(value)


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
    _add_iqm(row, np.array([float(e["mqi"]) for e in result.episodes]))
    row["train_timesteps"] = math.nan
    return row


def add_planner_fractions(
    summary: pd.DataFrame, best: str, shortest: str, planners: pd.DataFrame | None = None
) -> pd.DataFrame:
    """
    Every row's test MQI as a fraction of two planners' in the same mode: ``mqi_of_best`` (the best planner)
    and ``mqi_of_shortest`` (the shortest-path planner); ``mqi_gap`` is the best planner's optimality gap where a
    row has an upper bound: ``mqi_bound - mqi_radio_map``, both on the radio-map channel, where the bound holds
    (``mqi_bound - mqi`` for a row without ``mqi_radio_map``).

    :param summary: a summary (with the planner rows, unless ``planners`` is given)
    :param best: label (``algorithm``) of the best planner's rows
    :param shortest: label of the shortest-path planner's rows
    :param planners: the planner rows on the same test missions, for a summary that has none (e.g. Table II)
    :return: the summary with the new columns (NaN where a mode has no such planner row, or where the planner's
        MQI is not positive: a ratio to it would rank the rows backwards)
    """
    summary = summary.copy()
    rows = summary if planners is None else planners
    for column, label in (("mqi_of_best", best), ("mqi_of_shortest", shortest)):
        reference = rows[rows["algorithm"] == label].set_index("multiple_access")["mqi"]
        by_row = summary["multiple_access"].map(reference).astype(float)
        summary[column] = summary["mqi"] / by_row.where(by_row > 0)
    if "mqi_bound" in summary:
        on_radio_map = summary["mqi_radio_map"] if "mqi_radio_map" in summary else summary["mqi"]
        summary["mqi_gap"] = summary["mqi_bound"] - on_radio_map
    return summary


def _add_iqm(row: dict[str, Any], mqi: np.ndarray) -> None:
    """The IQM columns over the samples of the mean column: none where the mean has none (a non-finite MQI), where
    :func:`iqm` would drop that sample and the table's note ("same samples") would no longer hold."""
    mqi = np.asarray(mqi, dtype=np.float64)
    if not np.all(np.isfinite(mqi)):
        row["mqi_iqm"] = row["mqi_iqm_low"] = row["mqi_iqm_high"] = math.nan
        return
    row["mqi_iqm"] = iqm(mqi)
    row["mqi_iqm_low"], row["mqi_iqm_high"] = stratified_bootstrap_ci(mqi)


def _interval(value: float, low: float, high: float, digits: int = 1) -> str:
    if value is None or not np.isfinite(value):
        return "-"
    bounds = f"[{low:.{digits}f}, {high:.{digits}f}]" if np.isfinite(low) and np.isfinite(high) else "[n/a]"
    return f"{value:.{digits}f} {bounds}"


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _scales(summary: pd.DataFrame) -> list[float]:
    if "mqi_scale" not in summary:
        return []
    return sorted({float(v) for v in summary["mqi_scale"] if v is not None and np.isfinite(v)})


def table_notes(summary: pd.DataFrame) -> list[str]:
    """
    The notes printed under a table: what the ± and the brackets mean and, where the table's MQIs and
    the paper's are on different scales, how to compare them.

    :param summary: output of :func:`summarise` (plus planner rows; plus ``paper_mqi`` for the paper's values)
    :return: lines of text
    """
    notes = [
        "mean ± 95 % CI (t-interval over what n counts: seeds, or test episodes); n/a: one sample, no CI",
        "MQI IQM: interquartile mean with a 95 % percentile CI from the stratified bootstrap of Agarwal et al. (2021), "
        "computed with scipy.stats, same samples",
    ]
    if "mqi_of_best" in summary:
        notes.append(
            "of best, of shortest: the test MQI over the best planner's and over the shortest-path planner's in the same "
            "mode (best planner: a joint search over candidate paths with the best power split per step; shortest-path "
            "planner: the shortest paths with the best power split per step)"
        )
    if "mqi_bound" in summary:
        notes.append(
            "Bound (gap): an upper bound on the MQI of any policy on these missions with the radio-map channel "
            "(each robot alone with the whole AP power), and the best planner's distance from it on that channel "
            "(its optimality gap; with fading the NOMA bound still holds, the OMA one is not proven)"
        )
    scales = _scales(summary)
    if "paper_mqi" in summary and any(s != PAPER_MQI_SCALE for s in scales):
        ours = ", ".join(f"{s:g}" for s in scales)
        notes.append(
            f"Scales differ: MQI = t_total - sum over robots of (mission time + outage penalty x outage steps) is at "
            f"most t_total, {ours} for the scenario tested here but {PAPER_MQI_SCALE:g} for the paper's mall "
            f"scenario (Paper MQI); compare MQI / t_total, not the raw numbers"
        )
    return notes


def _display(summary: pd.DataFrame, columns: Sequence[str]) -> tuple[list[str], list[list[str]]]:
    names = {
        "algorithm": "Algorithm",
        "multiple_access": "MA",
        "training": "Training",
        "episodes": "Episodes",
        "learning_rate": "LR",
        "tag": "Run",
    }
    scales = _scales(summary)
    of = f" (of {scales[0]:g})" if len(scales) == 1 else ""
    header = [
        *(names.get(c, c) for c in columns),
        "n",
        "Success (%)",
        f"Test MQI{of}",
        "MQI IQM [95 % CI]",
        "Outage steps",
        "Mission time",
        "Train steps",
    ]
    fractions = "mqi_of_best" in summary and "mqi_of_shortest" in summary
    if fractions:
        header += ["of best", "of shortest"]
    if "mqi_bound" in summary:
        header.append("Bound (gap)")
    if "paper_mqi" in summary:
        header.append(f"Paper MQI (mall, of {PAPER_MQI_SCALE:g})")
    body = []
    for _, row in summary.iterrows():
        n = _count(int(row["n"]), "seed" if row["ci_over"] == "seeds" else "episode")
        steps = row.get("train_timesteps", math.nan)
        body.append(
            [
                *(str(row[c]) for c in columns),
                n,
                format_ci(row["success_rate"], row["success_rate_ci"], 0, 100.0),
                format_ci(row["mqi"], row["mqi_ci"]),
                _interval(row.get("mqi_iqm", math.nan), row.get("mqi_iqm_low", math.nan), row.get("mqi_iqm_high", math.nan)),
                format_ci(row["outage_steps"], row["outage_steps_ci"]),
                format_ci(row["mission_time"], row["mission_time_ci"]),
                "-" if not np.isfinite(steps) else f"{steps:,.0f}",
                *([_ratio(row["mqi_of_best"]), _ratio(row["mqi_of_shortest"])] if fractions else []),
                *([_bound(row["mqi_bound"], row.get("mqi_gap", math.nan))] if "mqi_bound" in summary else []),
                *([_plain(row["paper_mqi"])] if "paper_mqi" in summary else []),
            ]
        )
    return header, body


def _ratio(value: float) -> str:
    return f"{value:.3f}" if value is not None and np.isfinite(value) else "-"


def _bound(bound: float, gap: float) -> str:
    if bound is None or not np.isfinite(bound):
        return "-"
    return f"{bound:.1f} ({gap:+.1f})" if gap is not None and np.isfinite(gap) else f"{bound:.1f}"


def _plain(value: float) -> str:
    return f"{value:.1f}" if value is not None and np.isfinite(value) else "-"


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
    from rich.markup import escape
    from rich.table import Table

    header, body = _display(summary, columns)
    table = Table(title=title, caption="\n".join(table_notes(summary)))
    for k, name in enumerate(header):
        table.add_column(name, justify="left" if k < len(columns) else "right", no_wrap=True)
    for row in body:
        table.add_row(*(escape(cell) for cell in row))  # "[n/a]" is not rich markup
    Console(width=200).print(table)


def save_tables(
    summary: pd.DataFrame,
    records: pd.DataFrame,
    out: str | Path,
    stem: str,
    title: str,
    columns: Sequence[str] = ("algorithm", "multiple_access"),
    incomplete: str | None = None,
    extra_notes: Sequence[str] = (),
) -> None:
    """
    Write ``<stem>.md`` (Markdown), ``<stem>.csv`` (summary) and ``<stem>_runs.csv`` (one row per run), each
    atomically (a reader sees the previous file or the new one).

    :param incomplete: a line saying which runs are missing (failed), written in bold under the table
    :param extra_notes: more lines under the table, after the table's own notes
    """
    out = Path(out)
    notes = [f"**{incomplete}.**"] if incomplete else []
    notes += [f"{note}." for note in [*table_notes(summary), *extra_notes]]
    write_text(
        out / f"{stem}.md",
        f"# {title}\n\n" + format_markdown(summary, columns) + "\n" + "".join(f"{note}\n\n" for note in notes),
    )
    write_csv(out / f"{stem}.csv", summary)
    if not records.empty:
        write_csv(out / f"{stem}_runs.csv", records)
