"""Robot motion on the occupancy grid: sub-steps, wall sliding and arrival (paper Sec. IV-D; docs/MODEL.md, motion).

The room is ``[0, width) x [0, depth)``, cut into square cells of side ``resolution``
(:class:`~noma_radiomap.scenario.Room` maps points to cells). A point is *free* when it lies inside the
room and its cell does not block motion. Positions are only ever moved to free points, so a robot
never leaves the room nor stands in a blocked cell.
"""

import math
from typing import NamedTuple

import numpy as np

from noma_radiomap import geometry
from noma_radiomap.scenario import Room

_TINY = float(np.finfo(np.float64).tiny)


def clip_displacements(actions: np.ndarray, max_step: float) -> np.ndarray:
    """
    Map motion actions to displacements (docs/MODEL.md, motion): ``(dx, dy) in [-1, 1]^2`` scaled by
    ``max_step = V_max time_step``, then shortened to a norm of at most ``max_step``.

    :param actions: motion actions, shape (..., 2); clipped to [-1, 1]
    :param max_step: the longest displacement of one step, in metres
    :return: displacements in metres, shape (..., 2)
    """
    step = np.clip(actions, -1.0, 1.0) * max_step
    norm = np.sqrt((step * step).sum(axis=-1, keepdims=True))
    return step * np.minimum(1.0, max_step / np.maximum(norm, _TINY))


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

    :meth:`move` runs the sub-step loop over plain Python floats: with a handful of robots and 2-4 sub-steps it
    is several times faster than numpy calls on arrays of two elements (the env's speed budget,
    ``benchmarks/env_speed.py``). :meth:`move_batch` applies the same rules to many missions at once with
    numpy, looping over the sub-steps only (the vector env); a property test checks that both give the same
    bits.
    When the bounding box of a whole move holds no blocked cell (a summed-area table lookup), the
    collision tests are skipped: the result is the same, since no sub-step can then enter a blocked cell.

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
        self._nx, self._ny = blocked.shape
        # Nested lists: indexing them with Python ints is ~3x faster than indexing a numpy array.
        self._blocked_rows: list[list[bool]] = blocked.tolist()
        # Summed-area table: _blocked_count[i][j] = number of blocked cells with ix < i and iy < j.
        table = np.zeros((self._nx + 1, self._ny + 1), dtype=np.int64)
        table[1:, 1:] = blocked.cumsum(axis=0).cumsum(axis=1)
        self._blocked_count: list[list[int]] = table.tolist()
        self._blocked_table = table
        self._point_cell = room.point_cell
        self._n_substeps = max(1, math.ceil(self.max_step / (0.5 * self.resolution) - 1e-9))

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """
        Whether points are free (inside the room and not in a blocked cell).

        :param xy: points, shape (..., 2)
        :return: bool array of shape (...)
        """
        return self.room.contains(xy) & ~self.blocked[self.room.cell_index(xy)]

    def _cell(self, x: float, y: float) -> tuple[int, int] | None:
        """The cell of a point, or None when the point is outside the room or in a blocked cell."""
        if not (0.0 <= x < self.width and 0.0 <= y < self.depth):
            return None
        ix, iy = self._point_cell(x, y)
        return None if self._blocked_rows[ix][iy] else (ix, iy)

    def _box_clear(self, x0: float, y0: float, x1: float, y1: float) -> bool:
        """Whether the axis-aligned box spanned by two points (plus a rounding margin) is inside the room and
        holds no blocked cell (a summed-area table lookup)."""
        margin = 1e-9 * (1.0 + self.width + self.depth)
        low_x, high_x = min(x0, x1) - margin, max(x0, x1) + margin
        low_y, high_y = min(y0, y1) - margin, max(y0, y1) + margin
        if low_x < 0.0 or low_y < 0.0 or high_x >= self.width or high_y >= self.depth:
            return False
        ix0, iy0 = self._point_cell(low_x, low_y)
        ix1, iy1 = self._point_cell(high_x, high_y)
        ix1, iy1 = ix1 + 1, iy1 + 1
        table = self._blocked_count
        return table[ix1][iy1] - table[ix0][iy1] - table[ix1][iy0] + table[ix0][iy0] == 0

    def _step(self, x: float, y: float, cell: tuple[int, int], sx: float, sy: float) -> tuple[float, float, tuple[int, int]]:
        """One sub-step from the free point ``(x, y)`` in ``cell``, sliding along walls (see the class docstring)."""
        new_cell = self._cell(x + sx, y + sy)
        if new_cell is not None:
            if new_cell[0] == cell[0] or new_cell[1] == cell[1]:
                return x + sx, y + sy, new_cell
            # A diagonal cell change passes near the shared corner: both side cells must be free.
            if not (self._blocked_rows[new_cell[0]][cell[1]] or self._blocked_rows[cell[0]][new_cell[1]]):
                return x + sx, y + sy, new_cell
        # Slide along the wall: keep the component that does not enter a blocked cell.
        cell_x = self._cell(x + sx, y) if sx != 0.0 else None
        cell_y = self._cell(x, y + sy) if sy != 0.0 else None
        if cell_x is not None and (cell_y is None or abs(sx) >= abs(sy)):
            return x + sx, y, cell_x
        if cell_y is not None:
            return x, y + sy, cell_y
        return x, y, cell

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
        max_step, n_substeps = self.max_step, self._n_substeps
        radius_sq = self.arrival_radius * self.arrival_radius
        points = np.asarray(positions, dtype=float).tolist()
        moves = np.asarray(actions, dtype=float).tolist()
        active_list = [True] * len(points) if active is None else np.asarray(active, dtype=bool).tolist()
        goals = None if destinations is None else np.asarray(destinations, dtype=float).tolist()
        arrived = [False] * len(points)
        for u, (x, y) in enumerate(points):
            if active_list[u]:
                # clip_displacements() on Python floats.
                dx = min(max(moves[u][0], -1.0), 1.0) * max_step
                dy = min(max(moves[u][1], -1.0), 1.0) * max_step
                norm = math.hypot(dx, dy)
                scale = max_step / norm / n_substeps if norm > max_step else 1.0 / n_substeps
                sx, sy = dx * scale, dy * scale
                cell = self._cell(x, y)
                if cell is None:
                    raise ValueError(f"positions[{u}]: {[x, y]} is outside the room or in a blocked cell")
                # Fast path: no blocked cell and no wall in the box around the whole move -> no collision test.
                clear = self._box_clear(x, y, x + n_substeps * sx, y + n_substeps * sy)
                for _ in range(n_substeps):
                    # Products rather than ** 2 (C pow): move_batch computes the same bits with numpy.
                    if (
                        goals is not None
                        and (x - goals[u][0]) * (x - goals[u][0]) + (y - goals[u][1]) * (y - goals[u][1]) <= radius_sq
                    ):
                        break
                    if clear:
                        x, y = x + sx, y + sy
                    else:
                        x, y, cell = self._step(x, y, cell, sx, sy)
                points[u] = [x, y]
            if goals is not None:
                arrived[u] = (x - goals[u][0]) * (x - goals[u][0]) + (y - goals[u][1]) * (y - goals[u][1]) <= radius_sq
        return np.array(points, dtype=float).reshape(-1, 2), np.array(arrived, dtype=bool)

    def _free_cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_cell` on arrays: whether each point is free, and its cell indices (clipped to the grid)."""
        inside = (x >= 0.0) & (x < self.width) & (y >= 0.0) & (y < self.depth)
        ix, iy = self.room.cell_index(np.stack([x, y], axis=-1))
        return inside & ~self.blocked[ix, iy], ix, iy

    def _boxes_clear(self, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> np.ndarray:
        """:meth:`_box_clear` on arrays."""
        margin = 1e-9 * (1.0 + self.width + self.depth)
        low_x, high_x = np.minimum(x0, x1) - margin, np.maximum(x0, x1) + margin
        low_y, high_y = np.minimum(y0, y1) - margin, np.maximum(y0, y1) + margin
        inside = (low_x >= 0.0) & (low_y >= 0.0) & (high_x < self.width) & (high_y < self.depth)
        # Both corners in one cell_index call: the number of numpy calls is the cost on small batches.
        ix, iy = self.room.cell_index(np.stack([np.stack([low_x, low_y], axis=-1), np.stack([high_x, high_y], axis=-1)]))
        ix0, iy0, ix1, iy1 = ix[0], iy[0], ix[1] + 1, iy[1] + 1
        table = self._blocked_table
        return inside & (table[ix1, iy1] - table[ix0, iy1] - table[ix1, iy0] + table[ix0, iy0] == 0)

    def move_batch(
        self,
        positions: np.ndarray,
        actions: np.ndarray,
        destinations: np.ndarray,
        active: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """
        :meth:`move` for many missions at once: the same rules and the same bits, vectorised over every robot
        of every mission (a Python loop over the sub-steps only).

        :param positions: current positions, shape (..., U, 2); must be free points
        :param actions: motion actions in [-1, 1], shape (..., U, 2)
        :param destinations: destinations, shape (..., U, 2)
        :param active: which robots move, bool (..., U)
        :return: the new positions (..., U, 2) and the arrived flags (..., U), as :meth:`move`
        """
        positions = np.asarray(positions, dtype=np.float64)
        x, y = positions[..., 0].copy(), positions[..., 1].copy()
        goals = np.asarray(destinations, dtype=np.float64)
        gx, gy = goals[..., 0], goals[..., 1]
        free, ix, iy = self._free_cells(x, y)
        if not free.all():
            index = tuple(int(i) for i in np.argwhere(~free)[0])
            raise ValueError(f"positions{list(index)}: {positions[index].tolist()} is outside the room or in a blocked cell")
        max_step, n_substeps = self.max_step, self._n_substeps
        radius_sq = self.arrival_radius * self.arrival_radius
        step = np.minimum(np.maximum(np.asarray(actions, dtype=np.float64), -1.0), 1.0) * max_step
        # geometry.distance: math.hypot, as move() uses
        norm = geometry.distance(step, np.zeros(2))
        with np.errstate(divide="ignore"):
            scale = np.where(norm > max_step, max_step / norm / n_substeps, 1.0 / n_substeps)
        sx, sy = step[..., 0] * scale, step[..., 1] * scale
        clear = self._boxes_clear(x, y, x + n_substeps * sx, y + n_substeps * sy)
        moving = np.asarray(active, dtype=bool).copy()
        slide = _Slide(sx != 0.0, sy != 0.0, np.abs(sx) >= np.abs(sy))

        def within(px: np.ndarray, py: np.ndarray) -> np.ndarray:
            dx, dy = px - gx, py - gy
            return dx * dx + dy * dy <= radius_sq

        for _ in range(n_substeps):
            moving &= ~within(x, y)
            if not moving.any():
                break
            tx, ty = x + sx, y + sy
            if clear[moving].all():
                x, y = np.where(moving, tx, x), np.where(moving, ty, y)
                continue
            take_x, take_y, nix, niy = self._substep(tx, ty, ix, iy, clear, slide)
            take_x &= moving
            take_y &= moving
            x, y = np.where(take_x, tx, x), np.where(take_y, ty, y)
            ix, iy = np.where(take_x, nix, ix), np.where(take_y, niy, iy)
        return np.stack([x, y], axis=-1), within(x, y)

    def _substep(
        self, tx: np.ndarray, ty: np.ndarray, ix: np.ndarray, iy: np.ndarray, clear: np.ndarray, slide: "_Slide"
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """
        :meth:`_step` on arrays, from free points in cells ``(ix, iy)`` to the targets ``(tx, ty)``
        (``clear``: the fast path, no collision test).

        A point's cell index on one axis depends only on its coordinate on that axis, so the three points
        :meth:`_step` tests, ``(tx, ty)``, ``(tx, y)`` and ``(x, ty)``, need only the cells of ``tx`` and
        ``ty`` besides the current ones.

        :return: whether each robot takes its x and its y component, and the cells of ``tx`` and ``ty``
        """
        nix, niy = self.room.cell_index(np.stack([tx, ty], axis=-1))
        inside_x = (tx >= 0.0) & (tx < self.width)
        inside_y = (ty >= 0.0) & (ty < self.depth)
        blocked_x, blocked_y = self.blocked[nix, iy], self.blocked[ix, niy]
        free = inside_x & inside_y & ~self.blocked[nix, niy]
        straight = (nix == ix) | (niy == iy)
        direct = clear | (free & (straight | ~(blocked_x | blocked_y)))
        free_x = inside_x & ~blocked_x & slide.has_x
        free_y = inside_y & ~blocked_y & slide.has_y
        slide_x = free_x & (~free_y | slide.x_longer)
        slide_y = ~slide_x & free_y
        return direct | slide_x, direct | slide_y, nix, niy


class _Slide(NamedTuple):
    """Per robot, for the sliding rule of :meth:`GridMotion._substep`: which components are non-zero, and
    whether the x component is at least as long as the y component."""

    has_x: np.ndarray
    has_y: np.ndarray
    x_longer: np.ndarray
