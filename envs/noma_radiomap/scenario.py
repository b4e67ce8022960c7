"""Scenario files (docs/SCENARIOS.md): frozen dataclasses mirroring the YAML schema, loading and validation.

A scenario is plain data: the room, the robots' body, the radio parameters, the AP, the external
interferers, the obstacles (objects built from axis-aligned boxes, the paper's "Lego" bricks), the
robots' missions and the mission constants. All dataclasses are frozen and hold tuples only, so a
:class:`Scenario` is hashable and can key caches (:meth:`noma_radiomap.RadioMap.for_scenario`).

Every field is validated on construction from a mapping (:meth:`Scenario.from_dict`, which also takes numpy
scalars and arrays); a bad field raises a ``ValueError`` naming its path (e.g. ``obstacles[3].boxes[1]``) and the
offending value. An unknown key is reported with the closest known one (``unknown key 'wal_loss_db' (did you mean
'wall_loss_db'?)``).

YAML files are read with YAML 1.2 number rules (``15e3`` and ``1.0e9`` are numbers, not strings; ``010`` is 10,
``0o10`` 8, ``0x10`` 16 and ``1:00`` a string), merge keys (``<<: *base``) work, duplicate keys are errors, and a
file that is not UTF-8, nests deeper than :data:`MAX_NESTING`, is larger than :data:`MAX_FILE_BYTES` or holds more
than :data:`MAX_NODES` values once its aliases are expanded (an alias bomb) gives a ``ValueError`` naming the file.
Limits checked at load time, before anything is built: at most :data:`MAX_GRID_CELLS` grid cells,
:data:`MAX_SUBSTEPS` motion sub-steps per env step (``V_max time_step`` over half a cell), :data:`MAX_LIST_ITEMS`
entries in any list, the estimated memory of the radio map and the env's tables
(:data:`noma_radiomap.radiomap.MAX_MEMORY_BYTES`), and physical ranges (:data:`RANGES`) for every radio, power,
height and mission constant. Error messages quote values through a bounded ``repr`` (at most
:data:`MAX_MESSAGE_CHARS` characters), so a YAML alias bomb cannot hang them.
"""

from __future__ import annotations

import difflib
import functools
import math
import os
import re
import reprlib
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from noma_radiomap import geometry
from noma_radiomap.rewards import RewardConstants

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
#: ``(x0, y0, x1, y1, z_bottom, z_top)`` in metres.
Box = tuple[float, float, float, float, float, float]

#: Most grid cells a room may have (the ``mall``: 6 600); the radio map holds several float arrays per cell.
MAX_GRID_CELLS = 4_000_000
#: Most motion sub-steps of half a cell in one env step (``ceil(V_max time_step / (resolution / 2))``).
MAX_SUBSTEPS = 256
#: Most entries in any list of a scenario (robots, destinations, obstacles, boxes, interferers).
MAX_LIST_ITEMS = 10_000
#: Most values (scalars, lists and mappings) in a scenario file once its YAML aliases are expanded: what bounds
#: the work and memory of loading a small file whose aliases multiply lists (each list alone is within
#: :data:`MAX_LIST_ITEMS`). 10 000 one-box obstacles take about 130 000.
MAX_NODES = 1_000_000
#: Deepest nesting of mappings and lists in a scenario file (the schema needs 4).
MAX_NESTING = 32
#: Largest scenario file read.
MAX_FILE_BYTES = 4_000_000
#: Longest name (scenario, obstacle, interferer).
MAX_NAME_CHARS = 100
#: Longest quoted value in an error message.
MAX_MESSAGE_CHARS = 200
#: Unicode categories of the characters a name may not hold: control (NUL, ESC, newline, ...), format (bidi
#: overrides, zero-width), surrogates and line or paragraph separators; names end up in terminals and file names.
_CONTROL_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})
#: Physical range ``(low, high)`` of each constant (inclusive), by field path (``*``: any list index).
RANGES: dict[str, tuple[float, float]] = {
    "room.width": (0.0, 10_000.0),
    "room.depth": (0.0, 10_000.0),
    "robot.body_height": (0.0, 10.0),
    "robot.antenna_height": (0.0, 10.0),
    "robot.v_max": (0.0, 100.0),
    "robot.arrival_radius": (0.0, 1_000.0),
    "radio.frequency_mhz": (100.0, 100_000.0),  # ITU-R P.1238 covers 300 MHz to 450 GHz; 100 GHz is plenty
    "radio.nlos_distance_coefficient": (0.0, 100.0),
    "radio.wall_loss_db": (0.0, 100.0),
    "radio.wall_loss_step_db": (0.0, 100.0),
    "radio.noise_dbm_per_hz": (-250.0, -100.0),  # thermal noise: -174 dBm/Hz
    # At least 1 Hz: the noise N0 B (>= 1e-28 W) never underflows to 0, and the largest SINR (1 kW at 1 m, path
    # loss >= 12 dB at 100 MHz: below 1e32) and every rate stay finite
    "radio.bandwidth_per_robot_hz": (1.0, 1e10),
    "radio.qos_rate_bps": (0.0, 1e12),
    "ap.position[2]": (0.0, 50.0),
    "ap.max_power_dbm": (-100.0, 60.0),  # 60 dBm = 1 kW
    "interferers[*].position": (-100_000.0, 100_000.0),
    "interferers[*].power_dbm": (-100.0, 80.0),
    "mission.t_total": (0.0, 1e9),
    "mission.outage_penalty": (0.0, 1e6),
    "mission.max_steps": (1, 10_000_000),
    "mission.time_step": (0.0, 3_600.0),
    # Rewards: an episode's return (at most max_steps x robots of them) stays far inside the float32 replay buffer
    "mission.time_cost": (-1e6, 1e6),
    "mission.arrival_reward": (-1e6, 1e6),
    "mission.success_reward": (-1e6, 1e6),
}


