"""The paper's central claim on the paper's own task: DDPG vs DT-DPG, Table I and the tuned preset
(docs/RESULTS.md, "The paper's task").

The paper (Sec. V) reports that under the same training constraints DDPG finds the destination in fewer than
20 % of its training episodes and DT-DPG in more than 95 %. This experiment trains both on the paper's task
(``NomaRadioMapPaper-v0``: one fixed destination per robot, the state of Eq. (24), 1000-step episodes;
docs/MODEL.md), radio-map training, with each preset of :data:`PRESETS`, and reports the share of training
episodes in which every robot reached its destination (over all episodes and over the last 100, as a curve)
beside the usual test metrics on the 20 Rayleigh test missions, with DT-DPG - DDPG paired by seed.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sb3_dtdpg.common.files import write_csv, write_text
from sb3_dtdpg.evaluation import mean_ci
from sb3_dtdpg.experiments import plots, tables
from sb3_dtdpg.experiments.budgets import Budget
from sb3_dtdpg.experiments.compare import BEST_PLANNER, SHORTEST_PATH_PLANNER, compare_specs, evaluate_planners
from sb3_dtdpg.experiments.specs import RunSpec, identity_digest

__all__ = [
    "ENV_ID",
    "LAST_EPISODES",
    "PRESETS",
    "merge_runs",
    "paper_task_specs",
    "paper_task_tables",
    "table_name",
    "task_episodes",
    "training_success",
    "write_tables",
]

#: The paper's task (the OMA runs pass ``multiple_access="oma"``).
ENV_ID = "NomaRadioMapPaper-v0"
#: The presets compared: Table I as printed, and the tuned set of the default mission (docs/MODEL.md).
PRESETS = ("paper", "tuned")
#: The training success rate is also reported over the first and over the last this many training episodes.
LAST_EPISODES = 100
#: The paper's claim: DDPG below, DT-DPG above these training success rates.
PAPER_CLAIM = {"DDPG": ("<", 0.20), "DT-DPG": (">", 0.95)}
#: The rates read from a run's training log (NaN where none was read): summarised over the seeds that have one
_TRAINING = ("train_success", "train_success_first", "train_success_last")
_METRICS = (*_TRAINING, "success_rate", "mqi")


def task_episodes(budget: Budget, channel: str = "radio_map") -> int:
    """
    :param budget: the experiment's scale
    :param channel: the training channel
    :return: the training episodes of a paper-task run: :attr:`~sb3_dtdpg.experiments.budgets.Budget.task_episodes`
        on the radio map, :attr:`~sb3_dtdpg.experiments.budgets.Budget.task_long_episodes` (Table II's 700 at the
        paper's scale) with Rayleigh fading
    """
    return budget.task_long_episodes if channel == "rayleigh" else budget.task_episodes


def paper_task_specs(
    budget: Budget, seeds: int, modes: Sequence[str] = ("noma", "oma"), channel: str = "radio_map"
) -> list[RunSpec]:
    """
    :param budget: the experiment's scale (:attr:`~sb3_dtdpg.experiments.budgets.Budget.task_episodes` training
        episodes per run on the radio map; :attr:`~sb3_dtdpg.experiments.budgets.Budget.task_long_episodes`,
        Table II's 700 at the paper's scale, with ``channel="rayleigh"``)
    :param seeds: seeds per configuration
    :param modes: the downlink modes
    :param channel: the training channel: ``"radio_map"`` (the paper's method) or ``"rayleigh"`` ("reality")
    :return: DT-DPG and DDPG runs on the paper's task, per preset, mode and seed (seed-major order is left to
        the caller)
    """
    reality = channel == "rayleigh"
    episodes = task_episodes(budget, channel)
    return [
        spec
        for preset in PRESETS
        for spec in compare_specs(
            budget,
            seeds,
            modes=modes,
            env_id=ENV_ID,
            hyperparams=preset,
            observation="paper",
            episodes=episodes,
            tag=f"paper_task_{'reality_' if reality else ''}{episodes}",
            eval_before_transfer=True,
            channel=channel,
        )
    ]


def training_success(log_dir: str | Path, window: int = LAST_EPISODES) -> tuple[float, float, float, int]:
    """
    :param log_dir: a run's TensorBoard folder
    :param window: the number of first and of final episodes of the second and third rate
    :return: the share of training episodes in which every robot reached its destination, over all episodes, over
        the first ``window`` and over the last ``window``, and the number of episodes (NaN rates when nothing was
        logged)
    """
    successes = plots.rolling_curve(log_dir, plots.SUCCESS_TAG, 1).to_numpy(dtype=float)
    if not len(successes):
        return float("nan"), float("nan"), float("nan"), 0
    return float(successes.mean()), float(successes[:window].mean()), float(successes[-window:].mean()), len(successes)


def _records(out: Path, specs: Sequence[RunSpec], results: dict[str, Any]) -> pd.DataFrame:
    finished = [s for s in specs if results.get(s.run_id) is not None]
    records = tables.run_records([results[s.run_id] for s in finished])
    if records.empty:
        return records
    rates = [training_success(out / "tb" / s.run_id) for s in finished]
    records.insert(1, "preset", [s.hyperparams for s in finished])
    records["train_success"] = [r[0] for r in rates]
    records["train_success_first"] = [r[1] for r in rates]
    records["train_success_last"] = [r[2] for r in rates]
    records["train_episodes"] = [r[3] for r in rates]
    # what tells a run from one of another budget under the same id (merge_runs): its room, its test missions and
    # its identity less the seed (one value for the seeds of one configuration)
    stored = [results[s.run_id] for s in finished]
    records["scenario"] = [_room(result) for result in stored]
    records["eval_episodes"] = [result["spec"].get("eval_episodes") for result in stored]
    records["configuration"] = [
        identity_digest(r["identity"], seed=False) if isinstance(r.get("identity"), dict) else None for r in stored
    ]
    return records


def _room(result: dict[str, Any]) -> str:
    """:return: the name of the room a run trained in: its identity's scenario, else its spec's (None: ``mall``)"""
    content = (result.get("identity") or {}).get("scenario")
    if isinstance(content, dict) and isinstance(content.get("name"), str):
        return content["name"]
    return result["spec"].get("scenario") or "mall"


def _summary(records: pd.DataFrame) -> pd.DataFrame:
    """One row per preset, algorithm and mode: ``n`` seeds (the test metrics), ``train_n`` of them with a training
    log (the training success rates: a seed without one no longer blanks the row's)."""
    rows = []
    for (preset, algorithm, mode), group in records.groupby(["preset", "algorithm", "multiple_access"], sort=False):
        logged = group["train_success"].notna()
        row: dict[str, Any] = {"preset": preset, "algorithm": algorithm, "multiple_access": mode, "n": len(group)}
        row["train_n"] = int(logged.sum())
        for metric in _METRICS:
            values = group.loc[logged, metric] if metric in _TRAINING else group[metric]
            row[metric], row[f"{metric}_ci"] = mean_ci(values.to_numpy(dtype=float))
        claim = PAPER_CLAIM.get(algorithm)
        if claim is not None:
            side, bar = claim
            verdict = _claim_verdict(side, bar, row["train_success"], row["train_success_ci"])
            row["paper_claim"] = f"{side} {100 * bar:.0f} %: {verdict}"
        rows.append(row)
    return pd.DataFrame(rows)


def _paired(records: pd.DataFrame) -> pd.DataFrame:
    """DT-DPG - DDPG by seed per preset and mode: the test metrics on the ``n`` seeds both have, the training rates
    on the ``train_n`` of them with both training logs."""
    by = ("preset", "multiple_access")
    test = tables.paired_differences(records, "algorithm", "DT-DPG", "DDPG", by=by, metrics=("success_rate", "mqi"))
    if test.empty:
        return test
    logged = records[records["train_success"].notna()]
    training = tables.paired_differences(logged, "algorithm", "DT-DPG", "DDPG", by=by, metrics=_TRAINING)
    key = [*by, "contrast"]
    if training.empty:
        training = pd.DataFrame(columns=[*key, "n", *(f"{m}{s}" for m in _TRAINING for s in ("", "_ci"))])
    paired = test.merge(training.rename(columns={"n": "train_n"}), on=key, how="left")
    paired["train_n"] = paired["train_n"].fillna(0).astype(int)
    return paired[[*key, "n", "train_n", *(f"{m}{s}" for m in _METRICS for s in ("", "_ci"))]]


def _claim_verdict(side: str, bar: float, mean: float, half_width: float) -> str:
    """
    Whether a training success rate meets one of the paper's claims (Sec. V), judged on the mean over seeds and its
    95 % CI: the verdict of the mean, qualified ("on the mean") where the CI reaches the other side of the bar.

    :param side: ``"<"`` or ``">"``
    :param bar: the claim's rate (0.2, 0.95)
    :param mean: the mean rate over the seeds with training logs (NaN: none has one)
    :param half_width: its CI half-width (NaN: one seed, judged on the value)
    """
    if not np.isfinite(mean):
        return "n/a (no training logs)"
    holds = mean < bar if side == "<" else mean > bar
    verdict = "holds" if holds else "does not hold"
    if not np.isfinite(half_width):
        return verdict
    low, high = mean - half_width, mean + half_width
    crosses = (high >= bar if holds else low < bar) if side == "<" else (low <= bar if holds else high > bar)
    if not crosses:
        return verdict
    reach = f"up to {100 * high:.1f} %" if (side == "<") == holds else f"down to {100 * low:.1f} %"
    return f"{verdict} on the mean (its CI reaches {reach})"


def _with_planners(summary: pd.DataFrame, budget: Budget) -> pd.DataFrame:
    """The summary with the reference planners' rows on the same test missions, and every row's MQI as a fraction
    of the best and of the shortest-path planner's."""
    modes = [mode.lower() for mode in dict.fromkeys(summary["multiple_access"])]
    planners = pd.DataFrame(evaluate_planners(modes, budget, env_id=ENV_ID)[0])
    planners.insert(0, "preset", "-")
    summary = pd.concat([summary, planners[[c for c in planners if c in summary or c in ("preset", "n")]]])
    return tables.add_planner_fractions(summary.reset_index(drop=True), BEST_PLANNER, SHORTEST_PATH_PLANNER)


def _markdown(summary: pd.DataFrame, paired: pd.DataFrame, title: str) -> str:
    header = [
        "Preset",
        "Algorithm",
        "MA",
        "n",
        "Training success, all (%)",
        f"first {LAST_EPISODES} (%)",
        f"last {LAST_EPISODES} (%)",
        "Test success (%)",
        "Test MQI",
        "of best",
        "of shortest",
        "Paper's claim",
    ]
    lines = [f"# {title}", "", "| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for _, row in summary.iterrows():
        count = f"{row['n']} {('seed' if row['n'] == 1 else 'seeds') if row['preset'] != '-' else 'episodes'}"
        cells = [
            str(row["preset"]),
            str(row["algorithm"]),
            str(row["multiple_access"]),
            count + (_logged(row["train_n"], row["n"]) if row["preset"] != "-" else ""),
            *(
                tables.format_ci(row[m], row[f"{m}_ci"], scale=100.0)
                for m in ("train_success", "train_success_first", "train_success_last")
            ),
            tables.format_ci(row["success_rate"], row["success_rate_ci"], 0, 100.0),
            tables.format_ci(row["mqi"], row["mqi_ci"]),
            *(f"{row[c]:.3f}" if np.isfinite(row[c]) else "n/a" for c in ("mqi_of_best", "mqi_of_shortest")),
            str(row["paper_claim"]) if isinstance(row["paper_claim"], str) else "",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        "mean ± 95 % CI half-width (t-interval over seeds); training success: the share of training episodes in which "
        "every robot reached its destination, over the seeds with a training log (n says how many where fewer than "
        "all); of best, of shortest: the test MQI over the best planner's and over "
        "the shortest-path planner's (with its best power split) on the same missions; planners: CI over the test "
        "missions.",
        "",
    ]
    if not paired.empty:
        header = ["Contrast", "Preset", "MA", "Pairs (seeds)", "Training success, all (points)"]
        header += [f"first {LAST_EPISODES}", f"last {LAST_EPISODES}"]
        header += ["Test success (points)", "Test MQI"]
        lines += ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
        for _, row in paired.iterrows():
            pairs = str(row["n"]) + _logged(row["train_n"], row["n"])
            cells = [str(row["contrast"]), str(row["preset"]), str(row["multiple_access"]), pairs]
            cells += [
                tables.format_ci(row[m], row[f"{m}_ci"], scale=100.0)
                for m in ("train_success", "train_success_first", "train_success_last")
            ]
            cells += [
                tables.format_ci(row["success_rate"], row["success_rate_ci"], 0, 100.0),
                tables.format_ci(row["mqi"], row["mqi_ci"]),
            ]
            lines.append("| " + " | ".join(cells) + " |")
        lines += ["", "paired by seed: mean difference ± 95 % CI (t-interval over the per-seed differences).", ""]
    return "\n".join(lines)


def _logged(count: int, n: int) -> str:
    """The n cell's note where some but not all seeds have a training log: the training rates are over those (none:
    the rates are "-" and the claim says so)."""
    return f" ({int(count)} with training logs)" if 0 < count < n else ""


def write_tables(
    out: Path,
    budget: Budget,
    records: pd.DataFrame,
    progress: bool = True,
    channel: str = "radio_map",
    incomplete: str | None = None,
) -> pd.DataFrame:
    """
    Write ``<name>.md``, ``<name>.csv``, ``<name>_runs.csv`` and ``<name>_paired.csv`` (see
    :func:`paper_task_tables`; ``<name>`` is :func:`table_name` of the training channel) from per-run records.

    :param out: output folder
    :param budget: the runs' budget (for the planners' rows and the title)
    :param records: one row per run, the columns of ``paper_task_runs.csv``
    :param progress: print the Markdown table
    :param channel: the runs' training channel
    :param incomplete: a line saying which runs are missing (failed), written in bold under the title
    :return: the summary, with the reference planners' rows
    """
    summary = _with_planners(_summary(records), budget)
    paired = _paired(records)
    title = (
        f"The paper's task: DDPG vs DT-DPG ({budget.name} budget: {_training(budget, channel)}, "
        f"{budget.scenario or 'mall'}, {budget.eval_episodes} Rayleigh test missions)"
    )
    text = _markdown(summary, paired, title)
    if incomplete:
        heading, _, body = text.partition("\n\n")
        text = f"{heading}\n\n**{incomplete}.**\n\n{body}"
    name = table_name(channel)
    write_text(out / f"{name}.md", text)
    write_csv(out / f"{name}.csv", summary)
    write_csv(out / f"{name}_runs.csv", records)
    write_csv(out / f"{name}_paired.csv", paired)
    if progress:
        print(text)
    return summary


def table_name(channel: str = "radio_map") -> str:
    """The file name (no suffix) of the experiment's tables for runs trained on ``channel``: ``paper_task`` (radio
    map) or ``paper_task_reality``."""
    return "paper_task" if channel == "radio_map" else "paper_task_reality"


def _training(budget: Budget, channel: str) -> str:
    if channel == "radio_map":
        return f"{budget.task_episodes} training episodes on the radio map"
    return f'{budget.task_long_episodes} training episodes with Rayleigh fading ("reality")'


#: The per-run columns that say which budget a run is of: one value in a merged table (a CSV written before a column
#: existed lacks it)
BUDGET_COLUMNS = ("scenario", "eval_episodes")


def recorded_values(records: pd.DataFrame, column: str) -> list[Any]:
    """:return: the values the runs record in a column of :data:`BUDGET_COLUMNS`, sorted (none where the column is
    missing: a CSV written before it existed)"""
    return sorted(records[column].dropna().unique().tolist(), key=str) if column in records else []


def merge_runs(run_tables: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """
    The per-run records of several output folders of the experiment as one table, e.g. the ``paper_task_runs.csv``
    of a job that ran seeds 0-2 and of one that ran seeds 3 and 4.

    Two budgets of the same training episodes give their runs the same ids: the runs' budget columns
    (:data:`BUDGET_COLUMNS`) and ``configuration`` (their identity less the seed) tell them apart, where the tables
    record them, and such runs are refused rather than merged as one.

    :param run_tables: per-run records (the columns of ``paper_task_runs.csv``)
    :return: one row per run, by preset (:data:`PRESETS` order), algorithm (DT-DPG first), mode (NOMA first), seed
    :raises ValueError: the runs are of several budgets (a column of :data:`BUDGET_COLUMNS` has several values), the
        runs of a group are of several configurations, or a run (group and seed) is in more than one table with
        other results
    """
    merged = pd.concat(run_tables, ignore_index=True)
    for column in BUDGET_COLUMNS:
        values = recorded_values(merged, column)
        if len(values) > 1:
            raise ValueError(
                f"the runs are of several budgets ({column}: {', '.join(map(repr, values))}): merge the runs of one "
                "budget, one table per budget"
            )
    if "configuration" in merged:
        for group, digests in merged.groupby("group", sort=False)["configuration"]:
            found = digests.dropna().unique().tolist()
            if len(found) > 1:
                raise ValueError(
                    f"runs of {group}: several configurations under one id (configuration {', '.join(found)}: their "
                    "identities differ beyond the seed, e.g. another budget, or a room or preset changed between the "
                    "jobs); merge the runs of one configuration"
                )
    key = ["group", "seed"]
    merged = merged.drop_duplicates(subset=[*key, "success_rate", "mqi", "train_success"])
    clashes = merged[merged.duplicated(subset=key, keep=False)]
    if not clashes.empty:
        group, seed = clashes.iloc[0][key]
        raise ValueError(f"run {group} seed {seed}: different results in two tables ({len(clashes)} rows)")
    order = merged["preset"].map({preset: i for i, preset in enumerate(PRESETS)})
    merged = merged.assign(_order=order).sort_values(
        ["_order", "algorithm", "multiple_access", "seed"], ascending=[True, False, True, True], kind="stable"
    )
    return merged.drop(columns="_order").reset_index(drop=True)


def paper_task_tables(
    out: Path,
    budget: Budget,
    specs: Sequence[RunSpec],
    results: dict[str, Any],
    progress: bool = True,
    channel: str = "radio_map",
    incomplete: str | None = None,
) -> pd.DataFrame | None:
    """
    Write ``paper_task.md`` / ``paper_task.csv`` (per preset, algorithm and mode), ``paper_task_runs.csv`` (per run),
    ``paper_task_paired.csv`` (DT-DPG - DDPG by seed) and ``fig_paper_task_success.png`` (the training success
    rate per episode, a rolling mean over 20 episodes) from the finished runs of :func:`paper_task_specs`; for the
    runs trained with Rayleigh fading (``channel="rayleigh"``) the same as ``paper_task_reality*``.

    :param channel: the training channel of ``specs``
    :param incomplete: a line saying which of ``specs`` failed (:meth:`~sb3_dtdpg.experiments.pool.RunReport.incomplete_note`)
    :return: the summary (with the reference planners' rows), or None when no run has finished
    """
    records = _records(out, specs, results)
    if records.empty:
        return None
    summary = write_tables(out, budget, records, progress, channel, incomplete)
    groups: dict[str, list[Path]] = {}
    for spec in specs:
        if results.get(spec.run_id) is not None:
            label = f"{tables.ALGO_LABELS[spec.algo]} {spec.multiple_access.upper()}, {spec.hyperparams}"
            groups.setdefault(label, []).append(out / "tb" / spec.run_id)
    plots.plot_learning_curves(
        groups,
        out / f"fig_{table_name(channel)}_success.png",
        tags=((plots.SUCCESS_TAG, "training episodes reaching the destination"),),
        smooth=20,
        title=f"The paper's task: training success per episode\n({budget.scenario or 'mall'}, {budget.name} budget, "
        f"{'radio-map' if channel == 'radio_map' else 'Rayleigh'} training; dotted: DT-DPG's transfer)",
    )
    return summary
