"""Geometry of the "Lego" room (paper Sec. III-B, III-C): snapping, occupancy, height matrices, occlusion, grid paths.

Conventions
-----------
- Grids have shape ``(nx, ny)`` and are indexed ``[ix, iy]``; cell ``ix`` spans
  ``x in [ix * res, (ix + 1) * res)``, its centre is at ``(ix + 0.5) * res``.
- **Snapping rule.** A box ``[x0, y0, x1, y1, z_bottom, z_top]`` snaps to the grid by rounding each
  of its x/y edges to the nearest grid line (half up); a box thinner than a cell along an axis
  (both edges round to the same line) keeps the one cell that contains its centre, so a thin wall
  always occupies (and blocks) a full row of cells. Heights are not snapped. The snapped boxes
  are the paper's Lego bricks: both occupancy and occlusion use them, so what blocks motion and
  what blocks rays agree.
- A cell **blocks motion** when any snapped box covering it has ``z_bottom < body_height``
  (hanging objects do not block motion, but do block rays).
- **Occlusion** counts the distinct obstacles (objects, not boxes) whose boxes the 3D segment from
  transmitter to receiver crosses, by the slab (ray-AABB) test (Majercik et al., 2018, cited by the
  paper). A segment that only grazes a box face does not cross it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import csgraph

from noma_radiomap.compiled import compiled

#: Upper bound on the number of ray-box pairs evaluated at once (bounds memory: ~8 float64 arrays of
#: this many elements are alive at a time, i.e. ~64 MB).
CHUNK_PAIRS: int = 1_000_000


def grid_shape(width: float, depth: float, resolution: float) -> tuple[int, int]:
    """
    Grid shape of a room.

    :param width: room extent along x (m)
    :param depth: room extent along y (m)
    :param resolution: cell size (m)
    :return: ``(nx, ny)``
    """
    return round(width / resolution), round(depth / resolution)


def snap_boxes(boxes: np.ndarray, resolution: float, shape: tuple[int, int]) -> np.ndarray:
    """
    Snap boxes to the grid (rule in the module docstring).

    :param boxes: (n, 6) ``[x0, y0, x1, y1, z_bottom, z_top]`` in metres
    :param resolution: cell size (m)
    :param shape: grid shape ``(nx, ny)``
    :return: (n, 4) int cell ranges ``[ix0, iy0, ix1, iy1]`` (end exclusive), each at least one cell wide
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    limits = np.array([shape[0], shape[1]])
    # The small epsilon keeps edges that sit exactly on a grid line from rounding down through
    # floating-point error (e.g. 20.3 / 0.1 = 202.99999...).
    lo = np.floor(boxes[:, 0:2] / resolution + 0.5 + 1e-9).astype(np.int64)
    hi = np.floor(boxes[:, 2:4] / resolution + 0.5 + 1e-9).astype(np.int64)
    centre = np.floor((boxes[:, 0:2] + boxes[:, 2:4]) / (2.0 * resolution)).astype(np.int64)
    thin = hi <= lo
    lo = np.where(thin, centre, lo)
    hi = np.where(thin, centre + 1, hi)
    lo = np.clip(lo, 0, limits - 1)
    hi = np.clip(hi, lo + 1, limits)
    return np.concatenate([lo, hi], axis=1)


