"""The margins that make a room pose the paper's problem (docs/SCENARIOS.md, "mall design"), on its test missions.

For each channel (the radio map and Rayleigh fading) and multiple-access mode, the MQI of the best planner
(:class:`noma_radiomap.planners.ReferencePlanner`), of the shortest-path planner with the best power split per
step and with an equal split, and, on the radio-map channel, the mean upper bound
(:func:`noma_radiomap.planners.mqi_upper_bound`) with the best planner's optimality gap. Then the two margins
the default room is calibrated for:

- path design: best planner - shortest-path planner (best power), NOMA, >= 15 MQI;
- NOMA: the best planner's NOMA - its OMA, >= 25 MQI;

and, on the radio-map channel, the smallest per-mission difference best - shortest-path (never negative).
Last, the longest mission the room allows one robot: the shortest path from its start area to the farthest free
cell, in metres and in steps at ``V_max`` (with Rayleigh fading the NOMA margin is bounded by about 0.33 outages per
step of mission time, docs/SCENARIOS.md).
The test missions are those of ``sb3-dtdpg compare``: episode ``i`` reset with seed ``10000 + i``.

Usage::

    python benchmarks/room_calibration.py [--scenario mall] [--episodes 20] [--seed 10000]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import noma_radiomap  # noqa: F401  (registers the envs)
from noma_radiomap import load_scenario
from noma_radiomap.geometry import grid_distance_field
from noma_radiomap.planners import ReferencePlanner, ShortestPathPlanner
from sb3_dtdpg.arguments import positive_int, seed_int
from sb3_dtdpg.evaluation import evaluate
from sb3_dtdpg.experiments.compare import mission_bound, planner_margins

MIN_PATH_MARGIN = 15.0
MIN_NOMA_MARGIN = 25.0


def measure(scenario: str = "mall", episodes: int = 20, seed: int = 10_000) -> dict[str, dict[str, float]]:
    """
    :param scenario: scenario name or path
    :param episodes: test missions
    :param seed: seed of the first test mission
    :return: per channel, the MQIs (``"<planner> <mode>"``), ``bound <mode>``, the margins and ``min_difference``
    """
    best = ReferencePlanner()  # one instance: its candidate rollouts are shared by the modes and channels
    figures: dict[str, dict[str, float]] = {}
    for channel in ("radio_map", "rayleigh"):
        row: dict[str, float] = {}
        for mode in ("noma", "oma"):
            env = gym.make("NomaRadioMap-v0", scenario=scenario, channel=channel, multiple_access=mode)
            results = {
                "best": evaluate(best, env, n_episodes=episodes, seed=seed),
                "shortest": evaluate(ShortestPathPlanner(power="best"), env, n_episodes=episodes, seed=seed),
                "equal": evaluate(ShortestPathPlanner(), env, n_episodes=episodes, seed=seed),
            }
            for name, result in results.items():
                row[f"{name} {mode}"] = result.mqi_mean
            if channel == "radio_map":
                differences = [
                    b["mqi"] - s["mqi"] for b, s in zip(results["best"].episodes, results["shortest"].episodes, strict=True)
                ]
                row[f"min_difference {mode}"] = float(min(differences))
                row[f"bound {mode}"] = mission_bound("NomaRadioMap-v0", mode, episodes, seed, {"scenario": scenario})
            env.close()
        row["path_margin"], row["noma_margin"] = planner_margins(row["best noma"], row["shortest noma"], row["best oma"])
        figures[channel] = row
    return figures


def longest_mission(scenario: str = "mall") -> list[tuple[float, float]]:
    """
    :param scenario: scenario name or path
    :return: per robot, the longest shortest path (metres) from a cell of its start area to any free cell the
        robot can reach, and the steps it takes at ``V_max`` (less the arrival radius)
    """
    env = gym.make("NomaRadioMap-v0", scenario=scenario).unwrapped
    radio_map, spec = env.radio_map, env.scenario
    per_step = spec.robot.v_max * spec.mission.time_step
    longest = []
    for robot in range(len(spec.robots)):
        metres = 0.0
        for cell in radio_map.start_cells(robot):
            distances = grid_distance_field(radio_map.blocked, tuple(cell), radio_map.resolution)
            metres = max(metres, float(distances[np.isfinite(distances)].max()))
        longest.append((metres, (metres - spec.robot.arrival_radius) / per_step))
    env.close()
    return longest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="mall")
    parser.add_argument("--episodes", type=positive_int, default=20)
    parser.add_argument("--seed", type=seed_int, default=10_000)
    args = parser.parse_args()
    try:
        load_scenario(args.scenario)
    except ValueError as error:  # names the scenario and the built-in ones
        parser.error(f"--scenario: {error}")
    start = time.perf_counter()
    figures = measure(args.scenario, args.episodes, args.seed)
    print(f"{args.scenario}: {args.episodes} test missions (seeds {args.seed}..{args.seed + args.episodes - 1})")
    for channel, row in figures.items():
        print(f"\n{channel} channel")
        print(f"  {'mode':5} {'best':>7} {'shortest (best power)':>22} {'shortest (equal)':>17} {'bound (gap)':>16}")
        for mode in ("noma", "oma"):
            bound = (
                f"{row[f'bound {mode}']:.1f} ({row[f'bound {mode}'] - row[f'best {mode}']:.1f})"
                if f"bound {mode}" in row
                else "-"
            )
            print(
                f"  {mode.upper():5} {row[f'best {mode}']:7.1f} {row[f'shortest {mode}']:22.1f} "
                f"{row[f'equal {mode}']:17.1f} {bound:>16}"
            )
        print(
            f"  path design margin (best - shortest path, NOMA): {row['path_margin']:+.1f} (bar {MIN_PATH_MARGIN:g}); "
            f"NOMA margin (best NOMA - best OMA): {row['noma_margin']:+.1f} (bar {MIN_NOMA_MARGIN:g})"
        )
        if "min_difference noma" in row:
            print(
                f"  smallest per-mission best - shortest path: NOMA {row['min_difference noma']:+.1f}, "
                f"OMA {row['min_difference oma']:+.1f}"
            )
    print()
    for robot, (metres, steps) in enumerate(longest_mission(args.scenario)):
        print(f"robot {robot}: the farthest free cell from its start area is {metres:.1f} m away ({steps:.0f} steps)")
    print(f"\n({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
