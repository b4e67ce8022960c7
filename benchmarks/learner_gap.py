"""Where the learners lose MQI to the planners: the path they drive or the power split they choose.

For every trained model of a ``compare`` or ``reproduce`` output folder (``<out>/runs/*/model.zip``) and for the two
reference planners, the test missions are run on the radio-map channel (the channel the learners train on and the
planners plan on) and, at every step, the exact best power split for the positions the robots actually reached
(:func:`noma_radiomap.planners.best_power`) is computed. So a policy's MQI splits into

- its **path**: the MQI it would score driving the same positions with the best power split at every step
  (``MQI + lambda x (outage steps - outage steps with the best split on its path)``), and
- its **power split**: what it loses against the best split on its own path (``lambda`` x the extra outage steps).

And of that split: the share of the AP power ``P_max`` it transmits while a robot is under way (the env scales the
powers down when they ask for more than ``P_max``, never up) and the outage steps its split would have with the
powers scaled up to the whole ``P_max`` in the same ratio: what it loses by leaving power unused, apart from how it
divides the power.

A path scored with the best split can be compared with the planners, whose power split is already the best one:
above the shortest-path planner, the policy drives a path that uses the radio map better than the shortest one.
Printed: one row per algorithm and mode, mean and 95 % CI over the seeds (the planners: over the test missions);
written with ``--csv``: one row per model (or planner) and test mission. Only the radio-map channel: with Rayleigh
fading a policy sees the faded gains it acts on, so no split computed from the mean gains is a best one for it.

Usage::

    python benchmarks/learner_gap.py results/compare [--episodes 20] [--csv gap.csv] [--figure gap.png]
    python benchmarks/learner_gap.py results/paper --runs '*_radio_map_500_tuned_goal'  # one experiment of reproduce
    python benchmarks/learner_gap.py --from-csv a.csv b.csv --labels "500 episodes" "2000 episodes" --figure gap.png

The figure draws each learner's MQI with its own split and, stacked on it, what it loses to its split (the top of
the bar is its path's worth), against the two planners' MQIs, one panel per mode.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

import noma_radiomap  # noqa: F401  (registers the envs)
from noma_radiomap.planners import ReferencePlanner, ShortestPathPlanner, best_power, channel_maps, outages
from noma_radiomap.propagation import dbm_to_watt
from sb3_dtdpg.arguments import positive_int
from sb3_dtdpg.evaluation import evaluate, mean_ci
from sb3_dtdpg.experiments.tables import ALGO_LABELS
from sb3_dtdpg.model_files import read_saved_model

#: The reference planners: label -> factory
PLANNERS = {
    "best planner": lambda: ReferencePlanner(),
    "shortest-path planner": lambda: ShortestPathPlanner(power="best"),
}
#: The per-mission columns summarised by :func:`summarise`
COLUMNS = (
    "mqi",
    "mqi_best_power",
    "power_loss",
    "outage_steps",
    "outage_best_power",
    "steps",
    "power_used",
    "outage_full_power",
)
#: The columns a ``--csv`` of this script has (one of an earlier version lacks the power columns)
CSV_COLUMNS = ("policy", "mode", "run", "episode", *COLUMNS[:6])


class PowerRecorder(gym.Wrapper):
    """Keeps the transmit powers of every step (``info["power_w"]``), one list per episode."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.episodes: list[list[np.ndarray]] = []

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self.episodes.append([])
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.episodes[-1].append(np.asarray(info["power_w"], dtype=np.float64))
        return observation, reward, terminated, truncated, info


def _full_power_outages(env: Any, positions: np.ndarray, powers: np.ndarray, active: np.ndarray) -> float:
    """:return: the outage steps of the active robots with each step's powers scaled up to the whole ``P_max`` (the
    same ratio between the robots), on the radio-map channel"""
    scenario = env.scenario
    max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
    total = powers.sum(axis=1, keepdims=True)
    scaled = np.where(total > 0, powers * (max_power_w / np.maximum(total, 1e-300)), powers)
    gain, interference = channel_maps(env)
    ix, iy = env.radio_map.cell_index(positions)
    return float(outages(scaled, gain[ix, iy], interference[ix, iy], active, scenario, env.multiple_access).sum())


