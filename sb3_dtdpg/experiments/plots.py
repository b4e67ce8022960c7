"""Figures of the experiments: learning curves read back from TensorBoard, trajectories on the SINR map.

Learning curves come from the runs' TensorBoard event files (``tbparse``), i.e. from exactly what
``tensorboard --logdir <out>/tb`` shows, so a figure can always be re-drawn from the logs alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sb3_dtdpg.common.files import save_figure
from sb3_dtdpg.experiments.aggregate import (
    iqm,
    performance_profile,
    pointwise_bootstrap_ci,
    probability_of_improvement,
    stratified_bootstrap_ci,
)

__all__ = [
    "episode_curves",
    "episode_destinations",
    "plot_learning_curves",
    "plot_statistics",
    "plot_trajectories",
    "read_scalars",
    "rolling_curve",
    "transfer_episode",
]

#: The episode count logged with every dump (by :class:`sb3_dtdpg.experiments.runs.EpisodeReturnLogger`).
EPISODES_TAG = "episode/number"
#: Per-episode success (1: all robots arrived), logged by :class:`sb3_dtdpg.MissionLoggerCallback`.
SUCCESS_TAG = "mission/success"
_LOGGED_SUCCESS_RATE = "mission/success_rate"
_PHASE_TAG = "curriculum/phase"
#: The training return on the phase's own reward: its scale changes at a transfer (MQI and success do not)
RETURN_TAG = "episode/return"


#: Policy colours on the SINR map: none is the outage red, the obstacles' white or the interferers' orange.
_POLICY_COLOURS = ("#00e5ff", "#ff66ff", "#ffd700", "#7CFC00", "#1e90ff", "#ff1493")
_ROBOT_STYLES = ("-", "--", ":", "-.")
#: Learning-curve styles: colour, line style and marker all differ, so a series under another still shows.
_SERIES_STYLES = ("-", "--", "-.", ":")
_SERIES_MARKERS = ("o", "s", "^", "D", "v", "P")


def read_scalars(log_dir: str | Path) -> pd.DataFrame:
    """
    All scalars of one run's TensorBoard folder, one column per tag, indexed by the step.

    :param log_dir: the run's TensorBoard folder (``<out>/tb/<run_id>``)
    :return: a DataFrame (empty when there are no events)
    """
    from tbparse import SummaryReader

    if not Path(log_dir).is_dir():
        return pd.DataFrame()
    scalars = SummaryReader(str(log_dir)).scalars
    if scalars.empty:
        return pd.DataFrame()
    return scalars.pivot_table(index="step", columns="tag", values="value", aggfunc="last").sort_index()


def episode_curves(log_dir: str | Path, tags: Sequence[str]) -> pd.DataFrame:
    """
    Scalars of one run against the episode count (the paper's x-axis).

    :param log_dir: the run's TensorBoard folder
    :param tags: the scalar tags wanted (e.g. ``"mission/mqi"``)
    :return: a DataFrame indexed by episode with one column per tag present
    """
    frame = read_scalars(log_dir)
    if frame.empty or EPISODES_TAG not in frame:
        return pd.DataFrame(columns=list(tags))
    frame = frame.dropna(subset=[EPISODES_TAG])
    present = [tag for tag in tags if tag in frame]
    return frame.set_index(EPISODES_TAG)[present].groupby(level=0).last()


def transfer_episode(log_dir: str | Path) -> float | None:
    """
    The episode at which DT-DPG's curriculum entered its second phase (``curriculum/phase`` became 1).

    :param log_dir: the run's TensorBoard folder
    :return: the episode count, or None when the run never transferred (or is not DT-DPG)
    """
    return _transfer(episode_curves(log_dir, [_PHASE_TAG]))


def _transfer(curves: pd.DataFrame) -> float | None:
    if _PHASE_TAG not in curves:
        return None
    later = curves.index[curves[_PHASE_TAG].to_numpy() >= 1]
    return float(later[0]) if len(later) else None


def rolling_curve(log_dir: str | Path, tag: str, window: int) -> pd.Series:
    """
    One run's curve as a learning-curve panel shows it: the per-episode values of ``tag`` and their plain
    rolling mean over the last ``window`` episodes (fewer at the start; for the return, :data:`RETURN_TAG`, also
    after a curriculum transfer, where the reward changes and the window restarts). For the success panel
    (:data:`SUCCESS_TAG`, 1 when all robots arrived) this is the share of successful episodes in the window:
    the test table's success rate, on training episodes. A run logged before ``mission/success`` existed
    falls back to ``mission/success_rate`` as logged (already a rolling rate, so it is not smoothed again).

    :param log_dir: the run's TensorBoard folder
    :param tag: the scalar tag
    :param window: rolling window in episodes (1: no smoothing)
    :return: the curve indexed by the training episode (empty when the tag is absent)
    """
    return _rolling(episode_curves(log_dir, list(dict.fromkeys([tag, _LOGGED_SUCCESS_RATE, _PHASE_TAG]))), tag, window)[0]


def _rolling(curves: pd.DataFrame, tag: str, window: int) -> tuple[pd.Series, bool]:
    """:func:`rolling_curve` on a run's :func:`episode_curves`; also says whether it is a rate as logged."""
    if window < 1:
        raise ValueError(f"window must be a positive number of episodes, got {window!r}")
    if tag != _LOGGED_SUCCESS_RATE and tag in curves and curves[tag].notna().any():
        values = curves[tag].dropna()
        if tag != RETURN_TAG or _PHASE_TAG not in curves or curves[_PHASE_TAG].isna().all():
            return values.rolling(window, min_periods=1).mean(), False
        # The window restarts at a transfer: a mean over both phases would belong to neither (another reward). The
        # phase logged with an episode is the one after it (the transfer episode logs the new phase): shift by one.
        logged = curves[_PHASE_TAG].ffill().bfill()
        played = logged.shift(1).fillna(logged.iloc[0]).reindex(values.index)
        return values.groupby(played.to_numpy()).transform(lambda v: v.rolling(window, min_periods=1).mean()), False
    if tag in (SUCCESS_TAG, _LOGGED_SUCCESS_RATE) and _LOGGED_SUCCESS_RATE in curves:
        return curves[_LOGGED_SUCCESS_RATE].dropna(), True
    return pd.Series(dtype=float), False


def _mean_band(curves: Sequence[pd.Series], n_points: int = 200) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean and 95 % bootstrap CI across runs, after interpolating every run onto a common episode grid."""
    curves = [c.dropna() for c in curves if len(c.dropna())]
    end = min(float(c.index.max()) for c in curves)
    grid = np.linspace(min(float(c.index.min()) for c in curves), end, n_points)
    values = np.stack([np.interp(grid, c.index.to_numpy(dtype=float), c.to_numpy(dtype=float)) for c in curves])
    low, high = pointwise_bootstrap_ci(values)
    return grid, values.mean(axis=0), low, high


def plot_learning_curves(
    groups: Mapping[str, Sequence[str | Path]],
    path: str | Path,
    tags: Sequence[tuple[str, str]] = (("mission/mqi", "MQI"), (SUCCESS_TAG, "success rate")),
    smooth: int = 10,
    title: str | None = None,
    band_note: bool = False,
) -> Any:
    """
    Learning curves: for each group (e.g. ``DT-DPG NOMA``), the mean over its runs (seeds) and a 95 %
    percentile-bootstrap CI band over the runs, against the training episode; DT-DPG's transfer episodes
    are marked by dotted lines. Each run's curve is the plain rolling mean of its per-episode values over
    ``smooth`` episodes (:func:`rolling_curve`), and the y label says so. A group of one run has no band; where
    no group has two, the legend has no CI entry. A group's mean ends where its shortest run does (a run
    interrupted, or of another budget), and its legend label then says to which episode.

    :param groups: group label -> the TensorBoard folders of its runs
    :param path: where to save the PNG
    :param tags: ``(tag, axis label)`` pairs, one panel each
    :param smooth: rolling-mean window (episodes) of each run's curve
    :param title: figure title
    :param band_note: end the title with what the bands are: "(mean and 95 % CI over seeds)", or "(one seed per
        curve, no CI)" where no group has two runs
    :return: the figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, len(tags), figsize=(6.0 * len(tags), 4.6), squeeze=False, layout="constrained")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    transfers = banded = False
    as_logged: set[str] = set()
    wanted = list(dict.fromkeys([*(tag for tag, _ in tags), _LOGGED_SUCCESS_RATE, _PHASE_TAG]))
    for k, (label, dirs) in enumerate(groups.items()):
        colour = colours[k % len(colours)]
        runs = [episode_curves(d, wanted) for d in dirs]  # each event file is read once
        for ax, (tag, _) in zip(axes[0], tags, strict=False):
            curves = [_rolling(run, tag, smooth) for run in runs]
            series = [curve for curve, _ in curves if len(curve)]
            if not series:
                continue
            if any(logged for curve, logged in curves if len(curve)):
                as_logged.add(tag)
            x, mean, low, high = _mean_band(series)
            longest = max(float(curve.dropna().index.max()) for curve in series)
            # the mean is over every run, so it ends where the shortest one does: the label says where, if sooner
            cut = f", to episode {x[-1]:.0f} of {longest:.0f}" if x[-1] < longest else ""
            style = {"ls": _SERIES_STYLES[k % len(_SERIES_STYLES)], "marker": _SERIES_MARKERS[k % len(_SERIES_MARKERS)]}
            markevery = (k * max(len(x) // 40, 1), max(len(x) // 10, 1))  # staggered: markers of equal curves differ
            ax.plot(
                x,
                mean,
                color=colour,
                lw=1.6,
                ms=5,
                markevery=markevery,
                **style,
                label=f"{label} ({_count(len(series), 'seed')}{cut})",
            )
            if len(series) > 1:
                ax.fill_between(x, low, high, color=colour, alpha=0.2, lw=0)
                banded = True
            for episode in filter(None, (_transfer(run) for run in runs)):
                ax.axvline(episode, color=colour, ls=":", lw=0.8)
                transfers = True
    for ax, (tag, ylabel) in zip(axes[0], tags, strict=False):
        ax.set_xlabel("training episode")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        if tag in as_logged:
            window = "as logged: MissionLoggerCallback's stats_window_size"
        elif smooth > 1:
            window = f"rolling mean over the last {smooth} training episodes"
        else:
            window = "per training episode"
        ax.set_ylabel(f"{ylabel}\n({window})", fontsize=9)
        if tag in (SUCCESS_TAG, _LOGGED_SUCCESS_RATE):
            ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    if handles:
        if banded:
            handles.append(Line2D([], [], color="0.3", lw=6, alpha=0.25))
            labels.append("95 % bootstrap CI over seeds")
        if transfers:
            handles.append(Line2D([], [], color="0.3", ls=":", lw=0.8))
            labels.append("transfer to the second phase (DT-DPG)")
        columns = 3 if len(tags) > 1 else 2  # one 6-inch panel holds two legend columns, not three
        fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), columns), fontsize=8, frameon=False)
    if title and band_note:
        title += " (mean and 95 % CI over seeds)" if banded else " (one seed per curve, no CI)"
    return _save(fig, path, title)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def episode_destinations(record: Mapping[str, Any]) -> np.ndarray | None:
    """:return: the destinations (U, 2) stored in an evaluation episode record, or None"""
    points, u = [], 0
    while f"destination_x_{u}" in record:
        points.append((record[f"destination_x_{u}"], record[f"destination_y_{u}"]))
        u += 1
    return np.array(points) if points else None