def snapped_boxes_m(boxes: np.ndarray, resolution: float, shape: tuple[int, int]) -> np.ndarray:
    """
    The snapped boxes back in metres (the Lego bricks used for occlusion).

    :param boxes: (n, 6) boxes in metres
    :param resolution: cell size (m)
    :param shape: grid shape ``(nx, ny)``
    :return: (n, 6) snapped boxes ``[x0, y0, x1, y1, z_bottom, z_top]``
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    cells = snap_boxes(boxes, resolution, shape)
    return np.concatenate([cells * resolution, boxes[:, 4:6]], axis=1)


def occupancy_grid(boxes: np.ndarray, width: float, depth: float, resolution: float, body_height: float) -> np.ndarray:
    """
    Cells that block motion: covered by a snapped box whose bottom is below the robot's body height.

    :param boxes: (n, 6) boxes in metres
    :param width: room extent along x (m)
    :param depth: room extent along y (m)
    :param resolution: cell size (m)
    :param body_height: robot body height (m)
    :return: bool (nx, ny)
    """
    shape = grid_shape(width, depth, resolution)
    blocked = np.zeros(shape, dtype=bool)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    for (ix0, iy0, ix1, iy1), z_bottom in zip(snap_boxes(boxes, resolution, shape), boxes[:, 4], strict=True):
        if z_bottom < body_height:
            blocked[ix0:ix1, iy0:iy1] = True
    return blocked


def height_matrices(boxes: np.ndarray, width: float, depth: float, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """
    The paper's layout matrices ``L_bottom`` and ``L_top`` (Eq. (16), Section III-B): per cell, the lowest
    bottom and the highest top of the stack of snapped boxes covering it (0 where the cell is empty).
    They summarise the layout; the 3D boxes remain the source of truth.

    :param boxes: (n, 6) boxes in metres
    :param width: room extent along x (m)
    :param depth: room extent along y (m)
    :param resolution: cell size (m)
    :return: ``(bottom, top)``, float (nx, ny) each
    """
    shape = grid_shape(width, depth, resolution)
    bottom = np.full(shape, np.inf)
    top = np.zeros(shape)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    for (ix0, iy0, ix1, iy1), (z_bottom, z_top) in zip(snap_boxes(boxes, resolution, shape), boxes[:, 4:6], strict=True):
        bottom[ix0:ix1, iy0:iy1] = np.minimum(bottom[ix0:ix1, iy0:iy1], z_bottom)
        top[ix0:ix1, iy0:iy1] = np.maximum(top[ix0:ix1, iy0:iy1], z_top)
    bottom[np.isinf(bottom)] = 0.0
    return bottom, top


def free_components(blocked: np.ndarray) -> np.ndarray:
    """
    Connected components of the free cells (4-connectivity, which for the 8-connected grid without
    corner cutting gives the same components, and matches continuous motion that cannot squeeze
    between two diagonally touching blocked cells).

    :param blocked: bool (nx, ny)
    :return: int (nx, ny) labels, 0 on blocked cells
    """
    labels, _ = ndimage.label(~np.asarray(blocked, dtype=bool))
    return labels


def point_cell(xy: np.ndarray, resolution: float, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """
    Cell indices of points, clipped to the grid: ``ix = floor(x / res)``, ``iy = floor(y / res)``.

    :param xy: (..., 2) positions in metres
    :param resolution: cell size (m)
    :param shape: grid shape ``(nx, ny)``
    :return: ``(ix, iy)`` int arrays of shape (...)
    """
    xy = _points(xy)
    cells = _cells(xy.reshape(-1, 2), float(resolution), shape[0], shape[1], False).reshape(*xy.shape[:-1], 2)
    return cells[..., 0], cells[..., 1]


def flat_cell(xy: np.ndarray, resolution: float, shape: tuple[int, int]) -> np.ndarray:
    """
    Flat cell indices ``ix * ny + iy`` of points (:func:`point_cell`): rows of per-cell tables.

    :param xy: (..., 2) positions in metres
    :param resolution: cell size (m)
    :param shape: grid shape ``(nx, ny)``
    :return: int array of shape (...)
    """
    xy = _points(xy)
    return _cells(xy.reshape(-1, 2), float(resolution), shape[0], shape[1], True).reshape(xy.shape[:-1])


def _points(xy: np.ndarray) -> np.ndarray:
    """``xy`` as a float64 array of points (..., 2), or a ValueError naming its shape."""
    xy = np.asarray(xy, dtype=np.float64)
    if xy.shape[-1:] != (2,):
        raise ValueError(f"points: expected shape (..., 2), got {xy.shape}")
    return xy


@compiled
def axis_cell(coordinate: float, resolution: float, n_cells: int) -> int:
    """
    The cell index of a coordinate along one axis, ``floor(coordinate / resolution)`` clipped to
    ``[0, n_cells - 1]`` (compiled; :func:`point_cell` and the motion kernel use it).

    :param coordinate: x or y in metres
    :param resolution: cell size (m)
    :param n_cells: the grid's number of cells along that axis
    :return: the index
    """
    return min(max(math.floor(coordinate / resolution), 0), n_cells - 1)


@compiled
def _cells(xy: np.ndarray, resolution: float, nx: int, ny: int, flat: bool) -> np.ndarray:
    """The cells of (M, 2) points, compiled: (M, 2) ``[ix, iy]``, or (M,) flat indices when ``flat``."""
    cells = np.empty((len(xy), 1 if flat else 2), dtype=np.int64)
    for row in range(len(xy)):
        ix = axis_cell(xy[row, 0], resolution, nx)
        iy = axis_cell(xy[row, 1], resolution, ny)
        if flat:
            cells[row, 0] = ix * ny + iy
        else:
            cells[row, 0], cells[row, 1] = ix, iy
    return cells


def distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """
    Euclidean distance between points, ``sqrt((x_a - x_b)^2 + (y_a - y_b)^2)``.

    Computed with :func:`hypot` (the bits of Python's :func:`math.hypot`) rather than ``np.hypot`` (the
    platform's libm, which differs in the last bit on about 0.6 % of inputs), so results do not depend on the
    platform.

    :param a: points in metres, shape (..., 2)
    :param b: points in metres, broadcastable to ``a``
    :return: distances in metres, shape (...)
    """
    delta = _points(np.subtract(a, b, dtype=np.float64))
    return _norms(delta.reshape(-1, 2)).reshape(delta.shape[:-1])


@compiled
def distance_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`distance` of (M, U) points: float64 arrays (M, U, 2) of one shape, compiled (the mission engine's
    fast path)."""
    delta = a - b
    return _norms(delta.reshape(-1, 2)).reshape(delta.shape[:-1])


@compiled
def _norms(delta: np.ndarray) -> np.ndarray:
    """:func:`hypot` of each row of a (M, 2) array."""
    out = np.empty(len(delta))
    for row in range(len(delta)):
        out[row] = hypot(delta[row, 0], delta[row, 1])
    return out


@compiled
def _exact_product(a: float, b: float) -> tuple[float, float]:
    """``a * b`` rounded and its rounding error, exactly (Dekker's product, no fused multiply-add)."""
    product = a * b
    split = 134217729.0 * a  # 2**27 + 1: a = a_high + a_low with 26-bit halves
    a_high = split - (split - a)
    a_low = a - a_high
    split = 134217729.0 * b
    b_high = split - (split - b)
    b_low = b - b_high
    return product, ((a_high * b_high - product) + a_high * b_low + a_low * b_high) + a_low * b_low


@compiled
def hypot(dx: float, dy: float) -> float:
    """
    ``sqrt(dx^2 + dy^2)``, compiled (numba), with the algorithm of CPython's :func:`math.hypot` (3.10 and
    later: squares and sums carried exactly in two floats, one correction of the square root). It returns the
    bits of :func:`math.hypot` (subnormal inputs included) on every platform, unlike the platform's libm
    ``hypot`` (a property test checks the equality).

    :param dx: a coordinate difference
    :param dy: the other one
    :return: the Euclidean norm
    """
    x, y = abs(dx), abs(dy)
    largest = 0.0  # the largest of the two, a NaN left out (an infinity wins over a NaN, as in math.hypot)
    if x > largest:
        largest = x
    if y > largest:
        largest = y
    if math.isinf(largest):
        return largest
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if largest == 0.0:
        return largest
    _, exponent = math.frexp(largest)
    if exponent < -1023:  # subnormal: 2**-exponent would overflow; divide by the largest instead
        x, y = x / largest, y / largest
        return largest * math.sqrt(x * x + y * y)
    scale = math.ldexp(1.0, -exponent)
    total, low_products, low_sums = 1.0, 0.0, 0.0
    for value in (x * scale, y * scale):
        square, square_error = _exact_product(value, value)
        high = total + square
        low_sums += (total - high) + square
        total = high
        low_products += square_error
    root = math.sqrt(total - 1.0 + (low_products + low_sums))
    square, square_error = _exact_product(-root, root)
    high = total + square
    low_sums += (total - high) + square
    total = high
    low_products += square_error
    root += (total - 1.0 + (low_products + low_sums)) / (2.0 * root)
    return root / scale


def region_cells(region: tuple[float, float, float, float], resolution: float, shape: tuple[int, int]) -> np.ndarray:
    """
    Cells of a rectangular region ``(x0, y0, x1, y1)``: those whose centre lies in the closed
    rectangle; a region too small to contain a centre gives the cell containing its midpoint.

    :param region: ``(x0, y0, x1, y1)`` in metres
    :param resolution: cell size (m)
    :param shape: grid shape ``(nx, ny)``
    :return: int (k, 2) cell indices ``[ix, iy]`` (k >= 1), blocked or not
    """
    x0, y0, x1, y1 = region
    ix0, iy0, ix1, iy1 = _region_bounds(region, resolution, shape)
    if ix1 < ix0 or iy1 < iy0:
        ix, iy = point_cell(np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0]), resolution, shape)
        return np.array([[int(ix), int(iy)]], dtype=np.int64)
    gx, gy = np.meshgrid(np.arange(ix0, ix1 + 1), np.arange(iy0, iy1 + 1), indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], axis=1).astype(np.int64)


