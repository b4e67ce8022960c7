"""``sb3-dtdpg reproduce``: every experiment of the paper's Section V (docs/RESULTS.md), resumable.

Runs (per seed; ``E`` and ``L`` are the budget's ``episodes`` and ``long_episodes``, 500 and 700 in the paper):

- Table II: DT-DPG in NOMA and OMA, trained on the radio map for ``E`` episodes and in "reality"
  (Rayleigh fading) for ``E`` and ``L`` episodes, tested on 20 Rayleigh episodes;
- DDPG vs DT-DPG: plain DDPG in NOMA and OMA, radio map, ``E`` episodes (success rate and MQI);
- the two learning rates (paper Fig. 6): DT-DPG at 1e-3 and 1e-4 (one is the hyperparameter set's own), NOMA and OMA;
- the paper's task (:mod:`sb3_dtdpg.experiments.paper_task`): DDPG vs DT-DPG on ``NomaRadioMapPaper-v0`` with
  Table I and with the tuned set, NOMA and OMA, ``E`` episodes on the radio map (the share of training episodes
  that reach the destination, the paper's central claim), and, when asked for (``paper_task_reality``), the same
  trained in "reality" for ``L`` episodes (in proportion on the smaller budgets).

The first three use one hyperparameter set (``hyperparams``) and observation: ``"paper"`` (Table I) or ``"tuned"``
(the best measured DT-DPG settings, given to DDPG as well; see :mod:`sb3_dtdpg.presets`).

Figures: the power and SINR maps, trajectories NOMA vs OMA and before/after the transfer, reward per
episode in both phases for the two learning rates, MQI per episode (the dip at the transfer) and
DDPG vs DT-DPG. A run whose result file exists is not re-run, so the job can be interrupted and resumed.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from sb3_dtdpg.baselines import base_learning_rate
from sb3_dtdpg.common.files import write_csv, write_text
from sb3_dtdpg.evaluation import mean_ci
from sb3_dtdpg.experiments import plots, tables
from sb3_dtdpg.experiments.budgets import check_seeds
from sb3_dtdpg.experiments.compare import BEST_PLANNER, SHORTEST_PATH_PLANNER, evaluate_planners
from sb3_dtdpg.experiments.paper_task import paper_task_specs, paper_task_tables
from sb3_dtdpg.experiments.runs import Budget, RunReport, RunSpec, get_budget, load_results, output_lock, run_many
from sb3_dtdpg.experiments.storage import result_path
from sb3_dtdpg.presets import PRESETS

__all__ = [
    "DEFAULT_EXPERIMENTS",
    "EXPERIMENTS",
    "LEARNING_RATES",
    "PAPER_TABLE_II",
    "job_specs",
    "other_learning_rate",
    "reproduce_specs",
    "run_reproduce",
]

#: Paper Table II: (MA mode, approach, training episodes) -> MQI over 20 Rayleigh test episodes.
PAPER_TABLE_II: dict[tuple[str, str, str], float] = {
    ("OMA", "radio map", "E"): 879.5,
    ("OMA", "reality", "E"): 868.5,
    ("OMA", "reality", "L"): 876.2,
    ("NOMA", "radio map", "E"): 929.0,
    ("NOMA", "reality", "E"): 919.0,
    ("NOMA", "reality", "L"): 929.0,
}
#: The experiments of :func:`reproduce_specs`, by name.
EXPERIMENTS = ("table_ii", "ddpg_vs_dtdpg", "learning_rates", "paper_task", "paper_task_reality")
#: What ``reproduce`` trains unless told otherwise: all but the paper task's "reality" training, which at the paper's
#: scale takes about 5 CPU hours more, most of it its Table I runs (``--experiments paper_task_reality`` asks for it).
DEFAULT_EXPERIMENTS = EXPERIMENTS[:-1]
#: The paper's two learning rates (Fig. 6).
LEARNING_RATES = (1e-4, 1e-3)


def other_learning_rate(hyperparams: str) -> float:
    """:return: the paper's learning rate that DT-DPG does not have by default under ``hyperparams``"""
    base = base_learning_rate("dtdpg", hyperparams)
    return next(lr for lr in LEARNING_RATES if not math.isclose(lr, base))