def mission_splits(policy: Any, env: gym.Env, episodes: int, seed: int) -> list[dict[str, float]]:
    """
    The test missions of a policy (:func:`sb3_dtdpg.evaluation.evaluate`) and what the best power split on the
    positions it reached would have scored.

    :param policy: an SB3 model or a planner
    :param env: the (wrapped) mission env, on the radio-map channel
    :param episodes: test missions; mission ``i`` is reset with ``seed + i``
    :param seed: the reset seed of mission 0
    :return: per mission, its MQI, outage steps (the policy's and with the best split on its positions), the extra MQI
        of the best split, the episode length in steps, the mean share of ``P_max`` transmitted while a robot is
        under way, and the outage steps with the policy's powers scaled up to ``P_max``
    """
    recorder = PowerRecorder(env)
    result = evaluate(policy, recorder, n_episodes=episodes, seed=seed, return_trajectories=True)
    base: Any = env.unwrapped
    penalty = float(base.scenario.mission.outage_penalty)
    max_power_w = float(dbm_to_watt(base.scenario.ap.max_power_dbm))
    splits = []
    for record, trajectory, powers in zip(result.episodes, result.trajectories, recorder.episodes, strict=True):
        positions = trajectory[1:]  # after each step
        # A robot transmits (and can be in outage) until the step it arrives, as the planners count it
        arrival = np.array([record[f"mission_time_{u}"] for u in range(positions.shape[1])])
        active = np.arange(len(positions))[:, None] < arrival[None, :]
        _, best_outage = best_power(base, positions, active)
        power_loss = penalty * (record["outage_steps"] - float(best_outage.sum()))
        powers = np.array(powers)
        under_way = active.any(axis=1)
        used = (powers * active).sum(axis=1)[under_way] / max_power_w
        splits.append(
            {
                "mqi": record["mqi"],
                "mqi_best_power": record["mqi"] + power_loss,
                "power_loss": power_loss,
                "outage_steps": record["outage_steps"],
                "outage_best_power": float(best_outage.sum()),
                "steps": float(record["steps"]),
                "power_used": float(used.mean()),
                "outage_full_power": _full_power_outages(base, positions, powers, active),
            }
        )
    return splits


def _model_env(path: Path) -> tuple[Any, gym.Env, dict[str, Any], dict[str, Any]]:
    """:return: the model, its radio-map test env, its settings (with ``algo``) and that env's make arguments"""
    saved = read_saved_model(path, None)
    kwargs = saved.env_kwargs("radio_map")  # a scenario file's path where it was trained on one
    env = gym.make(saved.env_id or "NomaRadioMap-v0", **kwargs)
    return saved.load(env), env, {**(saved.settings or {}), "algo": saved.algo}, kwargs


def measure(out: Path, episodes: int, seed: int, runs: str = "*") -> pd.DataFrame:
    """
    :param runs: a glob pattern of the run folders to measure (``reproduce`` keeps several experiments' runs in one
        folder, which the table would otherwise pool by algorithm and mode)
    :return: one row per policy (model or planner) and test mission, with the columns of :func:`mission_splits`
    """
    rows: list[dict[str, Any]] = []
    models = sorted(out.glob(f"runs/{runs}/model.zip"))
    if not models:
        raise SystemExit(f"no models in {out}/runs/{runs}/model.zip: give the output folder of compare or reproduce")
    envs: dict[str, dict[str, Any]] = {}
    for path in models:
        model, env, settings, kwargs = _model_env(path)
        mode = str(settings.get("multiple_access", "noma"))
        envs.setdefault(mode, {k: kwargs[k] for k in ("scenario", "observation", "task") if kwargs.get(k) is not None})
        label = ALGO_LABELS.get(settings["algo"], settings["algo"])
        if settings.get("power_mapping", "paper") != "paper":  # benchmarks/power_shares.py's other arm
            label += f" ({settings['power_mapping']})"
        for i, split in enumerate(mission_splits(model, env, episodes, seed)):
            rows.append({"policy": label, "mode": mode, "run": path.parent.name, "episode": i, **split})
        env.close()
    for mode, kwargs in envs.items():
        env = gym.make("NomaRadioMap-v0", channel="radio_map", multiple_access=mode, **kwargs)
        for label, factory in PLANNERS.items():
            for i, split in enumerate(mission_splits(factory(), env, episodes, seed)):
                rows.append({"policy": label, "mode": mode, "run": label, "episode": i, **split})
        env.close()
    return pd.DataFrame(rows)


