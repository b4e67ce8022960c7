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

from sb3_dtdpg.evaluation import mean_ci

__all__ = [
    "episode_curves",
    "episode_destinations",
    "plot_learning_curves",
    "plot_trajectories",
    "read_scalars",
    "transfer_episode",
]

#: The episode count logged with every dump (by :class:`sb3_dtdpg.experiments.runs.EpisodeReturnLogger`).
EPISODES_TAG = "episode/number"


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
    curves = episode_curves(log_dir, ["curriculum/phase"])
    if "curriculum/phase" not in curves:
        return None
    later = curves.index[curves["curriculum/phase"].to_numpy() >= 1]
    return float(later[0]) if len(later) else None


def _mean_band(curves: Sequence[pd.Series], n_points: int = 200) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and 95 % CI across runs, after interpolating every run onto a common episode grid."""
    curves = [c.dropna() for c in curves if len(c.dropna())]
    end = min(float(c.index.max()) for c in curves)
    grid = np.linspace(min(float(c.index.min()) for c in curves), end, n_points)
    values = np.stack([np.interp(grid, c.index.to_numpy(dtype=float), c.to_numpy(dtype=float)) for c in curves])
    stats = [mean_ci(values[:, k]) for k in range(values.shape[1])]
    mean = np.array([s[0] for s in stats])
    half = np.nan_to_num(np.array([s[1] for s in stats]))
    return grid, mean, half


def plot_learning_curves(
    groups: Mapping[str, Sequence[str | Path]],
    path: str | Path,
    tags: Sequence[tuple[str, str]] = (("mission/mqi", "MQI per episode"), ("mission/success_rate", "success rate")),
    smooth: int = 10,
    title: str | None = None,
) -> Any:
    """
    Learning curves: for each group (e.g. ``dtdpg_noma``), the mean over its runs (seeds) and the 95 % CI
    band, against the training episode; DT-DPG's transfer episodes are marked by dotted lines.

    :param groups: group label -> the TensorBoard folders of its runs
    :param path: where to save the PNG
    :param tags: ``(tag, axis label)`` pairs, one panel each
    :param smooth: rolling-mean window (episodes) applied to each run before averaging
    :param title: figure title
    :return: the figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(tags), figsize=(6.0 * len(tags), 4.0), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (label, dirs) in enumerate(groups.items()):
        colour = colours[k % len(colours)]
        per_run = [episode_curves(d, [t for t, _ in tags]) for d in dirs]
        for ax, (tag, _) in zip(axes[0], tags, strict=False):
            series = [run[tag].rolling(smooth, min_periods=1).mean() for run in per_run if tag in run and len(run)]
            if not series:
                continue
            x, mean, half = _mean_band(series)
            ax.plot(x, mean, color=colour, label=f"{label} (n={len(series)})")
            ax.fill_between(x, mean - half, mean + half, color=colour, alpha=0.2, lw=0)
            for episode in filter(None, (transfer_episode(d) for d in dirs)):
                ax.axvline(episode, color=colour, ls=":", lw=0.8)
    for ax, (_, ylabel) in zip(axes[0], tags, strict=False):
        ax.set_xlabel("training episode")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    if axes[0][0].get_legend_handles_labels()[0]:
        axes[0][0].legend(fontsize=8)
    return _save(fig, path, title)


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
    Trajectories on the SINR map, one panel per key of ``panels`` (e.g. NOMA / OMA). Starts are circles,
    end points squares, destinations white crosses; robot 0 is drawn solid, the others dashed.

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

    from noma_radiomap import RadioMap, load_scenario

    scenario = load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario
    radio_map = RadioMap.for_scenario(scenario)
    room = scenario.room
    width = 7.0 * room.width / max(room.width, room.depth) + 1.5
    fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), 0.8 * width * room.depth / room.width + 1.2))
    axes = np.atleast_1d(axes)
    colours = ["#ffffff", "#00e5ff", "#ff66ff", "#ffd700", "#7CFC00", "#ff8c00"]  # red is the map's outage contour
    for ax, (panel, trajectories) in zip(axes, panels.items(), strict=False):
        radio_map.plot(ax=ax, kind="sinr", colorbar=True)
        goals = None if destinations is None else destinations.get(panel)
        if goals is not None:
            ax.plot(
                *np.asarray(goals, dtype=float).T,
                marker="X",
                ms=11,
                color="white",
                mec="black",
                ls="none",
                label="destination",
            )
        for k, (label, trajectory) in enumerate(trajectories.items()):
            trajectory = np.asarray(trajectory, dtype=float)
            for u in range(trajectory.shape[1]):
                ax.plot(
                    *trajectory[:, u].T,
                    color=colours[k % len(colours)],
                    lw=1.6,
                    ls="-" if u == 0 else "--",
                    label=label if u == 0 else None,
                )
                ax.plot(*trajectory[0, u], marker="o", ms=5, color=colours[k % len(colours)], mec="black")
                ax.plot(*trajectory[-1, u], marker="s", ms=5, color=colours[k % len(colours)], mec="black")
        ax.set_title(panel)
        ax.legend(fontsize=7, loc="upper right", framealpha=0.6)
    return _save(fig, path, title)


def _save(fig: Any, path: str | Path, title: str | None) -> Any:
    """Add the title, write the figure to ``path`` and release it; return the figure."""
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return fig