def _spec(
    budget: Budget,
    algo: str,
    mode: str,
    seed: int,
    channel: str,
    episodes: int,
    lr: float | None = None,
    hyperparams: str = "paper",
    observation: str = "goal",
) -> RunSpec:
    tag = f"{'radio_map' if channel == 'radio_map' else 'reality'}_{episodes}" + (f"_lr{lr:g}" if lr is not None else "")
    return budget.run_spec(
        algo,
        mode,
        seed,
        episodes,
        channel=channel,
        learning_rate=lr,
        tag=tag,
        hyperparams=hyperparams,
        observation=observation,
    )


def reproduce_specs(
    budget: Budget, seeds: int, hyperparams: str = "paper", observation: str = "goal"
) -> dict[str, list[RunSpec]]:
    """:return: the runs of every experiment, by experiment (a run may serve several experiments)"""
    e, long = budget.episodes, budget.long_episodes
    modes = ("noma", "oma")
    h, o = hyperparams, observation
    table = [
        _spec(budget, "dtdpg", m, s, c, n, hyperparams=h, observation=o)
        for m in modes
        for c, n in (("radio_map", e), ("rayleigh", e), ("rayleigh", long))
        for s in range(seeds)
    ]
    ddpg = [_spec(budget, "ddpg", m, s, "radio_map", e, hyperparams=h, observation=o) for m in modes for s in range(seeds)]
    dtdpg = [_spec(budget, "dtdpg", m, s, "radio_map", e, hyperparams=h, observation=o) for m in modes for s in range(seeds)]
    other = other_learning_rate(h)
    lrs = [
        _spec(budget, "dtdpg", m, s, "radio_map", e, other, hyperparams=h, observation=o) for m in modes for s in range(seeds)
    ]
    return {
        "ddpg_vs_dtdpg": dtdpg + ddpg,
        "table_ii": table,
        "learning_rates": dtdpg + lrs,
        "paper_task": paper_task_specs(budget, seeds, modes),
        "paper_task_reality": paper_task_specs(budget, seeds, modes, channel="rayleigh"),
    }


#: The paper-task experiments and their training channels.
_PAPER_TASK_CHANNELS = {"paper_task": "radio_map", "paper_task_reality": "rayleigh"}


def _paper_task_tables(
    out: Path,
    budget: Budget,
    experiments: dict[str, list[RunSpec]],
    results: dict[str, Any],
    progress: bool,
    report: RunReport,
) -> dict[str, pd.DataFrame]:
    """The tables of the paper-task experiments that have finished runs (:func:`paper_task_tables`)."""
    summaries = {
        name: paper_task_tables(
            out,
            budget,
            experiments[name],
            results,
            progress,
            channel,
            incomplete=report.incomplete_note(s.run_id for s in experiments[name]),
        )
        for name, channel in _PAPER_TASK_CHANNELS.items()
    }
    return {name: summary for name, summary in summaries.items() if summary is not None}


def _approach(spec: dict[str, Any], budget: Budget) -> tuple[str, str]:
    approach = "radio map" if spec["channel"] == "radio_map" else "reality"
    return approach, "E" if spec["episodes"] == budget.episodes else "L"


def _dip(log_dir: Path, window: int = 10) -> dict[str, float]:
    """
    Mean MQI per episode over the ``window`` episodes before the transfer, the ``window`` episodes right
    after it, and the last ``window`` episodes of training (plain means over equal windows: the minimum of
    a noisy curve after the transfer would be biased low).
    """
    from sb3_dtdpg.experiments.plots import episode_curves, transfer_episode

    episode = transfer_episode(log_dir)
    curve = episode_curves(log_dir, ["mission/mqi"]).get("mission/mqi")
    if episode is None or curve is None or curve.empty:
        return {"transfer_episode": math.nan, "before": math.nan, "after": math.nan, "final": math.nan}
    curve = curve.dropna()
    # ``episode`` is the last episode of the destination phase (its row is logged after the transfer, phase 1)
    before = curve[curve.index <= episode].tail(window)
    after = curve[curve.index > episode].head(window)
    return {
        "transfer_episode": episode,
        "before": float(before.mean()) if len(before) else math.nan,
        "after": float(after.mean()) if len(after) else math.nan,
        "final": float(curve.tail(window).mean()),
    }


