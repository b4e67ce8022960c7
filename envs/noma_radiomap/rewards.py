"""The reward of the mission env and the mission quality indicator (paper Sec. II-D and IV-E; docs/MODEL.md).

Functions whose leading axes are free: per-robot arrays have shape (..., U), so one mission ``(U,)`` and a
batch of N missions ``(N, U)`` go through the same code (the components in one compiled loop, numba). Sums
over robots run left to right, so a batch gives the same bits as its missions one by one.

The reward is a weighted sum of named components, each summed over the robots that had not arrived
before the step: ``time`` (``R_c``), ``inducing`` (``R_i``), ``qos`` (``R_QoS``), ``arrival`` (``R_d``)
and ``success`` (``R_s``). A reward phase picks the components (weights 0 or 1, :func:`phase_weights`).
"""

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from noma_radiomap.compiled import as_rows, as_scalar, compiled

#: The reward phases: the paper's destination training (Eq. (26)), its MQI training (Eq. (27)) and all five
#: components at once (the plain DDPG baseline).
REWARD_PHASES: tuple[str, ...] = ("destination", "mqi", "combined")
#: The reward components, in the order they are summed and stored.
REWARD_COMPONENTS: tuple[str, ...] = ("time", "inducing", "qos", "arrival", "success")
PHASE_TERMS: dict[str, tuple[str, ...]] = {
    "destination": ("time", "inducing", "arrival", "success"),
    "mqi": ("time", "qos", "arrival", "success"),
    "combined": REWARD_COMPONENTS,
}


@dataclass(frozen=True)
class RewardConstants:
    """
    Constants of the reward (paper Sec. IV-E; the scenario's ``mission`` section).

    :param time_cost: ``R_c``, per robot still on its way, per step
    :param outage_penalty: ``lambda``: ``R_QoS = -lambda`` per robot in outage, per step
    :param arrival_reward: ``R_d``, once per robot, on the step it arrives
    :param success_reward: ``R_s``, once, on the step the last robot arrives
    """

    time_cost: float = -1.0
    outage_penalty: float = 1.0
    arrival_reward: float = 10.0
    success_reward: float = 200.0

    def kernel_constants(self) -> tuple[float, float, float, float]:
        """The arguments of :func:`component_rows` after ``d_max``: the four constants as floats, in field order."""
        return float(self.time_cost), float(self.outage_penalty), float(self.arrival_reward), float(self.success_reward)


def phase_weights(phase: str) -> dict[str, float]:
    """
    Weights of the reward components in a reward phase: the phase's reward is
    ``sum(weights[k] * components[k])`` (Eq. (26) for ``destination``, Eq. (27) for ``mqi``).

    :param phase: one of :data:`REWARD_PHASES`
    :return: a weight (0 or 1) for each of :data:`REWARD_COMPONENTS`
    """
    if phase not in PHASE_TERMS:
        raise ValueError(f"reward_phase must be one of {REWARD_PHASES}, got {phase!r}")
    terms = PHASE_TERMS[phase]
    return {name: float(name in terms) for name in REWARD_COMPONENTS}


@compiled
def inducing_reward(distance: np.ndarray | float, d_max: float) -> np.ndarray | float:
    """
    Inducing reward ``R_i = 1 - d / d_max`` (paper Sec. IV-E, a term of Eq. (26), destination training).

    :param distance: distances ``d`` of the robots to their destinations in metres, an array (..., U) or a float
    :param d_max: the largest possible distance (the room's diagonal, :attr:`Room.d_max`)
    :return: ``R_i``, the shape of ``distance``
    """
    return 1.0 - distance / d_max


def reward_components(
    active: np.ndarray,
    arriving: np.ndarray,
    outage: np.ndarray,
    distance: np.ndarray,
    d_max: float,
    constants: RewardConstants,
) -> dict[str, np.ndarray]:
    """
    The reward components of one step, summed over the robots that had not arrived before it.

    ``success`` is paid once, on the step the last robot arrives (all robots have arrived and one of them
    arrived on this step).

    :param active: robots that had not arrived before the step, bool (..., U)
    :param arriving: robots that arrived on this step, bool (..., U)
    :param outage: robots in outage (only active ones count), bool (..., U)
    :param distance: distances to the destinations after the step in metres, (..., U)
    :param d_max: see :func:`inducing_reward`
    :param constants: the reward constants
    :return: ``{component: value}`` for each of :data:`REWARD_COMPONENTS`, arrays of shape (...)
    """
    active, arriving, outage = np.asarray(active, dtype=bool), np.asarray(arriving, dtype=bool), np.asarray(outage, dtype=bool)
    distance = np.asarray(distance, dtype=np.float64)
    robots_shape = active.shape
    if arriving.shape != robots_shape or outage.shape != robots_shape or distance.shape != robots_shape:
        # Broadcast as numpy would (the kernel does not check bounds)
        robots_shape = np.broadcast_shapes(robots_shape, arriving.shape, outage.shape, distance.shape)
        active, arriving, outage, distance = (np.broadcast_to(x, robots_shape) for x in (active, arriving, outage, distance))
    shape, rows = robots_shape[:-1], (-1, robots_shape[-1])
    robots = (x.reshape(rows) for x in (active, arriving, outage, distance))
    values = component_rows(*robots, float(d_max), *constants.kernel_constants())
    return dict(zip(REWARD_COMPONENTS, values.reshape(len(REWARD_COMPONENTS), *shape), strict=True))