def region_size(region: tuple[float, float, float, float], resolution: float, shape: tuple[int, int]) -> int:
    """
    The number of cells of :func:`region_cells`, without building them (for memory estimates).

    :param region: ``(x0, y0, x1, y1)`` in metres
    :param resolution: cell size (m)
    :param shape: grid shape ``(nx, ny)``
    :return: k >= 1
    """
    ix0, iy0, ix1, iy1 = _region_bounds(region, resolution, shape)
    return 1 if ix1 < ix0 or iy1 < iy0 else (ix1 - ix0 + 1) * (iy1 - iy0 + 1)


def _region_bounds(
    region: tuple[float, float, float, float], resolution: float, shape: tuple[int, int]
) -> tuple[int, int, int, int]:
    """The first and last cell indices ``(ix0, iy0, ix1, iy1)`` whose centres lie in ``region`` (empty: ix1 < ix0 or
    iy1 < iy0)."""
    x0, y0, x1, y1 = region
    ix0, iy0 = int(np.ceil(x0 / resolution - 0.5 - 1e-9)), int(np.ceil(y0 / resolution - 0.5 - 1e-9))
    ix1, iy1 = int(np.floor(x1 / resolution - 0.5 + 1e-9)), int(np.floor(y1 / resolution - 0.5 + 1e-9))
    return max(ix0, 0), max(iy0, 0), min(ix1, shape[0] - 1), min(iy1, shape[1] - 1)


