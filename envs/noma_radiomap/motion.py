"""Robot motion on the occupancy grid: sub-steps, wall sliding and arrival (paper Sec. IV-D; docs/MODEL.md, motion).

The room is ``[0, width) x [0, depth)``, cut into square cells of side ``resolution``
(:class:`~noma_radiomap.scenario.Room` maps points to cells). A point is *free* when it lies inside the
room and its cell does not block motion. Positions are only ever moved to free points, so a robot
never leaves the room nor stands in a blocked cell.
"""

import math
from typing import Any

import numpy as np

from noma_radiomap import geometry
from noma_radiomap.compiled import as_rows, as_scalar, compiled
from noma_radiomap.scenario import Room


def clip_displacements(actions: np.ndarray, max_step: float) -> np.ndarray:
    """
    Map motion actions to displacements (paper Eq. (25): the amplitude of ``Delta D_u`` in ``[0, V_max]`` per step;
    docs/MODEL.md, motion): ``(dx, dy) in [-1, 1]^2`` scaled by ``max_step = V_max time_step``, then shortened to a
    norm of at most ``max_step`` (:func:`clipped_displacement` per robot, the motion kernel's own).

    :param actions: motion actions, shape (..., 2); clipped to [-1, 1]
    :param max_step: the longest displacement of one step, in metres
    :return: displacements in metres, float64 of shape (..., 2)
    :raises ValueError: ``actions`` not of shape (..., 2), a ``max_step`` array
    """
    (rows,), shape = as_rows("clip_displacements: actions", actions, last=2)
    return displacement_rows(rows, as_scalar("max_step", max_step)).reshape((*shape, 2))


@compiled
def clipped_displacement(action_x: float, action_y: float, max_step: float, n_parts: int) -> tuple[float, float]:
    """
    The displacement of one motion action (paper Eq. (25); :func:`clip_displacements`), split into ``n_parts`` equal
    parts: ``(dx, dy)`` clipped to ``[-1, 1]``, times ``max_step``, shortened to a norm (:func:`~noma_radiomap.
    geometry.hypot`) of at most ``max_step``, divided by ``n_parts`` (the sub-steps of :func:`move_robots`; 1: the
    whole displacement). Compiled, on floats; the one implementation of the clip.
    """
    dx = min(max(action_x, -1.0), 1.0) * max_step
    dy = min(max(action_y, -1.0), 1.0) * max_step
    norm = geometry.hypot(dx, dy)
    scale = max_step / norm / n_parts if norm > max_step else 1.0 / n_parts
    return dx * scale, dy * scale


@compiled
def displacement_rows(actions: np.ndarray, max_step: float) -> np.ndarray:
    """:func:`clip_displacements` of (M, 2) actions, compiled: :func:`clipped_displacement` of each row, whole."""
    displacements = np.empty(actions.shape)
    for row in range(actions.shape[0]):
        displacements[row, 0], displacements[row, 1] = clipped_displacement(actions[row, 0], actions[row, 1], max_step, 1)
    return displacements


