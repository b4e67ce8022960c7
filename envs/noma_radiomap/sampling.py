"""The missions of a reset: each robot's start and destination, drawn from its scenario or given in the reset options
(docs/MODEL.md, the paper's task; the env's Starting State)."""

from typing import Any

import numpy as np

from noma_radiomap import geometry
from noma_radiomap.motion import GridMotion
from noma_radiomap.radiomap import RadioMap
from noma_radiomap.scenario import Scenario, starts_away_from

__all__ = ["MissionSampler"]


class MissionSampler:
    """
    Draws missions: per robot one of its scenario destinations (the first only with ``fixed_destinations``) and a
    free cell centre of its start region farther than ``arrival_radius`` from it, or the points of the reset
    options, checked (free, reachable, not already arrived).

    :param scenario: the scenario
    :param radio_map: its radio map (the free start cells)
    :param motion: its motion rules (which points are free)
    :param fixed_destinations: each robot's first listed destination only (the paper's task)
    """

    def __init__(self, scenario: Scenario, radio_map: RadioMap, motion: GridMotion, fixed_destinations: bool = False) -> None:
        self.scenario, self.radio_map, self.motion = scenario, radio_map, motion
        self.fixed_destinations = fixed_destinations
        self.n_robots = scenario.n_robots
        self._components = geometry.free_components(radio_map.blocked)
        #: Per robot, the centres of the free cells of its start region
        self._start_centres = [(radio_map.start_cells(u) + 0.5) * scenario.room.resolution for u in range(self.n_robots)]
        #: Per robot, its destinations and the free start cells not already at each of them
        self.choices = self._choices()

    def _choices(self) -> list[list[tuple[np.ndarray, np.ndarray]]]:
        """Per robot, its destinations (the first only in the paper's task) and the free start cells not already
        at each of them."""
        sc = self.scenario
        missions = []
        for u, robot in enumerate(sc.robots):
            centres = self._start_centres[u]
            choices = []
            for destination in robot.destinations[:1] if self.fixed_destinations else robot.destinations:
                far = starts_away_from(centres, destination, sc.robot.arrival_radius, u, robot.start)
                choices.append((np.asarray(destination, dtype=np.float64), centres[far]))
            missions.append(choices)
        return missions

    # --- missions ----------------------------------------------------------------------------------
    def draw(self, options: dict[str, Any] | None, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """
        Starts and destinations (U, 2) each: drawn from the scenario with ``rng``, or given in the reset options.

        :param options: the reset options
        :param rng: the mission's generator
        """
        options = {} if options is None else dict(options)
        unknown = set(options) - {"starts", "destinations"}
        if unknown:
            raise ValueError(f"options: unknown keys {sorted(unknown)}, expected 'starts' and/or 'destinations'")
        destinations = self._option_points(options, "destinations")
        starts = self._option_points(options, "starts")
        if destinations is None:
            destinations = np.empty((self.n_robots, 2))
            for u, choices in enumerate(self.choices):
                goals = [goal for goal, _ in choices] if starts is None else self._destinations_for(u, starts[u])
                destinations[u] = goals[rng.integers(len(goals))]
        if starts is None:
            starts = np.empty((self.n_robots, 2))
            for u, choices in enumerate(self.choices):
                candidates = self._start_candidates(u, destinations[u], choices)
                starts[u] = candidates[rng.integers(len(candidates))]
        self._check_mission(starts, destinations)
        return starts, destinations

    def _destinations_for(self, u: int, start: np.ndarray) -> list[np.ndarray]:
        """Robot ``u``'s destinations (the first only in the paper's task) that a mission from ``start``, given
        through the options, can have: reachable and farther than ``arrival_radius``."""
        goals = [goal for goal, _ in self.choices[u] if self._can_go(start, goal)]
        if not goals:
            listed = [goal.tolist() for goal, _ in self.choices[u]]
            raise ValueError(
                f"options['starts'][{u}]: {start.tolist()} is within arrival_radius of, or unreachable from, every "
                f"destination of robot {u} ({listed}); give options['destinations'] too"
            )
        return goals

    def _start_candidates(self, u: int, destination: np.ndarray, choices: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        for goal, candidates in choices:
            if np.array_equal(goal, destination):
                return candidates
        # A destination given through the options: any free cell of the start region that can go there.
        centres = self._start_centres[u]
        usable = self._can_go(centres, destination)
        if not usable.any():
            raise ValueError(
                f"options['destinations'][{u}]: {destination.tolist()} is within arrival_radius of, or unreachable "
                f"from, every free cell of robot {u}'s start region {list(self.scenario.robots[u].start)}"
            )
        return centres[usable]

    def _can_go(self, starts: np.ndarray, destination: np.ndarray) -> np.ndarray:
        """Whether missions from ``starts`` (one point or (k, 2)) to ``destination`` are possible: farther than
        ``arrival_radius`` and in the same free component of the room."""
        room = self.scenario.room
        far = np.hypot(*(np.asarray(starts) - destination).T) > self.scenario.robot.arrival_radius
        return far & (self._components[room.cell_index(starts)] == self._components[room.cell_index(destination)])

    def _option_points(self, options: dict[str, Any], key: str) -> np.ndarray | None:
        if key not in options or options[key] is None:
            return None
        try:
            points = np.array(options[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"options[{key!r}]: expected {self.n_robots} points [x, y], got {options[key]!r}") from None
        if points.shape != (self.n_robots, 2) or not np.isfinite(points).all():
            raise ValueError(
                f"options[{key!r}]: expected {self.n_robots} finite points [x, y] (shape ({self.n_robots}, 2)), "
                f"got {options[key]!r}"
            )
        free = self.motion.is_free(points)
        if not free.all():
            u = int(np.flatnonzero(~free)[0])
            raise ValueError(f"options[{key!r}][{u}]: {points[u].tolist()} is outside the room or in a blocked cell")
        return points

    def _check_mission(self, starts: np.ndarray, destinations: np.ndarray) -> None:
        start_labels = self._components[self.scenario.room.cell_index(starts)]
        goal_labels = self._components[self.scenario.room.cell_index(destinations)]
        for u in range(self.n_robots):
            if start_labels[u] != goal_labels[u]:
                raise ValueError(
                    f"options: destination {destinations[u].tolist()} of robot {u} is unreachable from its start "
                    f"{starts[u].tolist()}"
                )
            if np.hypot(*(starts[u] - destinations[u])) <= self.scenario.robot.arrival_radius:
                raise ValueError(
                    f"options: start {starts[u].tolist()} of robot {u} is already within arrival_radius "
                    f"({self.scenario.robot.arrival_radius} m) of its destination {destinations[u].tolist()}"
                )