@dataclass(frozen=True)
class Room:
    """
    The room: ``x in [0, width]``, ``y in [0, depth]``, a grid of square cells of side ``resolution``.

    The room owns the map from points to cells: cell ``(ix, iy)`` spans
    ``[ix res, (ix + 1) res) x [iy res, (iy + 1) res)`` and grids are indexed ``[ix, iy]`` (flat index
    ``ix * ny + iy``). The methods take points of shape ``(..., 2)``.
    """

    width: float
    depth: float
    resolution: float

    @functools.cached_property
    def nx(self) -> int:
        """Number of cells along x."""
        return round(self.width / self.resolution)

    @functools.cached_property
    def ny(self) -> int:
        """Number of cells along y."""
        return round(self.depth / self.resolution)

    @functools.cached_property
    def shape(self) -> tuple[int, int]:
        """Grid shape ``(nx, ny)``; grids are indexed ``[ix, iy]``."""
        return (self.nx, self.ny)

    @property
    def d_max(self) -> float:
        """The room's diagonal in metres: ``d_max`` of the inducing reward ``R_i = 1 - d / d_max`` (paper Sec. IV-E)."""
        return float(np.hypot(self.width, self.depth))

    def cell_index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Cells of points: ``ix = floor(x / res)``, ``iy = floor(y / res)``, clipped to the grid.

        :param xy: points in metres, shape (..., 2)
        :return: ``(ix, iy)``, int arrays of shape (...)
        """
        return geometry.point_cell(xy, self.resolution, self.shape)

    def flat_cell_index(self, xy: np.ndarray) -> np.ndarray:
        """
        Flat cell indices ``ix * ny + iy`` of points (rows of per-cell tables, ``grid.flat[...]``).

        :param xy: points in metres, shape (..., 2)
        :return: int array of shape (...)
        """
        return geometry.flat_cell(xy, self.resolution, self.shape)

    def cell_center(self, ix: np.ndarray | int, iy: np.ndarray | int) -> np.ndarray:
        """
        Centres of cells: ``((ix + 0.5) res, (iy + 0.5) res)``.

        :param ix: cell index/indices along x
        :param iy: cell index/indices along y
        :return: positions in metres, shape (..., 2)
        """
        return np.stack(
            [
                (np.asarray(ix, dtype=np.float64) + 0.5) * self.resolution,
                (np.asarray(iy, dtype=np.float64) + 0.5) * self.resolution,
            ],
            axis=-1,
        )

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """
        Whether points lie in the room ``[0, width) x [0, depth)``.

        :param xy: points in metres, shape (..., 2)
        :return: bool array of shape (...)
        """
        xy = np.asarray(xy, dtype=np.float64)
        x, y = xy[..., 0], xy[..., 1]
        return (x >= 0.0) & (x < self.width) & (y >= 0.0) & (y < self.depth)


@dataclass(frozen=True)
class RobotSpec:
    """The robots' body (shared by all robots): heights in metres, speed in m/s."""

    body_height: float
    antenna_height: float
    v_max: float
    arrival_radius: float


@dataclass(frozen=True)
class Radio:
    """Radio parameters: path-loss constants (paper Eq. (1)-(3)), noise, bandwidth and QoS (Eq. (12)-(13))."""

    frequency_mhz: float
    nlos_distance_coefficient: float
    wall_loss_db: float
    wall_loss_step_db: float
    noise_dbm_per_hz: float
    bandwidth_per_robot_hz: float
    qos_rate_bps: float


@dataclass(frozen=True)
class AccessPoint:
    """The serving access point: antenna position ``(x, y, z)`` and maximum transmit power."""

    position: Vec3
    max_power_dbm: float


@dataclass(frozen=True)
class Interferer:
    """An external interferer (another AP), possibly outside the room or on another floor."""

    name: str
    position: Vec3
    power_dbm: float


@dataclass(frozen=True)
class Obstacle:
    """One object made of one or more boxes; occlusion counts objects, not boxes (paper Sec. III-C)."""

    name: str
    boxes: tuple[Box, ...]


@dataclass(frozen=True)
class RobotMission:
    """One robot's mission: a start region ``(x0, y0, x1, y1)`` and its candidate destinations."""

    start: tuple[float, float, float, float]
    destinations: tuple[Vec2, ...]


@dataclass(frozen=True)
class Mission:
    """
    Mission constants: MQI budget ``t_total``, outage penalty ``lambda``, step limit and step length (s), and the
    reward constants (defaults: the paper's, Sec. IV-E): time cost ``R_c``, arrival reward ``R_d`` and success
    reward ``R_s``.
    """

    t_total: float
    outage_penalty: float
    max_steps: int
    time_step: float
    time_cost: float = RewardConstants.time_cost
    arrival_reward: float = RewardConstants.arrival_reward
    success_reward: float = RewardConstants.success_reward