def summarise(missions: pd.DataFrame) -> pd.DataFrame:
    """
    :return: per policy and mode, the mean and 95 % CI of each column, over the runs (seeds) for learners and over
        the missions for planners; ``vs_shortest``: the path's MQI (best split) minus the shortest-path planner's
    """
    rows = []
    columns = [column for column in COLUMNS if column in missions]  # a CSV of an earlier version has fewer
    for (policy, mode), group in missions.groupby(["policy", "mode"], sort=False):
        per_sample = group if policy in PLANNERS else group.groupby("run")[columns].mean()
        shortest = missions[(missions.policy == "shortest-path planner") & (missions["mode"] == mode)].mqi.mean()
        row: dict[str, Any] = {"policy": policy, "mode": mode, "n": len(per_sample)}
        for column in columns:
            row[column], row[f"{column}_ci"] = mean_ci(per_sample[column])
        row["vs_shortest"] = row["mqi_best_power"] - shortest
        rows.append(row)
    return pd.DataFrame(rows)


def plot(frames: dict[str, pd.DataFrame], path: Path) -> None:
    """
    :param frames: the missions of :func:`measure` (or their CSV) by label (e.g. the training budget)
    :param path: where to write the figure
    """
    from matplotlib.figure import Figure

    colors = {"DT-DPG": "tab:blue", "DDPG": "tab:orange"}
    summaries = {label: summarise(missions) for label, missions in frames.items()}
    modes = [m for m in ("noma", "oma") if any((s["mode"] == m).any() for s in summaries.values())]
    figure = Figure(figsize=(3.2 + 1.6 * len(frames) * len(modes), 4.6), layout="constrained")
    axes = figure.subplots(1, len(modes), squeeze=False)[0]
    for ax, mode in zip(axes, modes, strict=True):
        planners = next(iter(summaries.values()))
        planners = planners[planners["mode"] == mode].set_index("policy")
        lines = [planners.loc[name, "mqi"] for name in ("best planner", "shortest-path planner")]
        x, ticks, names, low, top = 0.0, [], [], min(lines), max(lines)
        for label, summary in summaries.items():
            learners = summary[(summary["mode"] == mode) & ~summary["policy"].isin(list(PLANNERS))]
            for _, row in learners.iterrows():
                color = colors.get(row.policy, "tab:gray")
                # One seed (compare's default) has no CI: the bar without an error bar
                ci = row.mqi_ci if np.isfinite(row.mqi_ci) else 0.0
                ax.bar(x, row.mqi, yerr=ci if ci > 0 else None, color=color, capsize=3)
                ax.bar(x, row.power_loss, bottom=row.mqi, color=color, alpha=0.3, hatch="//", edgecolor=color)
                ticks.append(x)
                names.append(f"{row.policy}\n{label}")
                low, top = min(low, row.mqi - ci), max(top, row.mqi + max(ci, row.power_loss))
                x += 1.0
            x += 0.5
        for name, style in (("best planner", "-"), ("shortest-path planner", "--")):
            ax.axhline(planners.loc[name, "mqi"], color="black", linestyle=style, linewidth=1, label=name)
        margin = max(top - low, 1.0)  # every bar and line at one value: still a range
        ax.set_ylim(low - 0.15 * margin, top + 0.1 * margin)
        ax.set_xticks(ticks, names, fontsize=8)
        ax.set_title(f"{mode.upper()}, radio-map channel")
    axes[0].set_ylabel("MQI on the test missions")
    axes[0].bar(np.nan, np.nan, color="gray", label="MQI with its own power split (95 % CI over seeds, if several)")
    axes[0].bar(np.nan, np.nan, color="gray", alpha=0.3, hatch="//", label="lost to its split (top: its path's worth)")
    figure.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=2, fontsize=8)
    figure.savefig(path, dpi=120)


def _format(value: float, ci: float) -> str:
    return f"{value:.1f}" if not np.isfinite(ci) or ci == 0 else f"{value:.1f} ± {ci:.1f}"


def csv_labels(paths: list[Path], labels: list[str] | None = None) -> list[str]:
    """
    :param paths: the ``--from-csv`` files
    :param labels: their ``--labels`` (None: the file names, with their folders where two share a name)
    :return: one label per file, no two alike
    :raises ValueError: a file given twice, a number of labels other than of files, or a label given twice
    """
    seen: dict[Path, Path] = {}
    for path in paths:
        if seen.setdefault(path.resolve(), path) is not path:
            raise ValueError(f"--from-csv: {path} given twice")
    if labels is None:  # the file names, with as many of their folders as tell them apart
        labels = [path.stem for path in paths]
        depth = 1
        while len(set(labels)) < len(labels) and depth < max(len(path.parts) for path in paths):
            depth += 1
            labels = ["/".join(path.with_suffix("").parts[-depth:]) for path in paths]
    elif len(labels) != len(paths):
        raise ValueError(f"--labels: {len(labels)} labels for {len(paths)} --from-csv files")
    repeated = sorted({label for label in labels if labels.count(label) > 1})
    if repeated:
        raise ValueError(f"--labels: {', '.join(map(repr, repeated))} given twice; give each --from-csv file its own label")
    return labels