def plot_trajectories(
    scenario: Any,
    panels: Mapping[str, Mapping[str, np.ndarray]],
    path: str | Path,
    title: str | None = None,
    destinations: Mapping[str, np.ndarray | None] | None = None,
) -> Any:
    """
    Trajectories on the SINR map, one panel per key of ``panels`` (e.g. NOMA / OMA): one colour per
    policy, one line style per robot (robot 0 solid, robot 1 dashed, ...); starts are circles, end points
    squares, destinations white crosses. One legend below the panels explains every colour, line style
    and marker, the map's included.

    :param scenario: the scenario (name, path or :class:`noma_radiomap.Scenario`)
    :param panels: panel title -> (label -> trajectory of shape (steps + 1, U, 2))
    :param path: where to save the PNG
    :param title: figure title
    :param destinations: panel title -> the robots' destinations (U, 2)
    :return: the figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from noma_radiomap import RadioMap, load_scenario

    scenario = load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario
    radio_map = RadioMap.for_scenario(scenario)
    room = scenario.room
    width = 7.0 * room.width / max(room.width, room.depth) + 1.5
    height = 0.8 * width * room.depth / room.width + 1.8
    fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), height), layout="constrained")
    axes = np.atleast_1d(axes)
    policies: dict[str, str] = {}
    n_robots = 0
    for ax, (panel, trajectories) in zip(axes, panels.items(), strict=False):
        radio_map.plot(ax=ax, kind="sinr", colorbar=True, legend=False)
        _mission_regions(ax, scenario)
        goals = None if destinations is None else destinations.get(panel)
        if goals is not None:
            ax.plot(*np.asarray(goals, dtype=float).T, marker="X", ms=11, color="white", mec="black", ls="none")
        for label, trajectory in trajectories.items():
            colour = policies.setdefault(label, _POLICY_COLOURS[len(policies) % len(_POLICY_COLOURS)])
            trajectory = np.asarray(trajectory, dtype=float)
            n_robots = max(n_robots, trajectory.shape[1])
            for u in range(trajectory.shape[1]):
                style = _ROBOT_STYLES[u % len(_ROBOT_STYLES)]
                ax.plot(*trajectory[:, u].T, color=colour, lw=1.6, ls=style)
                ax.plot(*trajectory[0, u], marker="o", ms=5, color=colour, mec="black")
                ax.plot(*trajectory[-1, u], marker="s", ms=5, color=colour, mec="black")
        ax.set_title(panel)
    map_handles, map_labels = axes[0].get_legend_handles_labels()
    keys = [Line2D([], [], color=c, lw=2.5, label=label) for label, c in policies.items()]
    keys += [
        Line2D([], [], color="0.4", lw=1.6, ls=_ROBOT_STYLES[u % len(_ROBOT_STYLES)], label=f"robot {u}")
        for u in range(n_robots)
    ]
    keys += [
        Line2D([], [], ls="none", marker="o", ms=5, color="0.6", mec="black", label="start"),
        Line2D([], [], ls="none", marker="s", ms=5, color="0.6", mec="black", label="end of the episode"),
    ]
    if destinations is not None and any(g is not None for g in destinations.values()):
        keys.append(
            Line2D(
                [],
                [],
                ls="none",
                marker="X",
                ms=11,
                color="white",
                mec="black",
                label=f"destination (reached within {scenario.robot.arrival_radius:g} m)",
            )
        )
    keys += [
        Line2D([], [], ls="--", lw=1.2, color="0.4", label="start region (scenario; white on the map)"),
        Line2D([], [], ls="none", marker="x", ms=6, color="0.4", label="candidate destinations (scenario; white)"),
    ]
    handles = keys + map_handles
    fig.legend(
        handles, [h.get_label() for h in keys] + map_labels, loc="outside lower center", ncol=4, fontsize=8, frameon=False
    )
    return _save(fig, path, title)


def _mission_regions(ax: Any, scenario: Any) -> None:
    """Each robot's start region (dashed rectangle, labelled with the robot) and candidate destinations (crosses)."""
    from matplotlib.patches import Rectangle

    for u, mission in enumerate(scenario.robots):
        x0, y0, x1, y1 = mission.start
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", lw=1.2, ec="white", zorder=4))
        ax.text(x0, y1, f" {u}", color="white", fontsize=7, va="bottom", zorder=4)
        candidates = np.asarray(mission.destinations, dtype=float).reshape(-1, 2)
        ax.plot(candidates[:, 0], candidates[:, 1], ls="none", marker="x", ms=6, color="white", zorder=4)