@dataclass(frozen=True)
class Scenario:
    """
    A complete scenario (docs/SCENARIOS.md). Build it with :func:`load_scenario` (a built-in name or a YAML
    path) or :meth:`Scenario.from_dict` (validated); :meth:`to_dict` gives the YAML mapping back.

    :param name: scenario name
    :param room: the room and its grid
    :param robot: the robots' body
    :param radio: radio parameters
    :param ap: the serving access point
    :param interferers: external interferers
    :param obstacles: obstacles (objects made of boxes)
    :param robots: one mission per robot (``U = len(robots)``)
    :param mission: mission constants
    :param source: where the scenario was loaded from (not part of equality or the hash)
    """

    name: str
    room: Room
    robot: RobotSpec
    radio: Radio
    ap: AccessPoint
    interferers: tuple[Interferer, ...]
    obstacles: tuple[Obstacle, ...]
    robots: tuple[RobotMission, ...]
    mission: Mission
    source: str | None = field(default=None, compare=False, hash=False, repr=False)

    @property
    def n_robots(self) -> int:
        """Number of robots ``U``."""
        return len(self.robots)

    @property
    def transmitter_names(self) -> tuple[str, ...]:
        """``("ap", *interferer names)``: the keys of the radio map's per-transmitter dicts."""
        return ("ap", *(i.name for i in self.interferers))

    def boxes_array(self) -> tuple[np.ndarray, np.ndarray]:
        """
        All obstacle boxes as one array, with the index of the obstacle each belongs to.

        :return: ``boxes`` of shape (n_boxes, 6) ``[x0, y0, x1, y1, z_bottom, z_top]`` and
            ``owner`` of shape (n_boxes,) (non-decreasing obstacle indices)
        """
        rows = [box for obstacle in self.obstacles for box in obstacle.boxes]
        owner = [k for k, obstacle in enumerate(self.obstacles) for _ in obstacle.boxes]
        return np.asarray(rows, dtype=np.float64).reshape(-1, 6), np.asarray(owner, dtype=np.int64)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str | None = None) -> Scenario:
        """
        Build and validate a scenario from a mapping with the keys of docs/SCENARIOS.md.

        :param data: the scenario mapping (as loaded from YAML)
        :param source: where it came from, used in error messages
        :return: the validated scenario
        :raises ValueError: naming the field path and the offending value (or ``NOMA_RADIOMAP_MAX_MEMORY_BYTES``
            when it is not a positive number of bytes)
        """
        from noma_radiomap.radiomap import memory_cap  # the radio map's module imports this one

        memory_cap()  # a bad cap is the environment's fault, not the scenario's: its error names no file
        try:
            return _parse_scenario(data, source)
        except ValueError as error:
            if source is not None:
                raise ValueError(f"{source}: {error}") from None
            raise

    def to_dict(self) -> dict[str, Any]:
        """
        The scenario as a plain mapping (lists, floats), such that ``Scenario.from_dict(s.to_dict()) == s``.

        :return: the YAML-ready mapping
        """
        return {
            "name": self.name,
            "room": {"width": self.room.width, "depth": self.room.depth, "resolution": self.room.resolution},
            "robot": _fields(self.robot),
            "radio": _fields(self.radio),
            "ap": {"position": list(self.ap.position), "max_power_dbm": self.ap.max_power_dbm},
            "interferers": [
                {"name": i.name, "position": list(i.position), "power_dbm": i.power_dbm} for i in self.interferers
            ],
            "obstacles": [{"name": o.name, "boxes": [list(b) for b in o.boxes]} for o in self.obstacles],
            "robots": [{"start": list(r.start), "destinations": [list(d) for d in r.destinations]} for r in self.robots],
            "mission": _fields(self.mission),
        }

    def with_resolution(self, resolution: float) -> Scenario:
        """
        The same scenario on another grid (validated again: destinations must stay free and reachable).

        :param resolution: new cell size in metres
        :return: a new scenario
        """
        data = self.to_dict()
        data["room"]["resolution"] = resolution
        return Scenario.from_dict(data, self.source)


def _fields(obj: Any) -> dict[str, Any]:
    return {name: getattr(obj, name) for name in obj.__dataclass_fields__}


# --------------------------------------------------------------------------------------------------
# Validation helpers. Each names the field path and the offending value in its error message.
# --------------------------------------------------------------------------------------------------


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxdict, _REPR.maxtuple = 3, 8, 8, 8
_REPR.maxstring, _REPR.maxother, _REPR.maxlong = MAX_MESSAGE_CHARS, MAX_MESSAGE_CHARS, 40


def _quote(value: Any) -> str:
    """A ``repr`` of bounded size and time (nested and shared structures are cut short)."""
    text = _REPR.repr(value)
    return text if len(text) <= MAX_MESSAGE_CHARS else text[: MAX_MESSAGE_CHARS - 3] + "..."


def _describe(value: Any) -> str:
    return f"{_quote(value)} ({type(value).__name__})"