def _paired_table(
    out: Path,
    budget: Budget,
    finished: list[dict[str, Any]],
    base_lr: float,
    other_lr: float,
    incomplete: str | None = None,
) -> pd.DataFrame | None:
    """
    The paper's claims as paired differences over seeds (``paired.md`` / ``paired.csv``): NOMA - OMA, DT-DPG -
    DDPG, radio-map training for ``E`` episodes - "reality" training for ``E`` and for ``L``, and the two
    learning rates.

    :param incomplete: the line saying which of the table's runs are missing (failed), written under the title;
        the contrasts left without a pair are named there too
    """
    rec = tables.run_records(finished)
    if rec.empty:
        return None
    rec["learning_rate"] = rec["learning_rate"].fillna(base_lr)
    rec["approach"] = [
        f"{'radio map' if t == 'radio_map' else 'reality'} {'E' if n == budget.episodes else 'L'}"
        for t, n in zip(rec["training"], rec["episodes"], strict=True)
    ]
    contrasts = [
        ("multiple_access", "NOMA", "OMA", ("algorithm", "approach", "learning_rate")),
        ("algorithm", "DT-DPG", "DDPG", ("multiple_access", "approach", "learning_rate")),
        ("approach", "radio map E", "reality E", ("algorithm", "multiple_access", "learning_rate")),
        ("approach", "radio map E", "reality L", ("algorithm", "multiple_access", "learning_rate")),
        ("learning_rate", base_lr, other_lr, ("algorithm", "multiple_access", "approach")),
    ]
    parts = [tables.paired_differences(rec, column, a, b, by) for column, a, b, by in contrasts]
    unpaired = [f"{a} - {b}" for (column, a, b, _), part in zip(contrasts, parts, strict=True) if part.empty]
    parts = [p for p in parts if not p.empty]
    if not parts:  # no contrast has both sides (e.g. one algorithm and one mode finished)
        return None
    paired = pd.concat(parts, ignore_index=True)
    columns = ("algorithm", "multiple_access", "approach", "learning_rate")
    notes = ""
    if incomplete:
        notes = f"**{incomplete}; no pair for: {', '.join(unpaired)}.**\n\n" if unpaired else f"**{incomplete}.**\n\n"
    write_text(
        out / "paired.md",
        f"# The paper's claims as paired differences ({budget.name} budget; E = {budget.episodes}, "
        f"L = {budget.long_episodes} episodes)\n\n"
        + notes
        + tables.format_paired_markdown(paired, columns)
        + "\nmean difference ± 95 % CI (t-interval over the per-seed differences); success in percentage points.\n",
    )
    write_csv(out / "paired.csv", paired)
    return paired


def _dip_table(out: Path, experiments: dict[str, list[RunSpec]], results: dict[str, Any]) -> pd.DataFrame | None:
    """MQI before and right after the transfer and at the end, per DT-DPG configuration (mean and CI over seeds;
    ``n``: the seeds whose log was read, ``<column>_n``: those with a value of that column)."""
    dips = []
    for spec in experiments["learning_rates"]:
        if results[spec.run_id] is not None:
            dips.append({"group": spec.group, "seed": spec.seed, **_dip(out / "tb" / spec.run_id)})
    if not dips:
        return None
    rows = []
    for group, part in pd.DataFrame(dips).groupby("group", sort=False):
        row: dict[str, Any] = {"group": group, "n": int(part["final"].notna().sum())}  # seeds whose log was read
        for key in ("transfer_episode", "before", "after", "final"):
            row[key], row[f"{key}_ci"] = mean_ci(part[key].dropna().to_numpy())
            # a run that transfers at its last episode has no "after": a column's own count of seeds
            row[f"{key}_n"] = int(part[key].notna().sum())
        rows.append(row)
    dip = pd.DataFrame(rows)
    write_csv(out / "transfer_dip.csv", dip)
    return dip


def finished_line(out: Path) -> Callable[[str], None]:
    """The ``on_finish`` of :func:`~sb3_dtdpg.experiments.runs.run_many` without progress bars: a line per finished run."""

    def report(run_id: str) -> None:
        print(f"finished {run_id}: {Path(out) / 'runs' / run_id / 'result.json'}", flush=True)

    return report