def _save(fig: Any, path: str | Path, title: str | None) -> Any:
    """Add the title, write the figure to ``path`` and release it; return the figure."""
    if title:
        fig.suptitle(title)
    return save_and_close(fig, path)


def save_and_close(fig: Any, path: str | Path, dpi: int = 120) -> Any:
    """
    Write a figure atomically (:func:`sb3_dtdpg.common.files.save_figure`) and release its memory.

    :param fig: the figure
    :param path: the file (format by extension)
    :param dpi: its resolution
    :return: the figure
    """
    import matplotlib.pyplot as plt

    save_figure(fig, path, dpi=dpi)
    plt.close(fig)
    return fig


def plot_statistics(
    records: pd.DataFrame, out: str | Path, title: str, reference: str = "DT-DPG", prefix: str = ""
) -> list[Path]:
    """
    The three few-seed statistics figures of Agarwal et al. (NeurIPS 2021), over the runs' test MQI as a share of
    the scenario's ``t_total`` (:mod:`sb3_dtdpg.experiments.aggregate`):

    - ``statistics_iqm.png``: per configuration, the IQM of the runs' scores with its 95 % stratified-bootstrap CI;
    - ``statistics_profiles.png``: performance profiles, the share of runs above each score, with 95 % CIs;
    - ``statistics_improvement.png``: per mode, the probability that a ``reference`` run beats a run of each other
      algorithm, with its 95 % bootstrap CI (0.5: no difference).

    Every statistic of a configuration uses the same runs: those with a finite score. The labels give their
    number (``4 of 5 runs`` where a run has none), the improvement figure's for both sides, and the axes name a CI
    only where some configuration has the two runs it needs. A run whose ``t_total`` is unknown (``mqi_scale``
    ``nan`` or not positive) is left out rather than drawn on another scale, and the figures' titles say how many
    were. Records without an ``mqi_scale`` column are drawn as raw MQIs, and the axes say so.

    :param records: :func:`sb3_dtdpg.experiments.tables.run_records` (columns ``algorithm``, ``multiple_access``,
        ``mqi``, ``mqi_scale``)
    :param out: output folder
    :param title: the figures' title (name the scenario and the budget)
    :param reference: the algorithm label compared with the others in the improvement figure
    :param prefix: the start of the file names (``reproduce`` names its figures after its experiment, so that a
        ``compare`` in the same folder keeps its own)
    :return: the written files
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    if "mqi_scale" in records:
        scale = records["mqi_scale"].astype(float)
        known = scale.gt(0) & np.isfinite(scale)
        data, score_name = records[known].assign(score=records["mqi"] / scale), "test MQI / t_total"
        if unscaled := int((~known).sum()):
            title = f"{title}\n({_count(unscaled, 'run')} left out: t_total of the scenario unknown)"
    else:
        data, score_name = records.assign(score=records["mqi"].astype(float)), "test MQI"
    runs: dict[tuple[str, str], tuple[np.ndarray, int]] = {}  # (algorithm, mode) -> (finite scores, runs)
    for (algo, mode), group in data.groupby(["algorithm", "multiple_access"], sort=False):
        scores = group["score"].to_numpy(dtype=float)
        runs[(algo, mode)] = (scores[np.isfinite(scores)], len(scores))
    groups = {f"{algo} {mode}": scores for (algo, mode), (scores, _) in runs.items()}
    counts = {f"{algo} {mode}": _used(scores.size, n) for (algo, mode), (scores, n) in runs.items()}
    complete = {f"{algo} {mode}": scores.size == n for (algo, mode), (scores, n) in runs.items()}
    any_ci = any(scores.size > 1 for scores in groups.values())
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    written = []

    fig, ax = plt.subplots(figsize=(7.0, 0.6 * len(groups) + 1.6), layout="constrained")
    for k, scores in enumerate(groups.values()):
        low, high = stratified_bootstrap_ci(scores)
        ax.plot([iqm(scores)], [k], "o", color=colours[k % len(colours)], ms=7)
        if np.isfinite(low):
            ax.plot([low, high], [k, k], "-", color=colours[k % len(colours)], lw=5, alpha=0.5)
    ax.set_yticks(range(len(groups)), [f"{label} ({counts[label]})" for label in groups])
    ax.set_xlabel(f"IQM of the {score_name}" + (" (95 % stratified-bootstrap CI)" if any_ci else ""))
    ax.grid(alpha=0.3, axis="x")
    written.append(out / f"{prefix}statistics_iqm.png")
    _save(fig, written[-1], title)

    fig, ax = plt.subplots(figsize=(7.0, 4.6), layout="constrained")
    all_scores = np.concatenate([np.empty(0), *groups.values()])
    if all_scores.size:
        low_score, high_score = float(all_scores.min()), float(all_scores.max())
        margin = max(0.1 * (high_score - low_score), 0.005)  # the range the runs span: where the profiles differ
        taus = np.linspace(low_score - margin, high_score + margin, 201)
        for k, (label, scores) in enumerate(groups.items()):
            share, low, high = performance_profile(scores, taus)
            colour = colours[k % len(colours)]
            named = label if complete[label] else f"{label} ({counts[label]})"
            ax.plot(taus, share, color=colour, ls=_SERIES_STYLES[k % len(_SERIES_STYLES)], label=named)
            if np.all(np.isfinite(low)):
                ax.fill_between(taus, low, high, color=colour, alpha=0.15, lw=0)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no run with a finite score", ha="center", transform=ax.transAxes)
    ax.set(xlabel=f"score tau ({score_name})", ylabel="share of runs with score > tau", ylim=(-0.03, 1.03))
    ax.grid(alpha=0.3)
    written.append(out / f"{prefix}statistics_profiles.png")
    _save(fig, written[-1], title)

    pairs = []
    modes = dict.fromkeys(mode for _, mode in runs)
    for mode in modes:
        by_algo = {algo: scores for (algo, m), (scores, _) in runs.items() if m == mode and scores.size}
        if reference in by_algo:
            x = by_algo[reference]
            pairs += [
                (f"{reference} > {other} ({mode}, {x.size} vs {_count(y.size, 'run')})", x, y)
                for other, y in by_algo.items()
                if other != reference
            ]
    fig, ax = plt.subplots(figsize=(7.0, 0.6 * max(len(pairs), 1) + 1.6), layout="constrained")
    for k, (_, x, y) in enumerate(pairs):
        probability, low, high = probability_of_improvement(x, y)
        ax.plot([probability], [k], "o", color=colours[0], ms=7)
        if np.isfinite(low):
            ax.plot([low, high], [k, k], "-", color=colours[0], lw=5, alpha=0.5)
    ax.axvline(0.5, color="0.4", ls=":", lw=1)
    ax.set_yticks(range(len(pairs)), [label for label, _, _ in pairs])
    with_ci = any(x.size > 1 and y.size > 1 for _, x, y in pairs)
    ax.set(xlim=(-0.02, 1.02), xlabel="P(a run of X scores above a run of Y)" + (", 95 % CI" if with_ci else ""))
    if not pairs:
        nothing = f"nothing to compare: no mode has runs of {reference} and of another algorithm with a score"
        ax.text(0.5, 0.5, nothing, ha="center", transform=ax.transAxes)
    written.append(out / f"{prefix}statistics_improvement.png")
    _save(fig, written[-1], title)
    return written


def _used(used: int, runs: int) -> str:
    """``"5 runs"``, or ``"4 of 5 runs"`` where some runs have no finite score."""
    return _count(used, "run") if used == runs else f"{used} of {_count(runs, 'run')}"