# --------------------------------------------------------------------------------------------------
# Occlusion: slab (ray-AABB) test, vectorised over rays x boxes
# --------------------------------------------------------------------------------------------------


def segment_box_hits(origins: np.ndarray, ends: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """
    Slab test of segments against axis-aligned boxes: does segment ``k`` pass through the interior of box ``j``?

    For each axis the segment ``o + t (e - o)``, ``t in [0, 1]``, is inside the slab between the
    box's two planes for ``t`` between ``(lo - o) / d`` and ``(hi - o) / d``; the segment crosses
    the box when the intersection of the three intervals and ``[0, 1]`` has positive length. For an
    axis with ``d = 0`` the divisions give ``+-inf`` (segment inside or outside the slab) or NaN
    when the segment lies exactly on a face plane, which the comparisons treat as "no hit" (grazing).

    :param origins: (n, 3) or (3,) segment starts
    :param ends: (n, 3) segment ends
    :param boxes: (m, 6) boxes ``[x0, y0, x1, y1, z_bottom, z_top]``
    :return: bool (n, m)
    """
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), ends.shape)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    lo = boxes[:, [0, 1, 4]]
    hi = boxes[:, [2, 3, 5]]
    direction = ends - origins
    t_near = np.zeros((len(ends), len(boxes)))
    t_far = np.ones((len(ends), len(boxes)))
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / direction
        for axis in range(3):
            o = origins[:, axis : axis + 1]
            inv = inverse[:, axis : axis + 1]
            t1 = (lo[None, :, axis] - o) * inv
            t2 = (hi[None, :, axis] - o) * inv
            # np.maximum / np.minimum propagate NaN, so a grazing segment never counts as a hit.
            t_near = np.maximum(t_near, np.minimum(t1, t2))
            t_far = np.minimum(t_far, np.maximum(t1, t2))
    return t_near < t_far