def _check_arguments(
    seeds: int,
    observation: str,
    experiments: Sequence[str] | None,
    multiple_access: Sequence[str] | None = None,
    paper_task_presets: Sequence[str] | None = None,
) -> None:
    from noma_radiomap.registration import check_observation

    check_seeds(seeds)
    check_observation(observation)
    for name, given, known in (
        ("experiments", experiments, EXPERIMENTS),
        ("multiple_access", multiple_access, ("noma", "oma")),
        ("paper_task_presets", paper_task_presets, PRESETS),
    ):
        if isinstance(given, str):  # a lone name would be taken letter by letter
            raise ValueError(f"{name}: expected a list of names, got the string {given!r}")
        unknown = sorted(set(given or ()) - set(known))
        if unknown:
            raise ValueError(f"{name}: unknown {unknown}, expected some of {list(known)}")


def job_specs(
    budget: Budget,
    seeds: int,
    hyperparams: str = "paper",
    observation: str = "goal",
    experiments: Sequence[str] | None = None,
    multiple_access: Sequence[str] | None = None,
    paper_task_presets: Sequence[str] | None = None,
) -> list[RunSpec]:
    """
    The runs a ``reproduce`` job trains, each once, seed by seed (so that an interrupted job has whole seeds of
    every experiment): the same list on every machine, which the workers of a distributed job share
    (:mod:`sb3_dtdpg.experiments.distributed`).

    :param budget: the budget
    :param seeds: seeds per configuration
    :param hyperparams: the hyperparameter set of the experiments other than the paper task's
    :param observation: the observation of the experiments other than the paper task's
    :param experiments: the runs of these experiments (None: :data:`DEFAULT_EXPERIMENTS`)
    :param multiple_access: the runs of these downlink modes (None: both)
    :param paper_task_presets: the paper-task experiments' runs of these hyperparameter sets only (None: both
        Table I and the tuned set, which their tables compare)
    :return: the runs
    :raises ValueError: an unknown experiment, downlink mode or hyperparameter set
    """
    _check_arguments(seeds, observation, experiments, multiple_access, paper_task_presets)
    by_experiment = reproduce_specs(budget, seeds, hyperparams, observation)
    return _chosen_specs(by_experiment, experiments, multiple_access, paper_task_presets)


def _chosen_specs(
    by_experiment: dict[str, list[RunSpec]],
    experiments: Sequence[str] | None,
    multiple_access: Sequence[str] | None,
    paper_task_presets: Sequence[str] | None,
) -> list[RunSpec]:
    """:func:`job_specs` from the runs of every experiment (:func:`reproduce_specs`), the arguments checked"""
    modes, sets = set(multiple_access or ("noma", "oma")), set(paper_task_presets or PRESETS)
    chosen = [
        spec
        for name in (experiments or DEFAULT_EXPERIMENTS)
        for spec in by_experiment[name]
        if spec.multiple_access in modes and (name not in _PAPER_TASK_CHANNELS or spec.hyperparams in sets)
    ]
    unique = list({spec.run_id: spec for spec in chosen}.values())
    return sorted(unique, key=lambda spec: spec.seed)


def check_finished_runs(out: str | Path, specs: Sequence[RunSpec], job: str, instead: str) -> None:
    """
    A report of a job draws its tables from the finished runs in ``out``: refuse a folder (missing or not) that
    holds none of the job's, before anything is created.

    :param out: the output folder
    :param specs: the job's runs
    :param job: the settings that name the job, for the message
    :param instead: what to do instead, for the message
    :raises ValueError: no run of ``specs`` has a result in ``out``
    """
    if not any(result_path(out, spec).is_file() for spec in specs):
        n_runs = len({spec.run_id for spec in specs})
        raise ValueError(f"{out} holds no finished runs of this job (none of its {n_runs} runs: {job}); {instead}")


def _check_report_only(train: bool, out: Path, budget: Budget, seeds: int, hyperparams: str, observation: str) -> None:
    """:raises ValueError: not ``train`` and ``out`` holds no finished run of the job (:func:`check_finished_runs`)"""
    if not train:
        specs = [spec for group in reproduce_specs(budget, seeds, hyperparams, observation).values() for spec in group]
        job = f"budget {budget.name!r}, {seeds} seeds, hyperparams {hyperparams!r}, observation {observation!r}"
        check_finished_runs(out, specs, job, "train them first (train=True)")