def read_missions(path: Path) -> pd.DataFrame:
    """
    :param path: a ``--csv`` of this script
    :return: its missions
    :raises ValueError: naming the file when it is no CSV or lacks columns of one
    """
    try:
        missions = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise ValueError(f"--from-csv {path}: cannot read it as a CSV ({error})") from error
    missing = [column for column in CSV_COLUMNS if column not in missions]
    if missing:
        raise ValueError(f"--from-csv {path}: no column {', '.join(missing)} (give a --csv of this script)")
    return missions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, nargs="?", help="output folder of compare or reproduce (its runs/*/model.zip)")
    # None where not given: they measure an output folder, and --from-csv refuses them
    parser.add_argument("--episodes", type=positive_int, default=None, help="test missions (default: 20, as compare)")
    parser.add_argument("--seed", type=int, default=None, help="reset seed of test mission 0 (default: 10000)")
    parser.add_argument(
        "--runs", default=None, help="only the run folders matching this glob pattern, e.g. '*_radio_map_500_tuned_goal'"
    )
    parser.add_argument("--csv", type=Path, default=None, help="write one row per policy and mission here (with out)")
    parser.add_argument("--figure", type=Path, default=None, help="draw the split here (.png)")
    parser.add_argument("--from-csv", type=Path, nargs="+", default=None, help="CSVs of earlier runs of --csv, instead of out")
    parser.add_argument(
        "--labels",
        nargs="+",
        default=None,
        help="a label per --from-csv file, no two alike (default: its name, with its folders where two share one)",
    )
    args = parser.parse_args()
    if args.from_csv:
        if args.out is not None:
            parser.error(f"give an output folder ({args.out}) or --from-csv, not both")
        measuring = [f"--{name}" for name in ("episodes", "seed", "runs", "csv") if getattr(args, name) is not None]
        if measuring:
            parser.error(
                f"{', '.join(measuring)}: only when measuring an output folder; --from-csv reads missions measured before"
            )
    elif args.out is None:
        parser.error("give an output folder of compare or reproduce, or --from-csv")
    elif args.labels is not None:
        parser.error("--labels: only with --from-csv (the label of an output folder is its name)")
    for option, path in (("--csv", args.csv), ("--figure", args.figure)):
        if path is not None:  # a folder that cannot be made fails now, not after the measurement
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                parser.error(f"{option} {path}: {error}")
    if args.from_csv:
        try:
            labels = csv_labels(args.from_csv, args.labels)
            frames = {label: read_missions(path) for label, path in zip(labels, args.from_csv, strict=True)}
        except ValueError as error:
            parser.error(str(error))
    else:
        episodes = 20 if args.episodes is None else args.episodes
        seed = 10_000 if args.seed is None else args.seed
        frames = {args.out.name: measure(args.out, episodes, seed, "*" if args.runs is None else args.runs)}
    for label, missions in frames.items():
        _print_summary(label, missions)
    if args.csv is not None:
        frames[args.out.name].to_csv(args.csv, index=False)
        print(f"wrote {args.csv}")
    if args.figure is not None:
        plot(frames, args.figure)
        print(f"wrote {args.figure}")


def _print_summary(label: str, missions: pd.DataFrame) -> None:
    episodes = missions["episode"].nunique()
    print(f"{label}: radio-map channel, {episodes} test missions (mean ± 95 % CI over seeds; planners: over the missions)")
    powers = "power_used" in missions
    print(
        "| policy | MA | n | MQI | MQI of its path with the best power split | lost to its power split | "
        "outage steps (with the best split) | steps | its path vs the shortest-path planner |"
        + (" share of P_max used | outage steps, its split at full power |" if powers else "")
    )
    print("|---|---|---|---|---|---|---|---|---|" + ("---|---|" if powers else ""))
    for _, r in summarise(missions).iterrows():
        print(
            f"| {r.policy} | {r['mode'].upper()} | {r.n} | {_format(r.mqi, r.mqi_ci)} | "
            f"{_format(r.mqi_best_power, r.mqi_best_power_ci)} | {_format(r.power_loss, r.power_loss_ci)} | "
            f"{r.outage_steps:.1f} ({r.outage_best_power:.1f}) | {r.steps:.1f} | {r.vs_shortest:+.1f} |"
            + (f" {r.power_used:.2f} | {r.outage_full_power:.1f} |" if powers else "")
        )


if __name__ == "__main__":
    main()
