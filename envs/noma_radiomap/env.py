"""The NOMA indoor radio-map environment (the paper's Sections II-IV; docs/MODEL.md, docs/ARCHITECTURE.md)."""

import os
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from noma_radiomap import rewards
from noma_radiomap.actions import check_action
from noma_radiomap.core import CHANNELS, INDUCING, RESET_FIRST, TASKS, MissionCore, summary_row
from noma_radiomap.observations import GAIN_DB_RANGE, observation_space
from noma_radiomap.scenario import Scenario

__all__ = ["CHANNELS", "INDUCING", "TASKS", "NomaRadioMapEnv"]

_ALL = slice(None)


class NomaRadioMapEnv(gym.Env[np.ndarray, np.ndarray]):
    """
    ## Description

    Indoor robots (IRs) cross a room built from "Lego" cuboids to their destinations while one access
    point (AP) serves them in the downlink with NOMA (superposition coding and SIC) or OMA (FDMA), under
    interference from external transmitters (Zhong et al., "Path Design and Resource Management for NOMA
    enhanced Indoor Intelligent Robots"). Each step, the agent moves every robot and splits the AP's power
    between them; a robot whose rate falls below the QoS rate is in outage. The mission quality indicator
    ``MQI = t_total - sum_u (T_u + lambda outage_u)`` rewards short missions with few outage steps.

    The channel comes from a pre-computed radio map (:class:`noma_radiomap.RadioMap`): ITU-R P.1238 path
    loss with obstacle counting (paper Eq. (1)-(4), (17)), plus Rayleigh fading, either at its expectation (the paper's
    radio-map training, deterministic) or drawn fresh every step ("reality").

    ## Action Space

    ``Box(-1, 1, (3U,), float32)``, per robot ``u`` (in scenario order) ``[dx, dy, power]``:

    | Num      | Action                                                       | Min | Max |
    |----------|--------------------------------------------------------------|-----|-----|
    | 3u       | x velocity, scaled by ``V_max time_step`` (metres per step)  | -1  | 1   |
    | 3u + 1   | y velocity; the displacement is clipped to norm ``V_max dt``  | -1  | 1   |
    | 3u + 2   | power: ``p_u = P_max (a + 1) / 2``, all scaled down to sum ``P_max`` if more | -1 | 1 |

    Robots move in sub-steps of at most half a cell and slide along walls (paper Sec. IV-D); an arrived robot's
    actions are ignored and it gets no power. Finite actions outside [-1, 1] are clipped; an action of another
    shape than ``(3U,)``, or with a NaN or infinite component, raises a ``ValueError`` naming the robot and the
    component, and leaves the env's state unchanged (:func:`noma_radiomap.actions.check_action`).

    ## Observation Space

    ``Box(-1, 1, (k U,), float32)`` in one of three layouts (``observation``, :mod:`noma_radiomap.observations`;
    docs/MODEL.md, Observations). ``"goal"`` (the default, ``9U``): the ``"destinations"`` values of every robot,
    then per robot the unit vector towards its destination and ``min(d / 10 m, 1)`` (0 once arrived).
    ``"destinations"`` (``6U``), per robot ``u``:

    | Num      | Observation                                                           | Min | Max |
    |----------|-----------------------------------------------------------------------|-----|-----|
    | 6u, 6u+1 | position ``(x, y)``: ``2 x / width - 1``, ``2 y / depth - 1``           | -1  | 1   |
    | 6u+2, +3 | destination, scaled like the position                                 | -1  | 1   |
    | 6u + 4   | AP channel gain ``g_u`` incl. fading in dB, [-130, -30] dB mapped onto [-1, 1], clipped | -1  | 1   |
    | 6u + 5   | arrived flag: 1 once the robot has arrived, else 0                     | 0   | 1   |

    ``"paper"`` (``3U``): the paper's state Eq. (24), per robot its position and gain (scaled as above), nothing
    else; the default of the paper's task.

    ## Rewards

    Per step, summed over the robots that had not arrived before the step (paper Sec. IV):
    time cost ``R_c = -1``; inducing reward ``R_i = 1 - d / d_max`` (``d``: distance to the destination,
    Euclidean or geodesic, ``d_max``: the room diagonal); QoS penalty ``R_qos = -lambda`` in outage;
    ``R_d = +10`` on the step a robot arrives; ``R_s = +200`` when all robots have arrived. The reward phase
    picks the terms: ``"destination"`` (phase 1): ``R_c + R_i + R_d + R_s``; ``"mqi"`` (phase 2):
    ``R_c + R_qos + R_d + R_s``; ``"combined"`` (the plain DDPG baseline): all five. Every ``info`` has
    ``reward_components`` (``time``, ``inducing``, ``qos``, ``arrival``, ``success``, summed over robots), so
    ``reward == sum(reward_weights()[k] * info["reward_components"][k])`` and any phase's reward can be
    recomputed; ``set_reward_phase`` switches the phase at run time (also through ``VecEnv.env_method``).

    ``info`` per step (per-robot arrays of length U): ``rate_bps``, ``sinr_db``, ``outage`` (bool, only for
    robots that had not arrived), ``power_w``, ``gain_db`` (incl. fading) and ``decoding_order`` (robot
    indices, weakest to strongest equivalent gain), and the episode summary as of the step: ``is_success``,
    ``mqi``, ``mission_time`` (per robot: steps until arrival, ``max_steps`` if never) and ``outage_steps`` (per
    robot); the env cannot see where an outer ``TimeLimit`` ends the episode, so every step carries it and the
    last one of an episode is final.

    ## Starting State

    Each robot starts at the centre of a cell drawn uniformly from the free cells of its scenario start
    region (farther than ``arrival_radius`` from its destination), heading to one of its scenario
    destinations drawn uniformly. ``reset(options={"starts": [[x, y], ...], "destinations": [[x, y], ...]})``
    fixes either or both (one ``[x, y]`` per robot, free and mutually reachable); the other is drawn uniformly
    among what fits: the scenario destinations reachable from a given start and farther than ``arrival_radius``,
    or the start cells that can reach a given destination.

    ## Episode End

    Terminates when every robot has arrived (within ``arrival_radius`` of its destination); truncated at the
    scenario's ``mission.max_steps``, where a mission ends (``T_u`` of a robot that has not arrived is that number
    of steps), also when the env is built without ``gymnasium.make``. The registered ids wrap it in a ``TimeLimit``
    of the same steps (:func:`noma_radiomap.registration.make_env`), so ``spec.max_episode_steps`` follows the
    scenario; ``gymnasium.make(..., max_episode_steps=n)`` may end it sooner (the last ``info`` has the summary
    either way).
    Stepping, rendering, ``trajectory`` or :meth:`episode_summary` before the first ``reset`` raise Gymnasium's
    ``ResetNeeded`` ("call reset() first").

    ## Arguments

    ```python
    >>> import gymnasium as gym
    >>> import noma_radiomap
    >>> env = gym.make("NomaRadioMap-v0", multiple_access="oma", channel="rayleigh", reward_phase="mqi")
    ```

    - ``scenario``: a built-in scenario name (``"mall"``), a YAML path or a :class:`Scenario`
    - ``multiple_access``: ``"noma"`` (SIC) or ``"oma"`` (FDMA)
    - ``channel``: ``"radio_map"`` (expected fading, -2.51 dB on every link, deterministic) or ``"rayleigh"``
      (``|h|^2 ~ Exp(1)`` per link per step from the env's seeded generator)
    - ``reward_phase``: ``"destination"``, ``"mqi"`` or ``"combined"``
    - ``inducing``: ``"euclidean"`` or ``"geodesic"`` (obstacle-aware grid distance) for ``R_i``
    - ``render_mode``: ``None``, ``"rgb_array"`` (SINR map with robots and trajectories) or ``"human"``
    - ``observation``: ``"goal"`` (the default), ``"destinations"`` or ``"paper"`` (see Observation Space; None:
      the task's default)
    - ``task``: ``"missions"`` (each episode draws each robot's destination from its scenario list) or
      ``"paper"``, the paper's task (docs/MODEL.md): each robot's first listed destination, fixed; observation
      ``"paper"``; ``T_total`` and the episode cap 1000 steps (``NomaRadioMapPaper-v0``)

    ## Attributes

    For planners, evaluation and plots (read-only): ``scenario``, ``radio_map``, ``positions`` (U, 2),
    ``destinations`` (U, 2), ``arrived`` (U,), ``step_count``, ``trajectory`` (steps + 1, U, 2),
    ``reward_phase``, ``observation``, ``task``, ``core`` (the mission engine,
    :class:`noma_radiomap.core.MissionCore` of one mission); :meth:`reward_weights`, :meth:`set_reward_phase`,
    :meth:`episode_summary`.

    ## Vector env

    ``gymnasium.make_vec("NomaRadioMap-v0", num_envs=N)`` steps N missions at once
    (:class:`noma_radiomap.vector.NomaRadioMapVecEnv`, the same engine with N missions: the same transitions as N
    single envs seeded ``seed + i``); for Stable-Baselines3, ``sb3_dtdpg.vec_env.make_mission_vec_env`` (docs/SCALING.md).

    ## Version History

    * v0: Initial release.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    REWARD_PHASES: ClassVar[tuple[str, ...]] = rewards.REWARD_PHASES
    REWARD_COMPONENTS: ClassVar[tuple[str, ...]] = rewards.REWARD_COMPONENTS
    #: Channel gains (dB) mapped onto the observation's [-1, 1] (:data:`noma_radiomap.observations.GAIN_DB_RANGE`).
    GAIN_DB_RANGE: ClassVar[tuple[float, float]] = GAIN_DB_RANGE

    def __init__(
        self,
        scenario: str | os.PathLike[str] | Scenario = "mall",
        multiple_access: str = "noma",
        channel: str = "radio_map",
        reward_phase: str = "destination",
        inducing: str = "euclidean",
        render_mode: str | None = None,
        observation: str | None = None,
        task: str = "missions",
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        #: The mission engine, one mission (:class:`noma_radiomap.core.MissionCore`)
        self.core = MissionCore(1, scenario, multiple_access, channel, reward_phase, inducing, observation, task)
        core = self.core
        self.scenario = core.scenario
        self.radio_map = core.radio_map
        self.multiple_access, self.channel, self.inducing, self.task = multiple_access, channel, inducing, task
        self.observation = core.observation
        self.render_mode = render_mode
        self.n_robots = core.n_robots
        self.max_steps = core.max_steps
        self.action_space = spaces.Box(-1.0, 1.0, (3 * self.n_robots,), dtype=np.float32)
        self.observation_space = observation_space(self.observation, self.n_robots)
        self._trajectory: list[np.ndarray] = []
        self._renderer = None

    # --- reward phases ---------------------------------------------------------------------------
    def set_reward_phase(self, name: str) -> None:
        """
        Switch the reward phase (takes effect from the next step).

        :param name: one of :attr:`REWARD_PHASES`
        """
        self.core.set_reward_phase(name, [0])

    @property
    def reward_phase(self) -> str:
        """The current reward phase (:meth:`set_reward_phase`)."""
        return self.core.reward_phases[0]

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        """
        Weights of the reward components in a phase: its reward is
        ``sum(weights[k] * info["reward_components"][k])``.

        :param phase: a reward phase; None: the current one
        :return: a weight (0 or 1) for each of :attr:`REWARD_COMPONENTS`
        """
        return rewards.phase_weights(self.reward_phase if phase is None else phase)

    # --- the mission state -----------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Robot positions in metres, (U, 2) (a copy)."""
        return self.core.positions[0].copy()

    @property
    def destinations(self) -> np.ndarray:
        """Destinations in metres, (U, 2) (a copy)."""
        return self.core.destinations[0].copy()

    @property
    def arrived(self) -> np.ndarray:
        """Arrived flags, (U,) (a copy)."""
        return self.core.arrived[0].copy()

    @property
    def step_count(self) -> int:
        """Steps since the last reset."""
        return int(self.core.step_counts[0])

    # --- Gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options: expected a dict of reset options (or None), got {type(options).__name__}")
        generator = self._np_random, self._np_random_seed
        super().reset(seed=seed)
        core = self.core
        try:
            core.reset(np.zeros(1, dtype=np.int64), options=options, rngs=[self.np_random])
        except ValueError:  # a refused option: the env, its generator included, is as it was
            self._np_random, self._np_random_seed = generator
            raise
        self._trajectory = [core.positions[0].copy()]
        if self.render_mode == "human":
            self.render()
        return core.observations()[0], {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        core = self.core
        core.check_reset()
        result = core.step(check_action(action, self.n_robots)[None], _ALL)
        self._trajectory.append(core.positions[0].copy())
        terminated = bool(result.terminated[0])
        info = result.info(0)  # with the episode summary as of this step (core.SUMMARY_KEYS)
        if self.render_mode == "human":
            self.render()
        truncated = bool(result.truncated[0])  # at max_steps: TimeLimit's step too, where the registered ids have one
        return core.observations()[0], float(result.reward[0]), terminated, truncated, info

    def episode_summary(self) -> dict[str, Any]:
        """
        The end-of-episode figures (paper Eq. (13)-(14)), as of the current step.

        :return: ``is_success`` (all arrived), ``mqi``, ``mission_time`` (per robot, ``T_u``: steps until
            arrival, ``max_steps`` if not arrived) and ``outage_steps`` (per robot)
        :raises ResetNeeded: before the first reset
        """
        return summary_row(self.core.episode_summaries(_ALL), 0)

    @property
    def trajectory(self) -> np.ndarray:
        """Robot positions since the last reset, shape (steps + 1, U, 2)."""
        if not self._trajectory:
            raise ResetNeeded(f"no trajectory before the first reset: {RESET_FIRST}")
        return np.stack(self._trajectory)

    def render(self) -> np.ndarray | None:
        if not self._trajectory:
            raise ResetNeeded(f"nothing to render before the first reset: {RESET_FIRST}")
        if self.render_mode is None:
            gym.logger.warn(
                "You are calling render method without specifying any render mode. "
                'You can specify the render_mode at initialization, e.g. gym.make("NomaRadioMap-v0", render_mode="rgb_array")'
            )
            return None
        if self._renderer is None:
            from noma_radiomap.rendering import Renderer

            self._renderer = Renderer(self, human=self.render_mode == "human")
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None  # matplotlib figures are rebuilt on demand
        return state
