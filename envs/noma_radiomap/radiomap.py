"""The radio map of a scenario (the paper's Section III, Eq. (16)-(19)): path-loss, power and SINR maps.

All maps have shape ``(nx, ny)``, are indexed ``[ix, iy]`` and hold values at the cell centres at
the robots' antenna height. Every link uses the expected Rayleigh fading
(:data:`~noma_radiomap.propagation.EXPECTED_FADING_DB`), so the maps are the statistical channel
the paper trains on (its Eq. (17)).
"""

from __future__ import annotations

import functools
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from noma_radiomap import geometry
from noma_radiomap.downlink import in_outage, shannon_rate, signal_band
from noma_radiomap.propagation import (
    EXPECTED_FADING_DB,
    db_to_linear,
    dbm_to_watt,
    expected_channel_gain,
    interference_power,
    noise_power_dbm,
    path_gain,
    path_loss_db,
    watt_to_dbm,
)
from noma_radiomap.scenario import Scenario

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


#: Largest estimated memory of a scenario's radio map and the env's tables (:func:`estimated_memory`), and of the
#: missions of a vector env (:func:`check_missions_memory`), in bytes; a scenario or a number of missions that needs
#: more is refused before anything is allocated. Override it by setting this attribute, or the environment variable
#: ``NOMA_RADIOMAP_MAX_MEMORY_BYTES``.
MAX_MEMORY_BYTES = 2**30
_MEMORY_VARIABLE = "NOMA_RADIOMAP_MAX_MEMORY_BYTES"
#: float64 arrays of one value per cell that a radio map holds or builds (the layout heights, the cell centres
#: and the receivers' 3-D positions, the power, SINR and interference maps), per transmitter (obstacle counts,
#: path loss, gains in dB, linear path gain and expected gain, the distances) and, in the env, per transmitter
#: twice (its gain table and that table's transposed copy), plus one per interferer (their stacked gains).
_PER_CELL, _PER_CELL_TRANSMITTER, _PER_CELL_TABLE = 10, 6, 2
#: Memory of one mission of a vector env, in bytes (measured: its own random generator, about 2 KB, and its arrays)
_PER_MISSION = 2_400
#: Bytes per start cell per destination of a robot in the env's mission sampler
#: (:class:`noma_radiomap.sampling.MissionSampler`: the float64 centres of its free start cells far enough from each
#: destination), and per start cell of the largest start region while the sampler is built (the cells, their centres
#: and distances)
_PER_START_CELL, _PER_START_CELL_BUILD = 16, 48
#: Distance fields (one per destination cell, float64 per cell) that the radio map caches for ``inducing="geodesic"``
_CACHED_DISTANCE_FIELDS = 64