def _check_range(value: float, path: str, key: str | None = None) -> float:
    low, high = RANGES[key or path]
    if not low <= value <= high:
        raise ValueError(f"{path}: {value!r} is outside the physical range [{low:g}, {high:g}]")
    return value


def _suggest(key: Any, known: tuple[str, ...]) -> str:
    close = difflib.get_close_matches(str(key), known, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _mapping(value: Any, path: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> Mapping[str, Any]:
    where = path or "scenario"
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: expected a mapping, got {_describe(value)}")
    prefix = f"{path}." if path else ""
    known = required + optional
    # Unknown keys first: a typo'd key is also a missing one, and the typo is the useful message.
    unknown = [key for key in value if key not in known]
    if unknown:
        key = unknown[0] if isinstance(unknown[0], str) and len(unknown[0]) <= MAX_NAME_CHARS else _quote(unknown[0])
        raise ValueError(f"{prefix}{key}: unknown key{_suggest(key, known)} (known keys of {where}: {sorted(known)})")
    missing = [key for key in required if key not in value]
    if missing:
        raise ValueError(f"{prefix}{missing[0]}: missing key (in {where}, which has keys {_quote(sorted(map(str, value)))})")
    return value


def _plain(value: Any) -> Any:
    """A numpy integer or float scalar as the Python number it holds (``np.bool_`` is neither); else ``value``."""
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def _number(value: Any, path: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    value = _plain(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{path}: expected a number, got {_describe(value)}")
    if abs(value) > 1e300:  # an int too large for a float, or a float too large for arithmetic
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{path}: expected a finite number, got {value!r}")
        raise ValueError(f"{path}: {_quote(value)} is out of range")
    if not math.isfinite(value):
        raise ValueError(f"{path}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise ValueError(f"{path}: must be > 0, got {_quote(value)}")
    if nonnegative and value < 0:
        raise ValueError(f"{path}: must be >= 0, got {value!r}")
    return float(value)


def _integer(value: Any, path: str, *, positive: bool = False) -> int:
    value = _plain(value)
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ValueError(f"{path}: expected an integer, got {_describe(value)}")
    if positive and value <= 0:
        raise ValueError(f"{path}: must be > 0, got {value!r}")
    return int(value)


def _string(value: Any, path: str) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"{path}: expected a non-empty string, got {_describe(value)}")
    if len(value) > MAX_NAME_CHARS:
        raise ValueError(f"{path}: {len(value)} characters, more than the limit of {MAX_NAME_CHARS}: {_quote(value)}")
    if not value.isprintable():  # str.isprintable is fast; the categories say which characters are refused
        for k, char in enumerate(value):
            if unicodedata.category(char) in _CONTROL_CATEGORIES:
                raise ValueError(
                    f"{path}: {_quote(value)} holds a control character ({char!r} at index {k}); names are printed "
                    "and used in file names"
                )
    return value


def _list(value: Any, path: str, *, non_empty: bool = False) -> list[Any]:
    array = isinstance(value, np.ndarray) and value.ndim > 0  # a numpy array is read as its nested lists
    if not (array or isinstance(value, (list, tuple))):
        raise ValueError(f"{path}: expected a list, got {_describe(value)}")
    if non_empty and len(value) == 0:
        raise ValueError(f"{path}: expected a non-empty list, got {_quote(value)}")
    if len(value) > MAX_LIST_ITEMS:
        raise ValueError(f"{path}: {len(value)} entries, more than the limit of {MAX_LIST_ITEMS}")
    return value.tolist() if array else list(value)


def _vector(value: Any, path: str, length: int) -> tuple[float, ...]:
    items = _list(value, path)
    if len(items) != length:
        raise ValueError(f"{path}: expected a list of {length} numbers, got {_quote(value)}")
    return tuple(_number(item, f"{path}[{k}]") for k, item in enumerate(items))


def _in_room(point: tuple[float, ...], room: Room, path: str) -> None:
    x, y = point[0], point[1]
    if not (0.0 <= x <= room.width and 0.0 <= y <= room.depth):
        raise ValueError(f"{path}: {list(point)} is outside the room [0, {room.width}] x [0, {room.depth}]")


def _on_floor(point: tuple[float, ...], room: Room, path: str) -> None:
    """A point a robot must reach: in the room as :meth:`Room.contains` (the env's check of its reset options)."""
    if not room.contains(np.asarray(point)):
        raise ValueError(f"{path}: {list(point)} is outside the room's cells [0, {room.width}) x [0, {room.depth})")


# --------------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------------

_TOP_KEYS = ("name", "room", "robot", "radio", "ap", "robots", "mission")
_OPTIONAL_TOP_KEYS = ("interferers", "obstacles")


def _parse_room(data: Any) -> Room:
    d = _mapping(data, "room", ("width", "depth", "resolution"))
    room = Room(
        width=_check_range(_number(d["width"], "room.width", positive=True), "room.width"),
        depth=_check_range(_number(d["depth"], "room.depth", positive=True), "room.depth"),
        resolution=_number(d["resolution"], "room.resolution", positive=True),
    )
    # Before anything is built from the grid: a fine resolution would allocate until memory runs out.
    n_cells = (room.width / room.resolution) * (room.depth / room.resolution)
    if not n_cells <= MAX_GRID_CELLS:
        raise ValueError(
            f"room.resolution: {room.resolution!r} gives {n_cells:.3g} cells on {room.width!r} x {room.depth!r} m, "
            f"more than the limit of {MAX_GRID_CELLS:,}"
        )
    for side in ("width", "depth"):
        cells = getattr(room, side) / room.resolution
        if cells < 1 or abs(cells - round(cells)) > 1e-6 * max(1.0, cells):
            raise ValueError(
                f"room.resolution: {room.resolution!r} must divide room.{side} = {getattr(room, side)!r} "
                "into a whole number (>= 1) of cells"
            )
    return room


def _parse_simple(cls: type, data: Any, path: str, positive: tuple[str, ...], nonnegative: tuple[str, ...] = ()) -> Any:
    names = tuple(cls.__dataclass_fields__)
    d = _mapping(data, path, names)
    values = {}
    for name in names:
        key = f"{path}.{name}"
        value = _number(d[name], key, positive=name in positive, nonnegative=name in nonnegative)
        values[name] = _check_range(value, key) if key in RANGES else value
    return cls(**values)


def _check_robot(robot: RobotSpec, room: Room, mission: Mission) -> None:
    if robot.body_height >= robot.antenna_height:
        raise ValueError(
            f"robot.body_height: {robot.body_height!r} must be below robot.antenna_height = {robot.antenna_height!r} "
            "(the antenna sits on the body)"
        )
    n_substeps = math.ceil(robot.v_max * mission.time_step / (0.5 * room.resolution) - 1e-9)
    if n_substeps > MAX_SUBSTEPS:
        raise ValueError(
            f"robot.v_max: {robot.v_max!r} m/s x mission.time_step {mission.time_step!r} s is {n_substeps} sub-steps "
            f"of half a cell ({0.5 * room.resolution!r} m) per step, more than the limit of {MAX_SUBSTEPS}"
        )


def _parse_mission(data: Any) -> Mission:
    reward_keys = ("time_cost", "arrival_reward", "success_reward")
    d = _mapping(data, "mission", ("t_total", "outage_penalty", "max_steps", "time_step"), reward_keys)
    defaults = {name: Mission.__dataclass_fields__[name].default for name in reward_keys}
    mission = Mission(
        t_total=_number(d["t_total"], "mission.t_total", positive=True),
        outage_penalty=_number(d["outage_penalty"], "mission.outage_penalty", nonnegative=True),
        max_steps=_integer(d["max_steps"], "mission.max_steps", positive=True),
        time_step=_number(d["time_step"], "mission.time_step", positive=True),
        **{name: _number(d.get(name, defaults[name]), f"mission.{name}") for name in reward_keys},
    )
    for name in ("t_total", "outage_penalty", "max_steps", "time_step", *reward_keys):
        _check_range(getattr(mission, name), f"mission.{name}")
    return mission


def _parse_ap(data: Any, room: Room) -> AccessPoint:
    d = _mapping(data, "ap", ("position", "max_power_dbm"))
    position = _vector(d["position"], "ap.position", 3)
    _in_room(position, room, "ap.position")
    if position[2] <= 0:
        raise ValueError(f"ap.position: the antenna height z must be > 0, got {list(position)}")
    _check_range(position[2], "ap.position[2]")
    power = _check_range(_number(d["max_power_dbm"], "ap.max_power_dbm"), "ap.max_power_dbm")
    return AccessPoint(position=position, max_power_dbm=power)  # type: ignore[arg-type]


def _parse_interferers(data: Any) -> tuple[Interferer, ...]:
    result = []
    names: set[str] = set()
    for k, item in enumerate(_list(data, "interferers")):
        path = f"interferers[{k}]"
        d = _mapping(item, path, ("name", "position", "power_dbm"))
        name = _string(d["name"], f"{path}.name")
        if name == "ap" or name in names:
            raise ValueError(f'{path}.name: {_quote(name)} is not unique ("ap" and other interferers\' names are taken)')
        names.add(name)
        position = _vector(d["position"], f"{path}.position", 3)
        for j, coordinate in enumerate(position):
            _check_range(coordinate, f"{path}.position[{j}]", "interferers[*].position")
        power = _check_range(_number(d["power_dbm"], f"{path}.power_dbm"), f"{path}.power_dbm", "interferers[*].power_dbm")
        result.append(Interferer(name=name, position=position, power_dbm=power))  # type: ignore[arg-type]
    return tuple(result)


def _parse_box(value: Any, path: str, room: Room) -> Box:
    box = _vector(value, path, 6)
    x0, y0, x1, y1, z0, z1 = box
    if x1 <= x0 or y1 <= y0:
        raise ValueError(f"{path}: non-positive size (need x0 < x1 and y0 < y1), got {list(box)}")
    if z1 <= z0:
        raise ValueError(f"{path}: z_top must be > z_bottom, got {list(box)}")
    if z0 < 0:
        raise ValueError(f"{path}: z_bottom must be >= 0, got {list(box)}")
    eps = 1e-9
    if x0 < -eps or y0 < -eps or x1 > room.width + eps or y1 > room.depth + eps:
        raise ValueError(f"{path}: box {list(box)} is outside the room [0, {room.width}] x [0, {room.depth}]")
    return box  # type: ignore[return-value]


def _parse_obstacles(data: Any, room: Room) -> tuple[Obstacle, ...]:
    result = []
    names: set[str] = set()
    for k, item in enumerate(_list(data, "obstacles")):
        path = f"obstacles[{k}]"
        d = _mapping(item, path, ("name", "boxes"))
        name = _string(d["name"], f"{path}.name")
        if name in names:
            raise ValueError(f"{path}.name: {_quote(name)} is not unique")
        names.add(name)
        boxes = tuple(
            _parse_box(b, f"{path}.boxes[{j}]", room) for j, b in enumerate(_list(d["boxes"], f"{path}.boxes", non_empty=True))
        )
        result.append(Obstacle(name=name, boxes=boxes))
    return tuple(result)


def _parse_robots(data: Any, room: Room) -> tuple[RobotMission, ...]:
    result = []
    for u, item in enumerate(_list(data, "robots", non_empty=True)):
        path = f"robots[{u}]"
        d = _mapping(item, path, ("start", "destinations"))
        start = _vector(d["start"], f"{path}.start", 4)
        x0, y0, x1, y1 = start
        if x1 < x0 or y1 < y0:
            raise ValueError(f"{path}.start: need x0 <= x1 and y0 <= y1, got {list(start)}")
        _in_room((x0, y0), room, f"{path}.start")
        _in_room((x1, y1), room, f"{path}.start")
        destinations = tuple(
            _vector(p, f"{path}.destinations[{j}]", 2)
            for j, p in enumerate(_list(d["destinations"], f"{path}.destinations", non_empty=True))
        )
        for j, p in enumerate(destinations):
            _on_floor(p, room, f"{path}.destinations[{j}]")
        result.append(RobotMission(start=start, destinations=destinations))  # type: ignore[arg-type]
    return tuple(result)


def _check_layout(scenario: Scenario) -> None:
    """Checks that need the grid: AP not inside an obstacle, start regions free, destinations reachable."""
    room = scenario.room
    ax, ay, az = scenario.ap.position
    boxes, owner = scenario.boxes_array()
    # The AP must be outside every box, as given and as snapped to the grid (occlusion uses the
    # snapped boxes: an AP inside one would see every ray cross it).
    snapped = geometry.snapped_boxes_m(boxes, room.resolution, room.shape)
    index_in_obstacle = np.arange(len(owner)) - np.searchsorted(owner, owner)
    for raw, grid, k, j in zip(boxes, snapped, owner, index_in_obstacle, strict=True):
        for x0, y0, x1, y1, z0, z1 in (raw, grid):
            if x0 < ax < x1 and y0 < ay < y1 and z0 < az < z1:
                raise ValueError(
                    f"ap.position: {list(scenario.ap.position)} is inside obstacles[{k}].boxes[{j}] "
                    f"({scenario.obstacles[k].name!r}: {list(scenario.obstacles[k].boxes[j])}, "
                    f"snapped to the grid: {grid.tolist()})"
                )
    blocked = geometry.occupancy_grid(boxes, room.width, room.depth, room.resolution, scenario.robot.body_height)
    components = geometry.free_components(blocked)
    for u, robot in enumerate(scenario.robots):
        cells = geometry.region_cells(robot.start, room.resolution, blocked.shape)
        free = cells[~blocked[cells[:, 0], cells[:, 1]]]
        if len(free) == 0:
            raise ValueError(f"robots[{u}].start: region {list(robot.start)} has no free cell")
        start_labels = np.unique(components[free[:, 0], free[:, 1]])
        centres = (free + 0.5) * room.resolution  # the start points the env draws (radiomap.RadioMap.start_cells)
        for j, destination in enumerate(robot.destinations):
            path = f"robots[{u}].destinations[{j}]"
            ix, iy = room.cell_index(np.asarray(destination))
            if blocked[ix, iy]:
                raise ValueError(f"{path}: {list(destination)} lies in a blocked cell ({int(ix)}, {int(iy)})")
            if len(start_labels) > 1 or components[ix, iy] != start_labels[0]:
                raise ValueError(
                    f"{path}: {list(destination)} is unreachable from robots[{u}].start region {list(robot.start)}"
                )
            starts_away_from(centres, destination, scenario.robot.arrival_radius, u, robot.start)


def starts_away_from(
    centres: np.ndarray, destination: Vec2, arrival_radius: float, u: int, start: tuple[float, ...]
) -> np.ndarray:
    """
    The start points of robot ``u`` farther than ``arrival_radius`` from one of its destinations (a robot never
    starts arrived); checked when a scenario is loaded and used by the env's mission sampler
    (:class:`noma_radiomap.sampling.MissionSampler`).

    :param centres: the centres of the free cells of its start region, (k, 2)
    :param destination: the destination
    :param arrival_radius: ``robot.arrival_radius``
    :param u: the robot's index, for the message
    :param start: its start region, for the message
    :return: the mask of ``centres`` far enough
    :raises ValueError: none is
    """
    far = np.hypot(*(centres - np.asarray(destination, dtype=np.float64)).T) > arrival_radius
    if not far.any():
        raise ValueError(
            f"robots[{u}].start: every free cell of {list(start)} is within arrival_radius of destination {list(destination)}"
        )
    return far


def _parse_scenario(data: Any, source: str | None) -> Scenario:
    d = _mapping(data, "", _TOP_KEYS, _OPTIONAL_TOP_KEYS)
    room = _parse_room(d["room"])
    scenario = Scenario(
        name=_string(d["name"], "name"),
        room=room,
        robot=_parse_simple(
            RobotSpec, d["robot"], "robot", positive=("body_height", "antenna_height", "v_max", "arrival_radius")
        ),
        radio=_parse_simple(
            Radio,
            d["radio"],
            "radio",
            positive=("frequency_mhz", "nlos_distance_coefficient", "bandwidth_per_robot_hz", "qos_rate_bps"),
            nonnegative=("wall_loss_db", "wall_loss_step_db"),
        ),
        ap=_parse_ap(d["ap"], room),
        interferers=_parse_interferers(d.get("interferers", [])),
        obstacles=_parse_obstacles(d.get("obstacles", []), room),
        robots=_parse_robots(d["robots"], room),
        mission=_parse_mission(d["mission"]),
        source=source,
    )
    _check_robot(scenario.robot, room, scenario.mission)
    from noma_radiomap.radiomap import check_memory  # the radio map's module imports this one

    check_memory(scenario)  # before the layout checks build the grid
    _check_layout(scenario)
    return scenario


# --------------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------------


def list_scenarios() -> list[str]:
    """
    Names of the built-in scenarios (the YAML files shipped in ``noma_radiomap/scenarios``).

    :return: sorted names, e.g. ``["mall", "small", "warehouse"]``
    """
    folder = resources.files("noma_radiomap") / "scenarios"
    return sorted(entry.name[: -len(".yaml")] for entry in folder.iterdir() if entry.name.endswith(".yaml"))


try:  # libyaml's event parser (about ten times faster) under PyYAML's composer, which counts the values
    from yaml._yaml import CParser

    class _SafeLoader(yaml.composer.Composer, CParser, yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
        """PyYAML's ``SafeLoader`` with libyaml's parser: its ``compose_node`` is Python, and can be overridden."""

        def __init__(self, stream: str | bytes) -> None:
            CParser.__init__(self, stream)
            yaml.composer.Composer.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)

except ImportError:  # PyYAML built without libyaml
    _SafeLoader = yaml.SafeLoader  # type: ignore[misc, assignment]


class ScenarioLoader(_SafeLoader):
    """
    PyYAML's safe loader with YAML 1.2 core-schema numbers and booleans (PyYAML's YAML 1.1 rules read ``15e3`` and
    ``1.0e9`` as strings, ``010`` as 8, ``1:00`` as 60 and ``no`` as False; here they are 15000.0, 1e9, 10 and
    strings; ``0o10`` is 8, ``0x10`` 16, ``true`` and ``false`` the booleans), merge keys (``<<: *base``),
    duplicate keys refused, nesting limited to :data:`MAX_NESTING` and the number of values, aliases expanded (a
    list used through 1000 aliases counts 1000 times), to :data:`MAX_NODES`; recursive aliases are refused. The
    counts are made while the file is composed, before any Python object is built.
    """

    def flatten_mapping(self, node: yaml.MappingNode) -> None:
        # Merging rewrites the node, and those it merges, in place: note their own keys first, once
        explicit: dict[int, list[yaml.Node]] = self.__dict__.setdefault("_explicit_keys", {})
        explicit.setdefault(id(node), [key_node for key_node, _ in node.value if key_node.tag != _MERGE_TAG])
        super().flatten_mapping(node)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        self.flatten_mapping(node)  # merge keys (``<<: *base``) first; an explicit key overrides a merged one
        seen: dict[Any, yaml.Node] = {}
        for key_node in self._explicit_keys[id(node)]:  # duplicates among the mapping's own keys
            key = self.construct_object(key_node, deep=deep)
            try:
                hash(key)
            except TypeError:
                break  # the base class reports an unhashable key
            if key in seen:
                first = seen[key].start_mark
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {_quote(key)} (first at line {first.line + 1})", key_node.start_mark
                )
            seen[key] = key_node
        return super().construct_mapping(node, deep=deep)

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        self._depth = getattr(self, "_depth", 0) + 1
        sizes: dict[int, int] = self.__dict__.setdefault("_sizes", {})  # expanded size of each composed node
        try:
            if self._depth > MAX_NESTING:
                raise yaml.composer.ComposerError(
                    None, None, f"nesting deeper than the limit of {MAX_NESTING}", self.peek_event().start_mark
                )
            mark = self.peek_event().start_mark
            if self.check_event(yaml.AliasEvent):
                node = super().compose_node(parent, index)
                if id(node) not in sizes:  # an alias of a node that contains it
                    raise yaml.composer.ComposerError(None, None, "recursive alias", mark)
                self._count(sizes[id(node)], mark)
                return node
            before = self._count(1, mark) - 1
            node = super().compose_node(parent, index)
            sizes[id(node)] = self._total - before
            return node
        finally:
            self._depth -= 1

    def _count(self, n_values: int, mark: Any) -> int:
        """Count ``n_values`` more values of the file (aliases expanded); :return: the count so far"""
        self._total: int = getattr(self, "_total", 0) + n_values
        if self._total > MAX_NODES:
            raise NodeLimitError(None, None, f"more than the limit of {MAX_NODES:,} values once aliases are expanded", mark)
        return self._total


class NodeLimitError(yaml.composer.ComposerError):
    """A scenario file holds more than :data:`MAX_NODES` values once its aliases are expanded."""


class IntegerRangeError(yaml.constructor.ConstructorError):
    """A scenario file holds an integer longer than Python converts from text (``sys.get_int_max_str_digits``)."""


_MERGE_TAG = "tag:yaml.org,2002:merge"
_INT_TAG, _FLOAT_TAG, _BOOL_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float", "tag:yaml.org,2002:bool"
# YAML 1.2 core schema numbers and booleans replace PyYAML's YAML 1.1 ones: its ints read ``010`` as octal 8,
# ``1:00`` as sexagesimal 60 and ``0b10`` as binary, its floats need a dot and a signed exponent and read ``1:30.0``
# as 5430.0, its booleans include ``yes``, ``no``, ``on``, ``off`` (a room named ``NO`` was False).
ScenarioLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag not in (_INT_TAG, _FLOAT_TAG, _BOOL_TAG)]
    for first, resolvers in yaml.resolver.Resolver.yaml_implicit_resolvers.items()
}
ScenarioLoader.add_implicit_resolver(_BOOL_TAG, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))
# Decimal (``_`` may group digits, as in the floats), ``0o`` octal and ``0x`` hexadecimal integers.
ScenarioLoader.add_implicit_resolver(
    _INT_TAG, re.compile(r"^(?:[-+]?[0-9][0-9_]*|0o[0-7]+|0x[0-9a-fA-F]+)$"), list("-+0123456789")
)
ScenarioLoader.add_implicit_resolver(
    _FLOAT_TAG,
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.VERBOSE,
    ),
    list("-+0123456789."),
)