def run_reproduce(
    out: str | Path = "results/reproduce",
    budget: str | Budget = "tiny",
    seeds: int | None = None,
    n_workers: int | None = None,
    progress: bool = True,
    train: bool = True,
    hyperparams: str = "paper",
    observation: str = "goal",
    experiments: Sequence[str] | None = None,
    multiple_access: Sequence[str] | None = None,
    paper_task_presets: Sequence[str] | None = None,
) -> dict[str, pd.DataFrame]:
    """
    Run (or resume) every experiment and write its tables (Markdown + CSV) and figures under ``out``.

    :param out: output folder
    :param budget: a budget name or :class:`~sb3_dtdpg.experiments.runs.Budget` (default ``"tiny"``: the whole
        pipeline in minutes; ``"paper"`` is the paper's scale: on 2 cores about 45 minutes for the first three
        experiments and about 5 hours more for the paper task, whose failing episodes last 1000 steps)
    :param seeds: seeds per configuration (default: the budget's)
    :param n_workers: parallel processes (default: the number of CPUs)
    :param progress: progress bars and printed tables
    :param train: run the unfinished runs; False only re-draws the tables and figures from the finished ones
    :param hyperparams: ``"paper"`` (Table I) or ``"tuned"`` (see :mod:`sb3_dtdpg.baselines`)
    :param observation: ``"goal"`` (the goal-conditioned layout, the default), ``"destinations"`` or ``"paper"`` (Eq. (24))
    :param experiments: train only the runs of these experiments (names of :data:`EXPERIMENTS`; None:
        :data:`DEFAULT_EXPERIMENTS`, all but ``paper_task_reality``); the tables and figures are drawn from every
        finished run either way
    :param multiple_access: train only the runs of these downlink modes (``"noma"``, ``"oma"``; None: both)
    :param paper_task_presets: the paper-task experiments train only their runs of these hyperparameter sets
        (``"paper"``, ``"tuned"``; None: both, which their tables compare)
    :return: the tables, by name
    :raises ValueError: on a bad argument, a budget that cannot train a run (before any run starts), or, with
        ``train=False``, an ``out`` that holds no finished run of this job (nothing is created)
    :raises OutputBusyError: another job is using ``out``
    :raises RunMismatchError: ``out`` holds a result of another run under one of these run ids (another budget,
        scenario or hyperparameters): use another folder
    :raises RunsFailedError: runs failed; the tables and figures of the runs that finished are written first
    """

    budget = get_budget(budget)
    seeds = budget.seeds if seeds is None else seeds
    _check_arguments(seeds, observation, experiments, multiple_access, paper_task_presets)
    out = Path(out)
    _check_report_only(train, out, budget, seeds, hyperparams, observation)
    out.mkdir(parents=True, exist_ok=True)
    with output_lock(out):  # one job per folder: a second one would write the same run folders
        base_lr = base_learning_rate("dtdpg", hyperparams)  # checks the set first
        by_experiment = reproduce_specs(budget, seeds, hyperparams, observation)
        wanted = _chosen_specs(by_experiment, experiments, multiple_access, paper_task_presets)
        unique = list({spec.run_id: spec for specs in by_experiment.values() for spec in specs}.values())
        # every stored run the tables will read is checked before anything trains, not only those trained now
        results = load_results(out, unique)
        report = RunReport()
        if train:
            report = run_many(
                wanted,
                out,
                n_workers=n_workers,
                progress=progress,
                on_finish=None if progress else finished_line(out),
            )
            for run_id, error in report.failed.items():
                print(f"run {run_id} failed: {error}")
            results = load_results(out, unique)
        if not train:  # the tables say which runs are missing
            report = RunReport.of_stored(results)

        def incomplete(name: str) -> str | None:
            return report.incomplete_note(s.run_id for s in by_experiment[name])

        def records(name: str) -> pd.DataFrame:
            return tables.run_records([results[s.run_id] for s in by_experiment[name] if results[s.run_id] is not None])

        out_tables: dict[str, pd.DataFrame] = {}
        # The planners on the test missions, evaluated once for every table that compares with them
        planners = functools.cache(lambda: pd.DataFrame(evaluate_planners(("noma", "oma"), budget)[0]))
        # Table II.
        rec = records("table_ii")
        if not rec.empty:
            summary = tables.summarise(rec, by=("multiple_access", "training", "episodes"))
            summary["approach"] = ["radio map" if t == "radio_map" else "reality" for t in summary["training"]]
            summary["paper_mqi"] = [
                PAPER_TABLE_II.get((m, a, "E" if n == budget.episodes else "L"), math.nan)
                for m, a, n in zip(summary["multiple_access"], summary["approach"], summary["episodes"], strict=False)
            ]
            summary = summary.sort_values(["multiple_access", "training", "episodes"], ascending=[False, True, True])
            summary = tables.add_planner_fractions(summary, BEST_PLANNER, SHORTEST_PATH_PLANNER, planners())
            tables.save_tables(
                summary,
                rec,
                out,
                "table_ii",
                f"Table II: DT-DPG test MQI ({budget.name} budget, {hyperparams} hyperparameters, {observation} observation)",
                columns=("multiple_access", "approach", "episodes"),
                incomplete=incomplete("table_ii"),
            )
            out_tables["table_ii"] = summary
            if progress:
                tables.print_table(summary, "Table II (DT-DPG)", columns=("multiple_access", "approach", "episodes"))
        # DDPG vs DT-DPG.
        rec = records("ddpg_vs_dtdpg")
        if not rec.empty:
            summary = tables.summarise(rec)
            summary = pd.concat([summary, planners()], ignore_index=True)
            summary = tables.add_planner_fractions(summary, BEST_PLANNER, SHORTEST_PATH_PLANNER)
            title = (
                f"DDPG vs DT-DPG ({budget.name} budget, {hyperparams} hyperparameters, {observation} observation, "
                "radio-map training)"
            )
            tables.save_tables(summary, rec, out, "ddpg_vs_dtdpg", title, incomplete=incomplete("ddpg_vs_dtdpg"))
            plots.plot_statistics(
                rec, out, f"DDPG vs DT-DPG, {budget.scenario or 'mall'}, {budget.name} budget", prefix="ddpg_vs_dtdpg_"
            )
            out_tables["ddpg_vs_dtdpg"] = summary
            if progress:
                tables.print_table(summary, "DDPG vs DT-DPG")
        # Learning rates.
        rec = records("learning_rates")
        if not rec.empty:
            rec["learning_rate"] = rec["learning_rate"].fillna(base_lr)
            summary = tables.summarise(rec, by=("multiple_access", "learning_rate"))
            summary = tables.add_planner_fractions(summary, BEST_PLANNER, SHORTEST_PATH_PLANNER, planners())
            tables.save_tables(
                summary,
                rec,
                out,
                "learning_rates",
                f"DT-DPG with two learning rates ({budget.name} budget, {hyperparams} hyperparameters, "
                f"{observation} observation)",
                columns=("multiple_access", "learning_rate"),
                incomplete=incomplete("learning_rates"),
            )
            out_tables["learning_rates"] = summary
            if progress:
                tables.print_table(summary, "Learning rates (DT-DPG)", columns=("multiple_access", "learning_rate"))
        out_tables.update(_paper_task_tables(out, budget, by_experiment, results, progress, report))
        # paired in their own tables
        task_runs = {spec.run_id for name in _PAPER_TASK_CHANNELS for spec in by_experiment[name]}
        paired = _paired_table(
            out,
            budget,
            [r for run_id, r in results.items() if r is not None and run_id not in task_runs],
            base_lr,
            other_learning_rate(hyperparams),
            report.incomplete_note(run_id for run_id in results if run_id not in task_runs),
        )
        if paired is not None:
            out_tables["paired"] = paired
            if progress:
                print(tables.format_paired_markdown(paired, ("algorithm", "multiple_access", "approach", "learning_rate")))
        dip = _dip_table(out, by_experiment, results)
        if dip is not None:
            out_tables["transfer_dip"] = dip
        _figures(out, budget, by_experiment, results, base_lr)
        counts = _counts({spec.run_id for spec in wanted}, results, report)
        print(
            f"reproduce: {counts}; tables (.md, .csv) and figures (.png) in {out}/, "
            f"run folders in {out}/runs/, TensorBoard: tensorboard --logdir {out}/tb"
        )
        report.raise_failures(out)
        return out_tables