def estimated_memory(scenario: Scenario) -> dict[str, int]:
    """
    The memory a scenario's radio map and the env's gain tables take, estimated from its size alone (nothing is
    allocated): ``cells x transmitters x 8 bytes x`` the number of arrays of each kind, plus the buffers of the
    chunked occlusion test (:data:`noma_radiomap.geometry.CHUNK_PAIRS`).

    The env's mission sampler counts too: per robot, the centres of the cells of its start region, once per
    destination (:class:`noma_radiomap.sampling.MissionSampler`), counted from the regions' sizes
    (:func:`~noma_radiomap.geometry.region_size`, blocked cells included: an upper bound).

    :param scenario: the scenario
    :return: ``cells``, ``transmitters``, ``boxes``, ``start_cells`` (start cells x destinations, summed over the
        robots) and the estimate in bytes: ``maps``, ``tables``, ``occlusion``, ``starts`` and their ``total``
    """
    room = scenario.room
    cells = room.nx * room.ny
    transmitters = 1 + len(scenario.interferers)
    boxes = sum(len(obstacle.boxes) for obstacle in scenario.obstacles)
    maps = 8 * cells * (_PER_CELL + _PER_CELL_TRANSMITTER * transmitters + (transmitters - 1))
    tables = 8 * cells * _PER_CELL_TABLE * transmitters
    rows = min(cells, max(1, geometry.CHUNK_PAIRS // max(boxes, 1)))
    occlusion = 8 * 8 * rows * boxes  # ~8 float64 arrays per segment-box pair of a chunk
    regions = [geometry.region_size(robot.start, room.resolution, room.shape) for robot in scenario.robots]
    start_cells = sum(k * len(robot.destinations) for k, robot in zip(regions, scenario.robots, strict=True))
    starts = _PER_START_CELL * start_cells + _PER_START_CELL_BUILD * max(regions, default=0)
    total = maps + tables + occlusion + starts
    return {
        "cells": cells,
        "transmitters": transmitters,
        "boxes": boxes,
        "start_cells": start_cells,
        "maps": maps,
        "tables": tables,
        "occlusion": occlusion,
        "starts": starts,
        "total": total,
    }


def memory_cap() -> int:
    """:return: the cap in bytes, :data:`MAX_MEMORY_BYTES` or ``NOMA_RADIOMAP_MAX_MEMORY_BYTES`` when set"""
    text = os.environ.get(_MEMORY_VARIABLE)
    name, given = (
        (_MEMORY_VARIABLE, text) if text is not None else ("noma_radiomap.radiomap.MAX_MEMORY_BYTES", MAX_MEMORY_BYTES)
    )
    try:
        value = -1 if isinstance(given, bool) else int(float(given))
    except (TypeError, ValueError, OverflowError):  # not a number, NaN; inf and 1e400 (float("1e400") is inf)
        value = -1
    if value <= 0:
        shown = given[:40] if isinstance(given, str) else given
        raise ValueError(f"{name}: expected a positive number of bytes, got {shown!r}")
    return value


def check_memory(scenario: Scenario) -> None:
    """
    :param scenario: the scenario
    :raises ValueError: its :func:`estimated_memory` exceeds :func:`memory_cap`, naming the numbers
    """
    estimate, cap = estimated_memory(scenario), memory_cap()
    if estimate["total"] <= cap:
        return
    parts = (
        f"({_size(estimate['maps'])} of maps, {_size(estimate['tables'])} of gain tables, "
        f"{_size(estimate['occlusion'])} of occlusion buffers, {_size(estimate['starts'])} of start-cell tables)"
    )
    raise_cap = f"or raise the cap ({_MEMORY_VARIABLE} or noma_radiomap.radiomap.MAX_MEMORY_BYTES)"
    if 2 * estimate["starts"] > estimate["total"]:  # the robots' start regions, not the grid, take most of it
        raise ValueError(
            f"robots: {scenario.n_robots:,} robots' start regions x destinations ({estimate['start_cells']:,} start "
            f"cells x destinations in all, on the {scenario.room.resolution!r} m grid) need about "
            f"{_size(estimate['total'])} for the radio map and the env's tables {parts}, more than the cap of "
            f"{_size(cap)}; use smaller robots[k].start regions, fewer destinations or a coarser room.resolution, "
            f"{raise_cap}"
        )
    raise ValueError(
        f"room.resolution, interferers: {estimate['cells']:,} cells x {estimate['transmitters']} transmitters "
        f"(the AP and {estimate['transmitters'] - 1} interferers) need about {_size(estimate['total'])} for the "
        f"radio map and the env's tables {parts}, more than the cap of {_size(cap)}; use a coarser room.resolution "
        f"or fewer interferers, {raise_cap}"
    )


def missions_memory(n_missions: int, scenario: Scenario | None = None, inducing: str = "euclidean") -> dict[str, int]:
    """
    The memory the missions of an env take, estimated from their number and the scenario's size (nothing is
    allocated): each its own random generator and arrays and, with ``inducing="geodesic"``, a distance table per
    robot (float64 per cell, allocated at the first reset) and the radio map's cached distance fields (one per
    destination cell, at most :data:`_CACHED_DISTANCE_FIELDS`).

    :param n_missions: the missions (``num_envs``; 1 for a single env)
    :param scenario: the scenario (None: the per-mission part only)
    :param inducing: the env's ``inducing``
    :return: ``missions`` (generators and arrays), ``distances`` (the geodesic tables) and their ``total``, in bytes
    """
    missions, distances = n_missions * _PER_MISSION, 0
    if scenario is not None and inducing == "geodesic":
        cells = scenario.room.nx * scenario.room.ny
        fields = min(_CACHED_DISTANCE_FIELDS, sum(len(robot.destinations) for robot in scenario.robots))
        distances = 8 * cells * (n_missions * scenario.n_robots + fields)
    return {"missions": missions, "distances": distances, "total": missions + distances}


def check_missions_memory(n_missions: int, scenario: Scenario | None = None, inducing: str = "euclidean") -> None:
    """
    :param n_missions: the missions of a vector env (``num_envs``; 1 for a single env)
    :param scenario: the scenario (None: the per-mission part only)
    :param inducing: the env's ``inducing`` (``"geodesic"``: per-mission distance tables)
    :raises ValueError: they need more than :func:`memory_cap` (:func:`missions_memory`), naming the numbers
    """
    need, cap = missions_memory(n_missions, scenario, inducing), memory_cap()
    if need["total"] <= cap:
        return
    raise_cap = f"or raise the cap ({_MEMORY_VARIABLE} or noma_radiomap.radiomap.MAX_MEMORY_BYTES)"
    if not need["distances"]:
        raise ValueError(
            f"num_envs: {n_missions:,} missions need about {_size(need['total'])} (each its own random generator and "
            f"arrays), more than the cap of {_size(cap)}; use fewer missions, {raise_cap}"
        )
    assert scenario is not None
    cells = scenario.room.nx * scenario.room.ny
    raise ValueError(
        f"num_envs, inducing: {n_missions:,} missions need about {_size(need['total'])} with inducing='geodesic' "
        f"({_size(need['distances'])} of distance tables: {scenario.n_robots:,} robots x {cells:,} cells x 8 bytes "
        f"per mission, {_size(need['missions'])} of random generators and arrays), more than the cap of "
        f"{_size(cap)}; use fewer missions, inducing='euclidean' or a coarser room.resolution, {raise_cap}"
    )


def _size(n_bytes: int) -> str:
    return f"{n_bytes / 2**30:.2f} GiB" if n_bytes >= 2**30 else f"{n_bytes / 2**20:.1f} MiB"


def antenna_distance(transmitter_xyz: np.ndarray, receivers_xyz: np.ndarray) -> np.ndarray:
    """
    Distance from a transmitter's antenna to receivers' antennas (paper Eq. (18)),
    ``d = sqrt(h_m^2 + (x - x_m)^2 + (y - y_m)^2)`` with ``h_m`` their height difference (docs/MODEL.md: the
    path loss clips it to ``d >= 1 m``).

    :param transmitter_xyz: the transmitter's antenna ``(x, y, z)`` in metres
    :param receivers_xyz: the receivers' antennas, (..., 3) in metres
    :return: the distances in metres, shape (...)
    """
    return np.linalg.norm(np.asarray(receivers_xyz) - np.asarray(transmitter_xyz), axis=-1)


class RadioMap:
    """
    Radio map of a scenario, built once (use :meth:`for_scenario` for the shared, cached instance).

    Attributes (arrays of shape ``(nx, ny)``, indexed ``[ix, iy]``):

    - ``blocked``: cells that block motion (docs/MODEL.md, geometry);
    - ``bottom``, ``top``: the paper's layout height matrices (:func:`~noma_radiomap.geometry.height_matrices`);
    - ``n_obstacles[name]``: distinct obstacles crossed from transmitter ``name`` (``"ap"`` or an
      interferer's name) to each cell;
    - ``path_loss_db[name]``: path loss (paper Eq. (1)-(3)) from each transmitter, at the distance of Eq. (18)
      (:func:`antenna_distance`);
    - ``path_gain[name]``: linear path gain without fading, ``10^(-path_loss_db / 10)`` (the Rayleigh
      channel multiplies it by ``|h|^2`` every step);
    - ``gain[name]``: linear channel gain with the expected fading
      (:func:`~noma_radiomap.propagation.expected_channel_gain`, paper Eq. (17)): the radio-map channel;
    - ``gain_db[name]``: the same in dB, ``-path_loss_db + EXPECTED_FADING_DB``;
    - ``interference_w``: total power received from all interferers in watts, on the radio-map channel
      (:func:`~noma_radiomap.propagation.interference_power`);
    - ``power_map_dbm``: power received from the AP at full power ``P_max`` (paper Fig. 4a);
    - ``sinr_map_db``: single-robot SINR with the AP at full power and all interferers on (paper
      Fig. 4b), ``SINR = P_AP g_AP / (sum_i P_i g_i + N0 W)``, ``W = U x B`` the NOMA cluster bandwidth
      over which the interferers spread their power and the noise ``N0 W`` (docs/MODEL.md explains why
      this replaces the paper's Eq. (19)).

    :param scenario: the scenario
    :raises ValueError: the scenario would need more memory than :data:`MAX_MEMORY_BYTES` (:func:`check_memory`)
    """

    def __init__(self, scenario: Scenario) -> None:
        check_memory(scenario)  # before anything is allocated
        self.scenario = scenario
        room = scenario.room
        self.resolution = room.resolution
        self.shape = (room.nx, room.ny)
        self.nx, self.ny = self.shape
        boxes, self.box_owner = scenario.boxes_array()
        #: The snapped (Lego) boxes used for occlusion, (n_boxes, 6).
        self.boxes = geometry.snapped_boxes_m(boxes, room.resolution, self.shape)
        self.blocked = geometry.occupancy_grid(boxes, room.width, room.depth, room.resolution, scenario.robot.body_height)
        self.bottom, self.top = geometry.height_matrices(boxes, room.width, room.depth, room.resolution)
        #: Cell centres, (nx, ny, 2).
        self.centers = room.cell_center(*np.meshgrid(np.arange(self.nx), np.arange(self.ny), indexing="ij"))
        receivers = np.concatenate(
            [self.centers.reshape(-1, 2), np.full((self.nx * self.ny, 1), scenario.robot.antenna_height)], axis=1
        )

        self.transmitters: dict[str, tuple[np.ndarray, float]] = {
            "ap": (np.asarray(scenario.ap.position), scenario.ap.max_power_dbm)
        }
        for interferer in scenario.interferers:
            self.transmitters[interferer.name] = (np.asarray(interferer.position), interferer.power_dbm)

        radio = scenario.radio
        self.n_obstacles: dict[str, np.ndarray] = {}
        self.path_loss_db: dict[str, np.ndarray] = {}
        self.gain_db: dict[str, np.ndarray] = {}
        self.path_gain: dict[str, np.ndarray] = {}
        self.gain: dict[str, np.ndarray] = {}
        for name, (position, _) in self.transmitters.items():
            counts = geometry.count_obstacles(position, receivers, self.boxes, self.box_owner)
            distance = antenna_distance(position, receivers)
            loss = path_loss_db(
                distance,
                counts,
                frequency_mhz=radio.frequency_mhz,
                nlos_distance_coefficient=radio.nlos_distance_coefficient,
                wall_loss_db=radio.wall_loss_db,
                wall_loss_step_db=radio.wall_loss_step_db,
            )
            self.n_obstacles[name] = counts.reshape(self.shape)
            self.path_loss_db[name] = loss.reshape(self.shape)
            self.gain_db[name] = -self.path_loss_db[name] + EXPECTED_FADING_DB
            self.path_gain[name] = path_gain(self.path_loss_db[name])
            self.gain[name] = expected_channel_gain(self.path_loss_db[name])

        #: Cluster bandwidth ``W = U x B`` (Hz, the NOMA band of :func:`~noma_radiomap.downlink.signal_band`) and
        #: the noise power over it (dBm, from the noise density in dBm/Hz: the map's dB scale).
        self.bandwidth_hz = signal_band(scenario.n_robots, radio.bandwidth_per_robot_hz, True)
        self.noise_dbm = float(noise_power_dbm(radio.noise_dbm_per_hz, self.bandwidth_hz))
        self.power_map_dbm = scenario.ap.max_power_dbm + self.gain_db["ap"]
        names = [i.name for i in scenario.interferers]
        interferer_gains = np.stack([self.gain[n] for n in names], axis=-1) if names else np.zeros((*self.shape, 0))
        interferer_power_w = dbm_to_watt(np.array([i.power_dbm for i in scenario.interferers], dtype=np.float64))
        self.interference_w = interference_power(interferer_gains, interferer_power_w)
        self.sinr_map_db = self.power_map_dbm - watt_to_dbm(self.interference_w + dbm_to_watt(self.noise_dbm))
        for array in (self.blocked, self.bottom, self.top, self.power_map_dbm, self.sinr_map_db, self.interference_w):
            array.setflags(write=False)
        for mapping in (self.n_obstacles, self.path_loss_db, self.gain_db, self.path_gain, self.gain):
            for array in mapping.values():
                array.setflags(write=False)

    @classmethod
    def for_scenario(cls, scenario: Scenario) -> RadioMap:
        """
        The shared radio map of a scenario, built on first use and cached by the scenario's content
        (equal scenarios share one map; the arrays are read-only).

        :param scenario: the scenario
        :return: the cached radio map
        """
        return _cached_radio_map(scenario)

    # ----------------------------------------------------------------------------------------------
    # Derived maps
    # ----------------------------------------------------------------------------------------------

    def rate_map_bps(self) -> np.ndarray:
        """
        Single-robot rate with the whole AP power: ``W log2(1 + SINR)`` over the cluster bandwidth ``W``.

        :return: float (nx, ny)
        """
        return shannon_rate(db_to_linear(self.sinr_map_db), self.bandwidth_hz)

    def outage_map(self) -> np.ndarray:
        """
        Cells where a single robot given the whole AP power fails the QoS:
        ``W log2(1 + SINR) < qos_rate_bps`` (:func:`~noma_radiomap.downlink.in_outage`). Computed for every
        cell, blocked or not.

        :return: bool (nx, ny)
        """
        return in_outage(self.rate_map_bps(), self.scenario.radio.qos_rate_bps)

    def outage_share(self) -> float:
        """
        Fraction of the free cells in :meth:`outage_map` (docs/SCENARIOS.md: 15-60 % for ``mall``).

        :return: a number in [0, 1]
        """
        return float(self.outage_map()[~self.blocked].mean())

    # ----------------------------------------------------------------------------------------------
    # Indexing and geometry helpers
    # ----------------------------------------------------------------------------------------------

    def cell_index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Cell indices of positions (:meth:`Room.cell_index <noma_radiomap.scenario.Room.cell_index>`).

        :param xy: (..., 2) positions in metres
        :return: ``(ix, iy)``, int arrays of shape (...)
        """
        return self.scenario.room.cell_index(xy)

    def cell_center(self, ix: np.ndarray | int, iy: np.ndarray | int) -> np.ndarray:
        """
        Centres of cells (:meth:`Room.cell_center <noma_radiomap.scenario.Room.cell_center>`).

        :param ix: cell index/indices along x
        :param iy: cell index/indices along y
        :return: (..., 2) positions in metres
        """
        return self.scenario.room.cell_center(ix, iy)

    def obstacles_crossed(self, tx_xyz: np.ndarray, rx_xyz: np.ndarray) -> int:
        """
        Number of distinct obstacles the segment from ``tx_xyz`` to ``rx_xyz`` crosses (paper Sec. III-C).

        :param tx_xyz: transmitter antenna position ``(x, y, z)``
        :param rx_xyz: receiver antenna position ``(x, y, z)``
        :return: obstacle count (0 = LoS)
        """
        return int(
            geometry.count_obstacles(
                np.asarray(tx_xyz, dtype=np.float64), np.asarray(rx_xyz, dtype=np.float64), self.boxes, self.box_owner
            )[0]
        )

    def start_cells(self, robot: int) -> np.ndarray:
        """
        Free cells of a robot's start region (starts are drawn uniformly from them).

        :param robot: robot index
        :return: int (k, 2) cells ``[ix, iy]``, k >= 1
        """
        cells = geometry.region_cells(self.scenario.robots[robot].start, self.resolution, self.shape)
        return cells[~self.blocked[cells[:, 0], cells[:, 1]]]

    def distance_field(self, goal_xy: np.ndarray, cost: np.ndarray | None = None) -> np.ndarray:
        """
        Geodesic distance (m) from every cell to the cell of ``goal_xy`` (8-connected grid, no corner
        cutting; ``inf`` on blocked/unreachable cells). Cached per goal cell when ``cost`` is None.

        :param goal_xy: goal position ``(x, y)`` in metres
        :param cost: optional extra cost per metre per cell (see :func:`~noma_radiomap.geometry.grid_graph`)
        :return: float (nx, ny), read-only when cached
        """
        ix, iy = self.cell_index(np.asarray(goal_xy, dtype=np.float64))
        if cost is not None:
            return geometry.grid_distance_field(self.blocked, (int(ix), int(iy)), self.resolution, cost)
        return self._distance_field_cached(int(ix), int(iy))

    @functools.lru_cache(maxsize=64)  # noqa: B019 - the map lives as long as its cache entry anyway
    def _distance_field_cached(self, ix: int, iy: int) -> np.ndarray:
        field = geometry.grid_distance_field(self.blocked, (ix, iy), self.resolution)
        field.setflags(write=False)
        return field

    # ----------------------------------------------------------------------------------------------
    # Plotting (paper Fig. 4): noma_radiomap.rendering, imported (with matplotlib) on the first plot
    # ----------------------------------------------------------------------------------------------

    def plot(
        self,
        ax: Axes | None = None,
        kind: str = "sinr",
        show_obstacles: bool = True,
        show_transmitters: bool = True,
        show_outage: bool = True,
        colorbar: bool = True,
        legend: bool = True,
        **imshow_kwargs: Any,
    ) -> Axes:
        """
        Draw a map as a heat map with obstacle footprints outlined (solid: blocks motion; dashed:
        hanging, robots pass under it but it blocks rays; whole-room slabs are not drawn), the outage
        region hatched in red and the AP and interferers marked. Every marker and line style is labelled,
        so ``ax.get_legend_handles_labels()`` returns them for a legend of the caller's own.

        Interferers outside the room are drawn where they are: the axes are extended to them (the area
        outside the room is grey), unless one is farther than a fifth of the room's size from the walls;
        such a one is drawn at the nearest wall with an arrow pointing to it and its distance.

        :param ax: axes to draw on (a new figure when None)
        :param kind: ``"sinr"`` (dB) or ``"power"`` (received AP power, dBm)
        :param show_obstacles: outline the obstacles
        :param show_transmitters: mark the AP and the interferers
        :param show_outage: on the SINR map, hatch the outage region of :meth:`outage_map` (red)
        :param colorbar: add a colour bar
        :param legend: add a legend below the axes (off the map)
        :param imshow_kwargs: passed to ``ax.imshow`` (e.g. ``cmap``, ``vmin``, ``vmax``)
        :return: the axes
        """
        from noma_radiomap.rendering import plot_radio_map

        return plot_radio_map(
            self,
            ax,
            kind=kind,
            show_obstacles=show_obstacles,
            show_transmitters=show_transmitters,
            show_outage=show_outage,
            colorbar=colorbar,
            legend=legend,
            **imshow_kwargs,
        )

    def plot_maps(self, path: str | None = None, dpi: int = 120) -> Figure:
        """
        The paper's Fig. 4: the power distribution map and the SINR map side by side, with one legend below.

        :param path: if given, save the figure there (PNG by extension)
        :param dpi: resolution of the saved figure
        :return: the figure
        """
        from noma_radiomap.rendering import plot_radio_maps

        return plot_radio_maps(self, path, dpi)

    def __repr__(self) -> str:
        return f"RadioMap(scenario={self.scenario.name!r}, shape={self.shape}, transmitters={list(self.transmitters)})"


@functools.lru_cache(maxsize=16)
def _cached_radio_map(scenario: Scenario) -> RadioMap:
    return RadioMap(scenario)