def _construct_int(loader: ScenarioLoader, node: yaml.ScalarNode) -> int:
    """A YAML 1.2 integer: decimal (a leading 0 is no octal prefix), ``0o`` octal or ``0x`` hexadecimal."""
    text = str(loader.construct_scalar(node)).replace("_", "")
    try:
        return int(text, 0) if text.startswith(("0o", "0x")) else int(text, 10)
    except ValueError:  # a scalar tagged ``!!int`` that is not one, or longer than Python converts
        if re.fullmatch(r"[-+]?[0-9]+", text):
            raise IntegerRangeError(
                None, None, f"an integer of {len(text.lstrip('+-')):,} digits is out of range", node.start_mark
            ) from None
        raise yaml.constructor.ConstructorError(
            None, None, f"expected an integer, got {_quote(node.value)}", node.start_mark
        ) from None


ScenarioLoader.add_constructor(_INT_TAG, _construct_int)


def _read_yaml(content: bytes, source: str) -> Any:
    if len(content) > MAX_FILE_BYTES:
        raise ValueError(f"{source}: {len(content):,} bytes, more than the limit of {MAX_FILE_BYTES:,}")
    try:
        text = content.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"{source}: not a UTF-8 text file (byte {error.start}: {error.reason})") from None
    try:
        return yaml.load(text, Loader=ScenarioLoader)  # a SafeLoader subclass: builds plain data only
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None) or getattr(error, "context_mark", None)
        where = f"{source}, line {mark.line + 1}, column {mark.column + 1}" if mark is not None else source
        problem = getattr(error, "problem", None) or str(error)
        kind = "" if isinstance(error, NodeLimitError | IntegerRangeError) else "malformed YAML: "
        raise ValueError(f"{where}: {kind}{problem}") from None
    except RecursionError:
        raise ValueError(f"{source}: malformed YAML: nested too deeply") from None