def _counts(wanted: set[str], results: dict[str, Any], report: RunReport) -> str:
    """
    :return: e.g. ``"20 of 20 runs finished (of all experiments' 130 runs, 20); 2 resumed from their checkpoints,
        1 failed"``
    """
    finished = sum(results[run_id] is not None for run_id in wanted)
    counts = f"{finished} of {len(wanted)} runs finished"
    if len(wanted) < len(results):
        counts += f" (of all experiments' {len(results)} runs, {sum(result is not None for result in results.values())})"
    if report.resumed:
        counts += f"; {report.resumed_count()}"
    if report.failed:
        counts += f", {len(report.failed)} failed"
    return counts


def _figures(
    out: Path, budget: Budget, experiments: dict[str, list[RunSpec]], results: dict[str, Any], base_lr: float
) -> None:
    from noma_radiomap import RadioMap, load_scenario

    scenario = load_scenario(budget.scenario or "mall")
    plots.save_and_close(RadioMap.for_scenario(scenario).plot_maps(), out / "fig_maps.png")
    where = f"{scenario.name}, {budget.name} budget: {budget.episodes} episodes"  # every title names both

    def dirs(name: str, **match: Any) -> dict[str, list[Path]]:
        groups: dict[str, list[Path]] = {}
        for spec in experiments[name]:
            if results[spec.run_id] is not None and all(getattr(spec, k) == v for k, v in match.items()):
                label = f"{tables.ALGO_LABELS[spec.algo]} {spec.multiple_access.upper()}"
                label += f" lr={spec.learning_rate or base_lr:g}" if name == "learning_rates" else ""
                groups.setdefault(label, []).append(out / "tb" / spec.run_id)
        return groups

    if groups := dirs("learning_rates"):
        for file, tag, title in (
            (
                "fig_reward_learning_rates.png",
                (plots.RETURN_TAG, "reward per episode (phase reward)"),
                f"DT-DPG reward per episode, two learning rates\n({where}; dotted: transfer)",
            ),
            (
                "fig_mqi_per_episode.png",
                ("mission/mqi", "MQI per episode"),
                f"DT-DPG MQI per episode\n({where}; dotted: transfer to MQI training)",
            ),
        ):
            plots.plot_learning_curves(groups, out / file, tags=(tag,), smooth=5, title=title)
    if groups := dirs("ddpg_vs_dtdpg"):
        plots.plot_learning_curves(
            groups, out / "fig_ddpg_vs_dtdpg.png", title=f"DDPG vs DT-DPG (radio-map training; {where})"
        )
    first, panel_of = {}, {}  # per mode, the first finished DT-DPG run, named with its seed (a failed seed: another)
    for spec in experiments["ddpg_vs_dtdpg"]:
        result = results[spec.run_id]
        if spec.algo == "dtdpg" and result is not None and spec.multiple_access not in first:
            first[spec.multiple_access] = result
            panel_of[spec.multiple_access] = f"{spec.multiple_access.upper()}, seed {spec.seed}"
    panels = {
        panel_of[mode]: {"DT-DPG": r["eval"]["trajectories"][0]} for mode, r in first.items() if r["eval"]["trajectories"]
    }
    goals = {
        panel_of[mode]: plots.episode_destinations(r["eval"]["episodes"][0]) if r["eval"]["episodes"] else None
        for mode, r in first.items()
    }
    if panels:
        plots.plot_trajectories(
            scenario,
            panels,
            out / "fig_trajectories_noma_oma.png",
            title=f"DT-DPG trajectories, NOMA vs OMA (test episode 0; {where})",
            destinations=goals,
        )
    transfer = {}
    for mode, result in first.items():
        if "before_transfer" in result and result["before_transfer"]["trajectories"]:
            transfer[panel_of[mode]] = {
                "before transfer": result["before_transfer"]["trajectories"][0],
                "after transfer": result["eval"]["trajectories"][0],
            }
    if transfer:
        plots.plot_trajectories(
            scenario,
            transfer,
            out / "fig_trajectories_transfer.png",
            title=f"DT-DPG trajectories before/after the transfer (test episode 0; {where})",
            destinations=goals,
        )
