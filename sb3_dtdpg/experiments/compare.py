"""``sb3-dtdpg compare``: the main job — DT-DPG vs DDPG (and any other algorithm), NOMA and OMA, several seeds.

All runs log under one TensorBoard folder, ``<out>/tb/<algo>_<mode>_s<seed>``, so
``tensorboard --logdir <out>/tb`` shows them side by side. The job then writes ``results.md`` /
``results.csv`` (one row per algorithm and mode, with the planners as reference rows),
``results_runs.csv`` (one row per run), ``learning_curves.png`` and ``trajectories.png``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import pandas as pd

from sb3_dtdpg.experiments.budgets import check_seeds
from sb3_dtdpg.experiments.runs import Budget, RunSpec, get_budget, load_result, output_lock, run_many

__all__ = [
    "CompareJob",
    "compare_job",
    "compare_specs",
    "evaluate_planners",
    "format_room_margins",
    "room_margins",
    "run_compare",
]

#: The reference rows of the tables: label -> (class in :mod:`noma_radiomap.planners`, its keyword arguments).
PLANNERS: dict[str, tuple[str, dict[str, Any]]] = {
    "best planner": ("ReferencePlanner", {}),
    "shortest-path planner": ("ShortestPathPlanner", {"power": "best"}),
    "shortest path, equal power": ("ShortestPathPlanner", {}),
    "random": ("RandomPlanner", {}),
}
#: The planners the learners are reported as a fraction of (:func:`sb3_dtdpg.experiments.tables.add_planner_fractions`).
BEST_PLANNER, SHORTEST_PATH_PLANNER = "best planner", "shortest-path planner"


def compare_specs(
    budget: Budget,
    seeds: int,
    algos: Sequence[str] = ("dtdpg", "ddpg"),
    modes: Sequence[str] = ("noma", "oma"),
    env_id: str = "NomaRadioMap-v0",
    hyperparams: str = "paper",
    observation: str = "goal",
    episodes: int | None = None,
    tag: str = "",
    eval_before_transfer: bool = False,
    channel: str | None = None,
) -> list[RunSpec]:
    """
    :param episodes: training episodes per run (None: the budget's)
    :param tag: run-id suffix of these runs (:attr:`RunSpec.tag`)
    :param eval_before_transfer: also evaluate DT-DPG's network from the end of its first phase
    :param channel: the training channel (:attr:`RunSpec.channel`; None: the env id's, ``radio_map`` but for the
        ``Reality`` ids)
    :return: the runs of a comparison (every algorithm x mode x seed)
    """
    if channel is None:
        import gymnasium as gym

        channel = gym.spec(env_id).kwargs.get("channel", "radio_map")
    return [
        budget.run_spec(
            algo,
            mode,
            seed,
            episodes,
            env_id=env_id,
            tag=tag,
            eval_before_transfer=eval_before_transfer,
            hyperparams=hyperparams,
            observation=observation,
            channel=channel,
        )
        for algo in algos
        for mode in modes
        for seed in range(seeds)
    ]


def evaluate_planners(
    modes: Sequence[str],
    budget: Budget,
    env_id: str = "NomaRadioMap-v0",
    eval_seed: int = 10_000,
    eval_channel: str = "rayleigh",
    names: Sequence[str] = tuple(PLANNERS),
    instances: dict[str, Any] | None = None,
) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """
    Evaluate the non-learning references on the learners' test missions.

    :param names: the planners of :data:`PLANNERS` to evaluate
    :param instances: planner objects by name, reused across modes (and across calls, for the caller's dict): the
        best planner rolls its candidate paths out once per mission (None: a new dict); the random planner is made
        anew for each mode, with its seed
    :return: the table rows and, per mode, the planners' first test trajectory; the best planner's row also has
        ``mqi_bound`` (:func:`mission_bound`) and ``mqi_radio_map``, its MQI on the radio-map channel, where the
        bound holds
    """
    from noma_radiomap import planners
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.experiments.tables import planner_row

    rows, trajectories = [], {}
    env_kwargs = {} if budget.scenario is None else {"scenario": budget.scenario}
    instances = {} if instances is None else instances
    for mode in modes:
        trajectories[mode] = {}
        for name in names:
            cls, kwargs = PLANNERS[name]
            if cls == "RandomPlanner":
                planner = planners.RandomPlanner(seed=eval_seed)
            else:
                if name not in instances:
                    instances[name] = getattr(planners, cls)(**kwargs)
                planner = instances[name]
            result = evaluate(
                planner,
                env_id,
                n_episodes=budget.eval_episodes,
                seed=eval_seed,
                channel=eval_channel,
                multiple_access=mode,
                env_kwargs=env_kwargs,
                return_trajectories=True,
            )
            row = planner_row(name, mode, result)
            if name == BEST_PLANNER:
                # The bound holds on the radio-map channel: the planner's gap to it is measured there too.
                row["mqi_bound"] = mission_bound(env_id, mode, budget.eval_episodes, eval_seed, env_kwargs)
                row["mqi_radio_map"] = (
                    result.mqi_mean
                    if eval_channel == "radio_map"
                    else evaluate(
                        planner,
                        env_id,
                        n_episodes=budget.eval_episodes,
                        seed=eval_seed,
                        channel="radio_map",
                        multiple_access=mode,
                        env_kwargs=env_kwargs,
                    ).mqi_mean
                )
            rows.append(row)
            trajectories[mode][name] = result.trajectories[0]
    return rows, trajectories


def room_margins(
    rayleigh_rows: Sequence[dict[str, Any]],
    budget: Budget,
    env_id: str = "NomaRadioMap-v0",
    instances: dict[str, Any] | None = None,
) -> dict[str, float]:
    """
    The two margins a room is calibrated for (docs/SCENARIOS.md, "mall calibration") on the test missions: what path
    design is worth (``path``: best planner - shortest-path planner, NOMA) and what NOMA is worth (``noma``: the best
    planner's NOMA - its OMA), on the radio-map channel (the planners are evaluated on it here) and with Rayleigh
    fading (from the rows of the table).

    :param rayleigh_rows: the planners' rows of the table (:func:`evaluate_planners`, NOMA and OMA; the best planner's
        with its radio-map MQI, ``mqi_radio_map``)
    :param budget: the budget (its scenario and test missions)
    :param env_id: the env id
    :param instances: the planner objects of the table's evaluation (:func:`evaluate_planners`), to reuse
    :return: ``{"path radio_map", "noma radio_map", "path rayleigh", "noma rayleigh"}``, in MQI
    """
    shortest_rows, _ = evaluate_planners(
        ("noma", "oma"), budget, env_id, eval_channel="radio_map", names=(SHORTEST_PATH_PLANNER,), instances=instances
    )
    best_rows = [
        {**row, "mqi": row["mqi_radio_map"]} for row in rayleigh_rows if row["algorithm"] == BEST_PLANNER
    ]  # evaluated on the radio-map channel with the table, for its gap to the bound
    radio_map_rows = best_rows + shortest_rows
    margins = {}
    for channel, rows in (("radio_map", radio_map_rows), ("rayleigh", rayleigh_rows)):
        mqi = {(row["algorithm"], row["multiple_access"]): float(row["mqi"]) for row in rows}
        path, noma = planner_margins(
            mqi[(BEST_PLANNER, "NOMA")], mqi[(SHORTEST_PATH_PLANNER, "NOMA")], mqi[(BEST_PLANNER, "OMA")]
        )
        margins[f"path {channel}"], margins[f"noma {channel}"] = path, noma
    return margins


def planner_margins(best_noma: float, shortest_noma: float, best_oma: float) -> tuple[float, float]:
    """
    The two margins a room is calibrated for (docs/SCENARIOS.md), from the planners' mean MQIs on one channel.

    :param best_noma: the best planner's MQI in NOMA
    :param shortest_noma: the shortest-path planner's (best power split) in NOMA
    :param best_oma: the best planner's in OMA
    :return: what path design is worth (best - shortest path, NOMA) and what NOMA is worth (the best planner's
        NOMA - its OMA)
    """
    return best_noma - shortest_noma, best_noma - best_oma


def format_room_margins(margins: dict[str, float]) -> str:
    """:return: the line of :func:`room_margins` under the compare table"""
    return (
        f"Room margins on these test missions, radio-map channel / Rayleigh fading: path design (best planner - "
        f"shortest-path planner, NOMA) {margins['path radio_map']:+.1f} / {margins['path rayleigh']:+.1f} MQI, "
        f"NOMA (the best planner's NOMA - OMA) {margins['noma radio_map']:+.1f} / {margins['noma rayleigh']:+.1f} MQI"
    )


def _finished_line(out: Path) -> Any:
    from sb3_dtdpg.experiments.reproduce import finished_line  # reproduce imports this module: import late

    return finished_line(out)


def mission_bound(env_id: str, mode: str, n_episodes: int, eval_seed: int, env_kwargs: dict[str, Any]) -> float:
    """
    The mean over the test missions of :func:`noma_radiomap.planners.mqi_upper_bound` (radio-map channel): no
    policy scores above it there, so ``bound - best planner`` bounds the best planner's optimality gap.

    :param env_id: the env id
    :param mode: ``"noma"`` or ``"oma"``
    :param n_episodes: test missions (episode ``i`` reset with ``eval_seed + i``, as in :func:`evaluate_planners`)
    :param eval_seed: the seed of the first test mission
    :param env_kwargs: extra ``gymnasium.make`` keyword arguments
    :return: the mean bound
    """
    import gymnasium as gym

    from noma_radiomap.planners import mqi_upper_bound

    env = gym.make(env_id, **{**env_kwargs, "channel": "radio_map", "multiple_access": mode})
    try:
        bounds = []
        for episode in range(n_episodes):
            env.reset(seed=eval_seed + episode)
            base = env.unwrapped
            bounds.append(mqi_upper_bound(base, base.positions, base.destinations))
    finally:
        env.close()
    return float(sum(bounds) / len(bounds))


def _check_arguments(algos: Sequence[str], modes: Sequence[str], hyperparams: str, observation: str, seeds: int) -> None:
    """:raises ValueError: naming the first bad argument of :func:`run_compare`, before any run starts"""
    from noma_radiomap.registration import check_observation
    from sb3_dtdpg.baselines import ALGORITHMS, check_hyperparams

    unknown = [a for a in algos if a not in ALGORITHMS]
    if unknown:
        raise ValueError(f"algos: unknown algorithm(s) {unknown}, expected some of {ALGORITHMS}")
    bad_modes = [m for m in modes if m not in ("noma", "oma")]
    if bad_modes:
        raise ValueError(f"modes: expected 'noma' and/or 'oma', got {bad_modes}")
    for algo in algos:
        check_hyperparams(algo, hyperparams)
    check_observation(observation)
    check_seeds(seeds)


def _check_planners_take(budget: Budget, env_id: str) -> None:
    """:raises ValueError: the scenario has more robots than the reference planners take (before any run trains)"""
    from noma_radiomap import load_scenario
    from noma_radiomap.planners import check_planner_robots
    from noma_radiomap.registration import default_scenario

    scenario = budget.scenario or default_scenario(env_id)
    check_planner_robots(load_scenario(scenario).n_robots, f"compare's reference planners on {scenario}")


class CompareJob(NamedTuple):
    """A comparison's runs and its arguments as resolved by :func:`compare_job`."""

    budget: Budget  #: the budget, with the scenario asked for
    specs: list[RunSpec]  #: every algorithm x mode x seed
    seeds: int  #: seeds per configuration
    algos: list[str]  #: the algorithms, each once
    modes: list[str]  #: the multiple-access modes, each once
    observation: str  #: the observation layout


def compare_job(
    budget: str | Budget = "default",
    seeds: int | None = None,
    algos: Sequence[str] = ("dtdpg", "ddpg"),
    modes: Sequence[str] = ("noma", "oma"),
    env_id: str = "NomaRadioMap-v0",
    scenario: str | None = None,
    hyperparams: str = "paper",
    observation: str | None = None,
) -> CompareJob:
    """
    The runs of a comparison, every argument checked before any run starts: what :func:`run_compare` trains,
    ``sb3-dtdpg compare`` checks and the distributed workers share out (:mod:`sb3_dtdpg.experiments.distributed`).

    :param budget: a name of :data:`~sb3_dtdpg.experiments.runs.BUDGETS` or a :class:`Budget`
    :param seeds: seeds per configuration (None: the budget's)
    :param algos: algorithms (a name given twice is one run per seed)
    :param modes: multiple-access modes
    :param env_id: a mission env id
    :param scenario: scenario name or path (None: the budget's)
    :param hyperparams: ``"paper"`` or ``"tuned"``
    :param observation: the observation layout (None: the env id's, :func:`sb3_dtdpg.baselines.default_observation_of`)
    :return: the job, its arguments resolved
    :raises ValueError: naming the first bad argument
    """
    from sb3_dtdpg.baselines import default_observation_of, is_mission_env

    budget = get_budget(budget)
    if scenario is not None:
        budget = dataclasses.replace(budget, scenario=scenario)
    algos, modes = list(dict.fromkeys(algos)), list(dict.fromkeys(modes))
    seeds = budget.seeds if seeds is None else seeds
    if not is_mission_env(env_id):
        raise ValueError(f"env: compare runs on the NomaRadioMap envs, got {env_id}")
    observation = observation or default_observation_of(env_id)
    _check_arguments(algos, modes, hyperparams, observation, seeds)
    _check_planners_take(budget, env_id)
    specs = compare_specs(budget, seeds, algos, modes, env_id, hyperparams, observation)
    return CompareJob(budget, specs, seeds, algos, modes, observation)


def run_compare(
    out: str | Path = "results/compare",
    budget: str | Budget = "default",
    seeds: int | None = None,
    algos: Sequence[str] = ("dtdpg", "ddpg"),
    modes: Sequence[str] = ("noma", "oma"),
    n_workers: int | None = None,
    progress: bool = True,
    env_id: str = "NomaRadioMap-v0",
    scenario: str | None = None,
    hyperparams: str = "paper",
    observation: str | None = None,
) -> pd.DataFrame:
    """
    Train and evaluate every algorithm x mode x seed (finished runs are kept), then write the tables and figures.

    :param out: output folder
    :param budget: a name of :data:`~sb3_dtdpg.experiments.runs.BUDGETS` or a :class:`Budget`
    :param seeds: seeds per configuration (default: the budget's)
    :param algos: algorithms (see :data:`sb3_dtdpg.baselines.ALGORITHMS`)
    :param modes: multiple-access modes
    :param n_workers: parallel processes (default: the number of CPUs)
    :param progress: show progress bars
    :param env_id: the env id
    :param scenario: scenario name or path (default: the budget's, ``mall`` unless ``tiny``)
    :param hyperparams: ``"paper"`` (Table I) or ``"tuned"`` (see :mod:`sb3_dtdpg.baselines`)
    :param observation: ``"goal"`` (the goal-conditioned layout), ``"destinations"`` or ``"paper"`` (Eq. (24);
        docs/MODEL.md, "Observations"); None: the env id's (``goal`` but for the paper task's id)
    :return: the summary table (learners and planners)
    :raises ValueError: on a bad argument, or a budget that cannot train an algorithm (before any run starts)
    :raises OutputBusyError: another job is using ``out``
    :raises RunMismatchError: ``out`` holds a result of another run under one of these run ids (another budget,
        scenario or hyperparameters): use another folder
    :raises RunsFailedError: runs failed; the tables and figures of the runs that finished are written first
    """
    from sb3_dtdpg.experiments import plots, tables

    job = compare_job(budget, seeds, algos, modes, env_id, scenario, hyperparams, observation)
    budget, specs, seeds = job.budget, job.specs, job.seeds
    algos, modes, observation = job.algos, job.modes, job.observation
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with output_lock(out):  # one job per folder: a second one would write the same run folders
        report = run_many(
            specs, out, n_workers=n_workers, progress=progress, on_finish=None if progress else _finished_line(out)
        )
        for run_id, error in report.failed.items():
            print(f"run {run_id} failed: {error}")

        results = {spec.run_id: load_result(out, spec) for spec in specs}
        finished = [r for r in results.values() if r is not None]
        records = tables.run_records(finished)
        summary = tables.summarise(records) if not records.empty else pd.DataFrame()
        planner_instances: dict[str, Any] = {}
        planner_rows, planner_paths = evaluate_planners(modes, budget, env_id, instances=planner_instances)
        summary = pd.concat([summary, pd.DataFrame(planner_rows)], ignore_index=True)
        summary = tables.add_planner_fractions(summary, BEST_PLANNER, SHORTEST_PATH_PLANNER)
        trained = "with Rayleigh fading" if specs and specs[0].channel == "rayleigh" else "on the radio map"
        title = (
            f"DT-DPG vs baselines on {budget.scenario or 'mall'} ({budget.name} budget: {budget.episodes} training episodes "
            f"{trained}, {budget.eval_episodes} Rayleigh test episodes, {seeds} seed{'s' if seeds != 1 else ''}, "
            f"{hyperparams} hyperparameters, {observation} observation)"
        )
        margins = []  # the room's margins need both modes' planners
        if set(modes) == {"noma", "oma"}:
            margins.append(format_room_margins(room_margins(planner_rows, budget, env_id, planner_instances)))
        tables.save_tables(summary, records, out, "results", title, incomplete=report.incomplete_note(), extra_notes=margins)
        tables.print_table(summary, title)
        for line in margins:
            print(line)
        if not records.empty:
            plots.plot_statistics(
                records, out, f"{budget.scenario or 'mall'}, {budget.name} budget ({budget.episodes} episodes)"
            )

        groups: dict[str, list[Path]] = {}
        for spec in specs:
            if results[spec.run_id] is not None:
                groups.setdefault(f"{tables.ALGO_LABELS[spec.algo]} {spec.multiple_access.upper()}", []).append(
                    out / "tb" / spec.run_id
                )
        if groups:
            plots.plot_learning_curves(
                groups,
                out / "learning_curves.png",
                title=f"Learning curves on {budget.scenario or 'mall'}, {budget.name} budget",
                band_note=True,
            )
        panels: dict[str, dict[str, Any]] = {}
        goals: dict[str, Any] = {}
        for mode in modes:
            panel = {}
            for algo in algos:
                first = next(
                    (
                        results[s.run_id]
                        for s in specs
                        if s.algo == algo and s.multiple_access == mode and results[s.run_id] is not None
                    ),
                    None,
                )
                if first is not None and first["eval"]["trajectories"]:
                    panel[f"{tables.ALGO_LABELS[algo]} (seed {first['spec']['seed']})"] = first["eval"]["trajectories"][0]
                    goals[mode.upper()] = plots.episode_destinations(first["eval"]["episodes"][0])
            panel[BEST_PLANNER] = planner_paths[mode][BEST_PLANNER]
            panels[mode.upper()] = panel
        plots.plot_trajectories(
            budget.scenario or "mall",
            panels,
            out / "trajectories.png",
            title=f"Test episode 0 on {budget.scenario or 'mall'} (same mission and fading for every policy)",
            destinations=goals,
        )
        print(  # also without progress bars: where the results went
            f"wrote {out}/results.md, results.csv, results_runs.csv, learning_curves.png, trajectories.png, "
            f"statistics_*.png; TensorBoard: tensorboard --logdir {out}/tb ({report.wall_s:.0f} s for {report.counts()})"
        )
        report.raise_failures(out)
        return summary