def load_scenario(name_or_path: str | os.PathLike[str]) -> Scenario:
    """
    Load a scenario: a built-in name (see :func:`list_scenarios`) or the path of a YAML file.

    A string that is a built-in name is the built-in scenario, even where a file of that name exists in the
    working folder: write a path (``./small``, ``small.yaml``) or pass a ``pathlib.Path`` for the file.

    :param name_or_path: e.g. ``"mall"`` or ``"my_scenarios/office.yaml"``
    :return: the validated scenario
    :raises ValueError: unknown name, unreadable or malformed YAML (file and line), duplicate or unknown keys,
        an invalid field (its path and value) or a limit exceeded (see the module docstring)
    """
    text = os.fspath(name_or_path)
    builtins = list_scenarios()
    if text in builtins and not isinstance(name_or_path, Path):
        resource = resources.files("noma_radiomap") / "scenarios" / f"{text}.yaml"
        source = f"{text}.yaml"
        content = resource.read_bytes()
    elif os.path.isfile(text):
        source = text
        try:
            with open(text, "rb") as file:
                content = file.read(MAX_FILE_BYTES + 1)
        except OSError as error:
            raise ValueError(f"{source}: cannot read the scenario file ({error.strerror})") from None
    elif os.path.exists(text):
        kind = "a folder" if os.path.isdir(text) else "not a regular file (a FIFO, socket or device)"
        raise ValueError(f"scenario {text!r} is {kind}: give a scenario YAML file or a built-in name ({builtins})")
    else:
        raise ValueError(f"scenario {text!r}: unknown built-in name and no such file (built-in scenarios: {builtins})")
    return Scenario.from_dict(_read_yaml(content, source), source=source)