@compiled
def weighted_rows(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """
    The weighted reward of Eq. (26) and (27) (:func:`weighted_reward`) of (K, M) component values with (K, M)
    weights (the env: the 5 components of :data:`REWARD_COMPONENTS`, a phase per mission), compiled: per mission
    ``0.0 + w_0 c_0 + w_1 c_1 + ...``, summed in row order.
    """
    reward = np.empty(values.shape[1])
    for row in range(values.shape[1]):
        total = 0.0
        for k in range(values.shape[0]):
            total = total + weights[k, row] * values[k, row]
        reward[row] = total
    return reward


@compiled
def component_rows(
    active: np.ndarray,
    arriving: np.ndarray,
    outage: np.ndarray,
    distance: np.ndarray,
    d_max: float,
    time_cost: float,
    outage_penalty: float,
    arrival_reward: float,
    success_reward: float,
) -> np.ndarray:
    """:func:`reward_components` of (M, U) robots, compiled: the components in the rows of a (5, M) array
    (the order of :data:`REWARD_COMPONENTS`), the inducing terms summed left to right."""
    values = np.empty((5, active.shape[0]))
    for row in range(active.shape[0]):
        n_active, n_arriving, n_outage, inducing, all_arrived = 0, 0, 0, 0.0, True
        for u in range(active.shape[1]):
            if active[row, u]:
                n_active += 1
                n_outage += outage[row, u]
                inducing += inducing_reward(distance[row, u], d_max)
            n_arriving += arriving[row, u]
            # Everyone has arrived: the active robots of this step are exactly the arriving ones.
            all_arrived &= arriving[row, u] or not active[row, u]
        values[0, row] = time_cost * n_active + 0.0  # + 0.0: no -0.0 when every robot has arrived
        values[1, row] = inducing
        values[2, row] = 0.0 - outage_penalty * n_outage
        values[3, row] = arrival_reward * n_arriving
        values[4, row] = success_reward if all_arrived and n_arriving > 0 else 0.0
    return values


def weighted_reward(components: Mapping[str, np.ndarray], weights: Mapping[str, float]) -> np.ndarray:
    """
    The reward ``sum_k weights[k] * components[k]`` (Eq. (26) and (27) with the weights of
    :func:`phase_weights`), summed in the order of ``components``: :func:`weighted_rows`, the one implementation.

    :param components: the reward components (:func:`reward_components`), arrays of shape (...)
    :param weights: a weight per component (:func:`phase_weights`), or an array of weights per mission
        broadcastable to the components (the vector env); missing components weigh 0
    :return: the reward, float64 of shape (...)
    """
    values = [np.asarray(value, dtype=np.float64) for value in components.values()]
    factors = [np.asarray(weights.get(name, 0.0), dtype=np.float64) for name in components]
    shape = np.broadcast_shapes(*(array.shape for array in values + factors))
    rows = (len(values), int(np.prod(shape, dtype=np.int64)))
    stacked_values, stacked_weights = (
        np.array([np.broadcast_to(array, shape) for array in arrays]).reshape(rows) for arrays in (values, factors)
    )
    return weighted_rows(stacked_values, stacked_weights).reshape(shape)


def mission_quality_indicator(
    t_total: float, mission_time: np.ndarray, outage_steps: np.ndarray, outage_penalty: float
) -> np.ndarray:
    """
    Mission quality indicator ``MQI = T_total - sum_u (T_u + lambda T_out_u)`` (paper Eq. (14)) of missions with
    robots on the last axis: :func:`mqi_rows`, the one implementation (the env's episode summaries call it too).

    :param t_total: ``T_total``, the MQI budget
    :param mission_time: ``T_u``, steps until each robot arrived (``max_steps`` if it never did), (..., U)
    :param outage_steps: steps each robot spent in outage, (..., U)
    :param outage_penalty: ``lambda``
    :return: the MQI, float64 of shape (...)
    :raises ValueError: 0-d ``mission_time`` and ``outage_steps``, or ``t_total`` / ``outage_penalty`` arrays
    """
    (times, outages), shape = as_rows("mission_quality_indicator: mission_time, outage_steps", mission_time, outage_steps)
    t_total, outage_penalty = as_scalar("t_total", t_total), as_scalar("outage_penalty", outage_penalty)
    return mqi_rows(t_total, times, outages, outage_penalty).reshape(shape)


@compiled
def mqi_rows(t_total: float, mission_time: np.ndarray, outage_steps: np.ndarray, outage_penalty: float) -> np.ndarray:
    """
    The MQI of Eq. (14), ``T_total - sum_u (T_u + lambda T_out_u)``, of (M, U) robots, compiled: one per row, the
    sum over the robots left to right (like every sum over robots of the env), so a batch gives the bits of its
    missions one by one.
    """
    mqi = np.empty(mission_time.shape[0])
    for row in range(mission_time.shape[0]):
        total = 0.0
        for u in range(mission_time.shape[1]):
            term = mission_time[row, u] + outage_penalty * outage_steps[row, u]
            total = term if u == 0 else total + term
        mqi[row] = t_total - total
    return mqi