class GridMotion:
    """
    Moves robots on a grid with sub-steps and wall sliding (the paper's "the component of action
    perpendicular to the contact surface will be cancelled", Sec. IV-D).

    A displacement is split into equal sub-steps no longer than half a cell, so that a sub-step crosses at
    most one cell boundary per axis and can never jump over a one-cell wall. A sub-step is taken
    when it ends on a free point and, if it changes both cell indices, both cells it could cut through at
    the corner are free too (no slipping between diagonally touching blocked cells). Otherwise the robot
    slides: the component perpendicular to the contact surface is cancelled for that sub-step and the
    component along it is kept (if both single-axis moves are free, at a corner, the larger one is kept).
    A robot that comes within ``arrival_radius`` of its destination stops there (it has arrived).

    One compiled kernel (:func:`move_robots`, numba) moves every robot of one mission (:meth:`move`, the
    single env) or of many (:meth:`move_batch`, the vector env): the sub-step loop of a handful of robots is
    Python-bound in numpy, and the kernel's arithmetic (``+``, ``*``, ``/`` and comparisons, no fused
    multiply-add) gives the bits of the same loop on Python floats. When the bounding box of a whole move
    holds no blocked cell (a summed-area table lookup), the collision tests are skipped: the result is the
    same, since no sub-step can then enter a blocked cell.

    :param blocked: cells that block motion, bool array of shape ``room.shape`` indexed ``[ix, iy]``
    :param room: the room and its grid
    :param max_step: the longest displacement of one step, ``V_max time_step``, in metres
    :param arrival_radius: distance to the destination at which a robot has arrived, in metres
    """

    def __init__(
        self,
        blocked: np.ndarray,
        room: Room,
        max_step: float,
        arrival_radius: float = 0.0,
    ) -> None:
        blocked = np.asarray(blocked, dtype=bool)
        if blocked.shape != room.shape:
            raise ValueError(f"blocked must have the room's grid shape {room.shape}, got shape {blocked.shape}")
        self.blocked = blocked
        self.room = room
        self.resolution = float(room.resolution)
        self.width = float(room.width)
        self.depth = float(room.depth)
        self.max_step = float(max_step)
        self.arrival_radius = float(arrival_radius)
        # Summed-area table: _blocked_table[i, j] = number of blocked cells with ix < i and iy < j.
        table = np.zeros((blocked.shape[0] + 1, blocked.shape[1] + 1), dtype=np.int64)
        table[1:, 1:] = blocked.cumsum(axis=0).cumsum(axis=1)
        self._blocked_table = table
        self._n_substeps = max(1, math.ceil(self.max_step / (0.5 * self.resolution) - 1e-9))
        #: Take the collision-free fast path when a move's box is clear (False: always test; for tests).
        self._fast_path = True

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """
        Whether points are free (inside the room and not in a blocked cell).

        :param xy: points, shape (..., 2)
        :return: bool array of shape (...)
        """
        return self.room.contains(xy) & ~self.blocked[self.room.cell_index(xy)]

    def move(
        self,
        positions: np.ndarray,
        actions: np.ndarray,
        destinations: np.ndarray | None = None,
        active: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """
        Move every active robot by one step.

        :param positions: current positions, shape (U, 2); must be free points
        :param actions: motion actions in [-1, 1], shape (U, 2) (see :func:`clip_displacements`)
        :param destinations: destinations, shape (U, 2); None disables the arrival check
        :param active: which robots move, bool array of shape (U,) (arrived robots stay); None: all
        :return: the new positions (U, 2) and, per robot, whether it is within ``arrival_radius`` of its
            destination at the end of the step (all False when ``destinations`` is None)
        """
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        return self.move_batch(
            positions, actions, destinations, np.ones(len(positions), dtype=bool) if active is None else active
        )

    def move_batch(
        self,
        positions: np.ndarray,
        actions: np.ndarray,
        destinations: np.ndarray | None,
        active: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`move` for many missions at once (the vector env).

        :param positions: current positions, shape (..., U, 2); must be free points
        :param actions: motion actions in [-1, 1], shape (..., U, 2)
        :param destinations: destinations, shape (..., U, 2); None disables the arrival check
        :param active: which robots move, bool (..., U)
        :return: the new positions (..., U, 2) and the arrived flags (..., U), as :meth:`move`
        """
        positions = np.asarray(positions, dtype=np.float64)
        actions = np.asarray(actions, dtype=np.float64)
        goals = positions if destinations is None else np.asarray(destinations, dtype=np.float64)
        active = np.asarray(active, dtype=bool)
        shape = positions.shape[:-1]
        # The kernel does not check bounds: the shapes must agree exactly.
        if (
            positions.shape[-1:] != (2,)
            or actions.shape != positions.shape
            or goals.shape != positions.shape
            or active.shape != shape
        ):
            raise ValueError(
                f"positions {positions.shape} must be points (..., 2); actions {actions.shape} and destinations "
                f"{goals.shape} must have their shape, active {active.shape} the shape of their robots {shape}"
            )
        new, arrived, bad = move_robots(
            positions.reshape(-1, 2),
            actions.reshape(-1, 2),
            goals.reshape(-1, 2),
            active.reshape(-1),
            destinations is not None,
            *self.kernel_constants(),
        )
        if bad >= 0:
            raise self.position_error(positions, bad)
        return new.reshape(*shape, 2), arrived.reshape(shape)

    def kernel_constants(self) -> tuple[Any, ...]:
        """The arguments of :func:`move_robots` after the robots' own: the grid and the motion's constants."""
        return (
            self.blocked,
            self._blocked_table,
            self.width,
            self.depth,
            self.resolution,
            self.max_step,
            self._n_substeps,
            self.arrival_radius * self.arrival_radius,
            self._fast_path,
        )

    @staticmethod
    def position_error(positions: np.ndarray, bad: int) -> ValueError:
        """The error for robots of which one, the ``bad``-th (flat index), is not on a free point."""
        index = [int(i) for i in np.unravel_index(bad, positions.shape[:-1])]
        return ValueError(f"positions{index}: {positions[tuple(index)].tolist()} is outside the room or in a blocked cell")


@compiled
def move_robots(
    positions: np.ndarray,
    actions: np.ndarray,
    goals: np.ndarray,
    active: np.ndarray,
    has_goals: bool,
    blocked: np.ndarray,
    table: np.ndarray,
    width: float,
    depth: float,
    resolution: float,
    max_step: float,
    n_substeps: int,
    radius_sq: float,
    fast_path: bool,
) -> tuple[np.ndarray, np.ndarray, int]:
    """
    The rules of :class:`GridMotion` on every robot (rows): motion ``actions`` (M, 2) from free ``positions``
    (M, 2), the displacement of paper Eq. (25) (:func:`clipped_displacement`, in sub-steps) with the wall sliding
    of its Sec. IV-D, keeping every robot on the floor's free cells and inside the room (the constraints (15b) and
    (15d) of the paper's problem (15)). Returns the new positions, the arrived flags, and the first row whose
    position is not free (-1: none; nothing is moved then).
    """
    nx, ny = blocked.shape
    margin = 1e-9 * (1.0 + width + depth)
    new = positions.copy()
    arrived = np.zeros(len(positions), dtype=np.bool_)
    for row in range(len(positions)):
        x, y = positions[row, 0], positions[row, 1]
        if not (0.0 <= x < width and 0.0 <= y < depth):
            return positions, arrived, row
        ix, iy = geometry.axis_cell(x, resolution, nx), geometry.axis_cell(y, resolution, ny)
        if blocked[ix, iy]:
            return positions, arrived, row
    for row in range(len(positions)):
        x, y = positions[row, 0], positions[row, 1]
        gx, gy = goals[row, 0], goals[row, 1]
        if active[row]:
            sx, sy = clipped_displacement(actions[row, 0], actions[row, 1], max_step, n_substeps)
            ix, iy = geometry.axis_cell(x, resolution, nx), geometry.axis_cell(y, resolution, ny)
            # Fast path: no blocked cell and no wall in the box around the whole move -> no collision test.
            end_x, end_y = x + n_substeps * sx, y + n_substeps * sy
            low_x, high_x = min(x, end_x) - margin, max(x, end_x) + margin
            low_y, high_y = min(y, end_y) - margin, max(y, end_y) + margin
            clear = False
            if fast_path and low_x >= 0.0 and low_y >= 0.0 and high_x < width and high_y < depth:
                ix0, iy0 = geometry.axis_cell(low_x, resolution, nx), geometry.axis_cell(low_y, resolution, ny)
                ix1 = geometry.axis_cell(high_x, resolution, nx) + 1
                iy1 = geometry.axis_cell(high_y, resolution, ny) + 1
                clear = table[ix1, iy1] - table[ix0, iy1] - table[ix1, iy0] + table[ix0, iy0] == 0
            for _ in range(n_substeps):
                if has_goals and (x - gx) * (x - gx) + (y - gy) * (y - gy) <= radius_sq:
                    break
                tx, ty = x + sx, y + sy
                if clear:
                    x, y = tx, ty
                    continue
                inside_x, inside_y = 0.0 <= tx < width, 0.0 <= ty < depth
                nix = geometry.axis_cell(tx, resolution, nx) if inside_x else -1
                niy = geometry.axis_cell(ty, resolution, ny) if inside_y else -1
                if inside_x and inside_y and not blocked[nix, niy]:
                    # A diagonal cell change passes near the shared corner: both side cells must be free.
                    if nix == ix or niy == iy or not (blocked[nix, iy] or blocked[ix, niy]):
                        x, y, ix, iy = tx, ty, nix, niy
                        continue
                # Slide along the wall: keep the component that does not enter a blocked cell.
                free_x = sx != 0.0 and inside_x and not blocked[nix, iy]
                free_y = sy != 0.0 and inside_y and not blocked[ix, niy]
                if free_x and (not free_y or abs(sx) >= abs(sy)):
                    x, ix = tx, nix
                elif free_y:
                    y, iy = ty, niy
            new[row, 0], new[row, 1] = x, y
        arrived[row] = has_goals and (x - gx) * (x - gx) + (y - gy) * (y - gy) <= radius_sq
    return new, arrived, -1