def count_obstacles(
    origins: np.ndarray,
    ends: np.ndarray,
    boxes: np.ndarray,
    owner: np.ndarray,
    chunk_pairs: int = CHUNK_PAIRS,
) -> np.ndarray:
    """
    Number of distinct obstacles (objects, not boxes) each segment crosses (paper Sec. III-C), vectorised
    over all segments x all boxes, in chunks of at most ``chunk_pairs`` segment-box pairs.

    :param origins: (n, 3) or (3,) segment starts (transmitter antennas)
    :param ends: (n, 3) segment ends (receiver antennas)
    :param boxes: (m, 6) boxes
    :param owner: (m,) index of the obstacle each box belongs to
    :param chunk_pairs: memory bound, see :data:`CHUNK_PAIRS`
    :return: int (n,)
    """
    ends = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), ends.shape)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    owner = np.asarray(owner, dtype=np.int64).reshape(-1)
    counts = np.zeros(len(ends), dtype=np.int64)
    if len(boxes) == 0 or len(ends) == 0:
        return counts
    order = np.argsort(owner, kind="stable")
    boxes, owner = boxes[order], owner[order]
    # First box of each obstacle: reduceat over the box axis turns box hits into obstacle hits.
    starts = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    step = max(1, chunk_pairs // len(boxes))
    for k in range(0, len(ends), step):
        hits = segment_box_hits(origins[k : k + step], ends[k : k + step], boxes)
        counts[k : k + step] = np.logical_or.reduceat(hits, starts, axis=1).sum(axis=1)
    return counts


# --------------------------------------------------------------------------------------------------
# Grid paths: 8-connected, no corner cutting
# --------------------------------------------------------------------------------------------------

_OFFSETS = ((1, 0), (0, 1), (1, 1), (1, -1))


def grid_graph(blocked: np.ndarray, resolution: float, cost: np.ndarray | None = None) -> sparse.csr_matrix:
    """
    The free cells as a weighted graph (node ``ix * ny + iy``): 8-connected, a diagonal step
    allowed only when both cells it cuts the corner of are free (no corner cutting).

    The weight of a step is its length in metres times ``1 + (cost[a] + cost[b]) / 2``: ``cost`` is
    an extra cost per metre travelled in a cell (e.g. an outage penalty), split evenly between the
    two cells a step joins, which keeps the graph symmetric.

    :param blocked: bool (nx, ny)
    :param resolution: cell size (m)
    :param cost: optional non-negative float (nx, ny)
    :return: symmetric sparse (nx*ny, nx*ny) matrix of step weights
    """
    blocked = np.asarray(blocked, dtype=bool)
    nx, ny = blocked.shape
    free = ~blocked
    if cost is not None:
        cost = np.asarray(cost, dtype=np.float64)
        if cost.shape != blocked.shape or np.any(cost < 0) or not np.all(np.isfinite(cost[free])):
            raise ValueError(f"cost: expected a finite non-negative array of shape {blocked.shape}, got shape {cost.shape}")
    index = np.arange(nx * ny).reshape(nx, ny)
    rows, cols, weights = [], [], []
    for dx, dy in _OFFSETS:
        sx = slice(max(0, -dx), nx - max(0, dx))
        sy = slice(max(0, -dy), ny - max(0, dy))
        tx = slice(sx.start + dx, sx.stop + dx)
        ty = slice(sy.start + dy, sy.stop + dy)
        ok = free[sx, sy] & free[tx, ty]
        if dx and dy:
            ok &= free[tx, sy] & free[sx, ty]
        length = resolution * float(np.hypot(dx, dy))
        weight = np.full(ok.shape, length)
        if cost is not None:
            weight = length * (1.0 + 0.5 * (cost[sx, sy] + cost[tx, ty]))
        rows.append(index[sx, sy][ok])
        cols.append(index[tx, ty][ok])
        weights.append(weight[ok])
    r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
    return sparse.csr_matrix((np.r_[w, w], (np.r_[r, c], np.r_[c, r])), shape=(nx * ny, nx * ny))


def grid_distance_field(
    blocked: np.ndarray, goal_cell: tuple[int, int], resolution: float, cost: np.ndarray | None = None
) -> np.ndarray:
    """
    Obstacle-aware (geodesic) distance in metres from every cell to ``goal_cell`` along the
    8-connected grid without corner cutting (Dijkstra); ``inf`` on blocked or unreachable cells.

    :param blocked: bool (nx, ny)
    :param goal_cell: ``(ix, iy)``
    :param resolution: cell size (m)
    :param cost: optional extra cost per metre per cell, see :func:`grid_graph`
    :return: float (nx, ny)
    """
    blocked = np.asarray(blocked, dtype=bool)
    nx, ny = blocked.shape
    gx, gy = int(goal_cell[0]), int(goal_cell[1])
    if not (0 <= gx < nx and 0 <= gy < ny):
        raise ValueError(f"goal_cell: {goal_cell!r} is outside the grid of shape {blocked.shape}")
    if blocked[gx, gy]:
        return np.full(blocked.shape, np.inf)
    graph = grid_graph(blocked, resolution, cost)
    distances = csgraph.dijkstra(graph, directed=False, indices=gx * ny + gy)
    return distances.reshape(nx, ny)


def shortest_path(
    blocked: np.ndarray,
    start_cell: tuple[int, int],
    goal_cell: tuple[int, int],
    cost: np.ndarray | None = None,
    resolution: float = 1.0,
) -> tuple[np.ndarray, float]:
    """
    Shortest grid path (Dijkstra, 8-connected, no corner cutting) from ``start_cell`` to ``goal_cell``.

    :param blocked: bool (nx, ny)
    :param start_cell: ``(ix, iy)``
    :param goal_cell: ``(ix, iy)``
    :param cost: optional extra cost per metre per cell, see :func:`grid_graph`
    :param resolution: cell size (m); the returned cost is in metres (times the cost factor)
    :return: ``(cells, total_cost)``: int (k, 2) cells from start to goal, both included, and the
        path's total weight; ``(empty (0, 2), inf)`` when the goal is unreachable
    """
    blocked = np.asarray(blocked, dtype=bool)
    nx, ny = blocked.shape
    for name, cell in (("start_cell", start_cell), ("goal_cell", goal_cell)):
        if not (0 <= int(cell[0]) < nx and 0 <= int(cell[1]) < ny):
            raise ValueError(f"{name}: {cell!r} is outside the grid of shape {blocked.shape}")
    start = int(start_cell[0]) * ny + int(start_cell[1])
    goal = int(goal_cell[0]) * ny + int(goal_cell[1])
    if blocked.flat[start] or blocked.flat[goal]:
        return np.zeros((0, 2), dtype=np.int64), float("inf")
    graph = grid_graph(blocked, resolution, cost)
    distances, predecessors = csgraph.dijkstra(graph, directed=False, indices=start, return_predecessors=True)
    if not np.isfinite(distances[goal]):
        return np.zeros((0, 2), dtype=np.int64), float("inf")
    nodes = [goal]
    while nodes[-1] != start:
        nodes.append(int(predecessors[nodes[-1]]))
    nodes.reverse()
    path = np.asarray(nodes, dtype=np.int64)
    return np.stack([path // ny, path % ny], axis=1), float(distances[goal])
