"""NomaRadioMapEnv (docs/MODEL.md): API checkers, determinism, rewards and phases, MQI, options, vec envs."""

import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

import noma_radiomap
from noma_radiomap import NomaRadioMapEnv, RadioMap, Scenario, load_scenario
from noma_radiomap.core import PAPER_MAX_STEPS
from noma_radiomap.downlink import allocate_power, downlink
from noma_radiomap.propagation import EXPECTED_FADING_DB, db_to_linear, dbm_to_watt
from noma_radiomap.registration import ENV_IDS, register_envs

MALL_STEPS = load_scenario("mall").mission.max_steps

MODES = [(ma, ch) for ma in ("noma", "oma") for ch in ("radio_map", "rayleigh")]
# Two free, mutually reachable points per robot in the `small` scenario (left of its wall, no obstacle on the
# straight line between start and destination): a mission robots can drive straight.
STRAIGHT = {"starts": [[1.25, 1.25], [1.25, 6.75]], "destinations": [[5.0, 3.0], [4.0, 7.0]]}


def small_env(**kwargs) -> NomaRadioMapEnv:
    return NomaRadioMapEnv(scenario="small", **kwargs)


def rollout(env, seed: int, n_steps: int, options=None):
    """Observations, rewards and infos of random actions (the actions drawn from their own seeded generator)."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed, options=options)
    records = [obs]
    for _ in range(n_steps):
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        records.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            records.append(env.reset()[0])
    return records


def assert_same(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, tuple | list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    else:
        np.testing.assert_array_equal(a, b)


def drive_straight(env) -> np.ndarray:
    """Scripted policy: every robot heads straight to its destination at full speed, equal power."""
    direction = env.destinations - env.positions
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    power = np.zeros((env.n_robots, 1))
    return np.concatenate([direction, power], axis=1).ravel().astype(np.float32)


# --- checkers -----------------------------------------------------------------------------------------


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_checkers_registered_ids(env_id):
    env = gym.make(env_id)
    gym_check_env(env.unwrapped)
    sb3_check_env(env, warn=True)
    assert env.spec.max_episode_steps == (PAPER_MAX_STEPS if "Paper" in env_id else MALL_STEPS)


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("multiple_access,channel", MODES)
def test_checkers_modes(multiple_access, channel):
    env = gym.make("NomaRadioMap-v0", scenario="small", multiple_access=multiple_access, channel=channel)
    gym_check_env(env.unwrapped)
    sb3_check_env(env, warn=True)


def test_registration_is_idempotent_and_kwargs_pass_through():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        register_envs()
    # The TimeLimit follows the scenario's mission.max_steps
    assert gym.make("NomaRadioMap-v0", scenario="small").spec.max_episode_steps == load_scenario("small").mission.max_steps
    env = gym.make("NomaRadioMapOMAReality-v0", scenario="small", reward_phase="mqi", inducing="geodesic").unwrapped
    assert (env.scenario.name, env.multiple_access, env.channel, env.reward_phase, env.inducing) == (
        "small",
        "oma",
        "rayleigh",
        "mqi",
        "geodesic",
    )
    default = gym.make("NomaRadioMap-v0").unwrapped
    assert (default.scenario.name, default.multiple_access, default.channel, default.reward_phase) == (
        "mall",
        "noma",
        "radio_map",
        "destination",
    )


def test_a_time_limit_of_make_shortens_missions_and_never_lengthens_them():
    """The env ends every mission at mission.max_steps (small: 60); gymnasium.make's limit adds a TimeLimit on top."""
    for limit, expected in [(100, 60), (60, 60), (10, 10), (-1, 60), (None, 60)]:  # -1: no TimeLimit of make's
        env = gym.make("NomaRadioMap-v0", scenario="small", max_episode_steps=limit)
        env.reset(seed=0)
        steps, done = 0, False
        while not done:
            _, _, terminated, truncated, _ = env.step(np.zeros(6))
            steps, done = steps + 1, terminated or truncated
        assert truncated and steps == expected


def test_the_env_built_without_make_ends_its_missions_at_max_steps_too():
    # It ran on past max_steps (an endless mission in training, evaluate() never returned) with T_u = max_steps
    env, made = small_env(), gym.make("NomaRadioMap-v0", scenario="small")
    for e in (env, made):
        e.reset(seed=0)
    for step in range(1, env.max_steps + 1):
        outcome, made_outcome = env.step(np.zeros(6)), made.step(np.zeros(6))
        assert outcome[3] == made_outcome[3] == (step == env.max_steps)  # truncated at the same step as under make
        np.testing.assert_array_equal(outcome[0], made_outcome[0])
    assert env.step_count == env.max_steps and list(outcome[4]["mission_time"]) == [env.max_steps] * env.n_robots


@pytest.mark.parametrize(
    "kwarg,value",
    [("multiple_access", "fdma"), ("channel", "ricean"), ("reward_phase", "speed"), ("inducing", "manhattan")],
)
def test_invalid_kwargs_name_the_kwarg_and_value(kwarg, value):
    with pytest.raises(ValueError, match=rf"{kwarg}.*'{value}'"):
        small_env(**{kwarg: value})


def test_invalid_render_mode_and_scenario():
    with pytest.raises(ValueError, match=r"render_mode.*'video'"):
        small_env(render_mode="video")
    with pytest.raises(ValueError, match=r"scenario.*42"):
        NomaRadioMapEnv(scenario=42)
    with pytest.raises(ValueError, match="no_such_place"):
        NomaRadioMapEnv(scenario="no_such_place")


def test_scenario_object_and_path_are_accepted(tmp_path):
    scenario = load_scenario("small")
    assert NomaRadioMapEnv(scenario=scenario).scenario == scenario
    path = tmp_path / "copy.yaml"
    import yaml

    path.write_text(yaml.safe_dump(scenario.to_dict()))
    assert NomaRadioMapEnv(scenario=path).scenario == scenario


# --- determinism --------------------------------------------------------------------------------------


@pytest.mark.parametrize("channel", ["radio_map", "rayleigh"])
def test_same_seed_same_trajectory(channel):
    a = rollout(small_env(channel=channel), seed=3, n_steps=100)
    b = rollout(small_env(channel=channel), seed=3, n_steps=100)
    assert_same(a, b)


def test_different_seeds_differ_in_rayleigh_mode():
    # Same mission and actions: only the fading draws differ.
    env_a, env_b = small_env(channel="rayleigh"), small_env(channel="rayleigh")
    env_a.reset(seed=1, options=STRAIGHT)
    env_b.reset(seed=2, options=STRAIGHT)
    action = np.full(env_a.action_space.shape, 0.3, dtype=np.float32)
    for _ in range(3):
        obs_a, _, _, _, info_a = env_a.step(action)
        obs_b, _, _, _, info_b = env_b.step(action)
        np.testing.assert_array_equal(env_a.positions, env_b.positions)
        assert not np.array_equal(info_a["gain_db"], info_b["gain_db"])
        assert not np.array_equal(obs_a, obs_b)


def test_radio_map_channel_is_deterministic_given_positions():
    # Different seeds, same mission and same actions: identical channel in radio_map mode.
    env_a, env_b = small_env(), small_env()
    env_a.reset(seed=1, options=STRAIGHT)
    env_b.reset(seed=2, options=STRAIGHT)
    action = np.full(env_a.action_space.shape, 0.3, dtype=np.float32)
    _, _, _, _, info_a = env_a.step(action)
    _, _, _, _, info_b = env_b.step(action)
    np.testing.assert_array_equal(info_a["gain_db"], info_b["gain_db"])


def test_reset_draws_from_scenario_regions():
    env = small_env()
    radio_map = env.radio_map
    seen_destinations = set()
    for seed in range(30):
        env.reset(seed=seed)
        for u, robot in enumerate(env.scenario.robots):
            x0, y0, x1, y1 = robot.start
            assert x0 <= env.positions[u, 0] <= x1 and y0 <= env.positions[u, 1] <= y1
            ix, iy = radio_map.cell_index(env.positions[u])
            assert not radio_map.blocked[ix, iy]
            assert any(np.allclose(env.destinations[u], d) for d in robot.destinations)
            seen_destinations.add((u, tuple(env.destinations[u])))
    assert len(seen_destinations) == sum(len(r.destinations) for r in env.scenario.robots)


# --- channel and downlink in the info -----------------------------------------------------------------


@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_info_matches_radio_map_and_downlink(multiple_access):
    env = small_env(multiple_access=multiple_access)
    scenario, radio_map = env.scenario, env.radio_map
    env.reset(seed=0, options=STRAIGHT)
    rng = np.random.default_rng(0)
    for _ in range(5):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        _, _, _, _, info = env.step(action)
        ix, iy = radio_map.cell_index(env.positions)
        gain_db = -radio_map.path_loss_db["ap"][ix, iy] + EXPECTED_FADING_DB
        np.testing.assert_allclose(info["gain_db"], gain_db)
        interference = sum(
            dbm_to_watt(i.power_dbm) * db_to_linear(-radio_map.path_loss_db[i.name][ix, iy] + EXPECTED_FADING_DB)
            for i in scenario.interferers
        )
        power = allocate_power(action.reshape(-1, 3)[:, 2].astype(np.float64), dbm_to_watt(scenario.ap.max_power_dbm))
        np.testing.assert_allclose(info["power_w"], power)
        expected = downlink(
            power,
            db_to_linear(gain_db),
            interference,
            scenario.radio.bandwidth_per_robot_hz,
            dbm_to_watt(scenario.radio.noise_dbm_per_hz),
            multiple_access,
        )
        np.testing.assert_allclose(info["rate_bps"], expected.rate_bps, rtol=1e-12)
        np.testing.assert_allclose(info["sinr_db"], expected.sinr_db, rtol=1e-12)
        np.testing.assert_array_equal(info["decoding_order"], expected.decoding_order)
        np.testing.assert_array_equal(info["outage"], expected.rate_bps < scenario.radio.qos_rate_bps)


def test_rayleigh_fading_statistics():
    # |h|^2 ~ Exp(1): E[10 log10 |h|^2] = -2.51 dB around the radio-map gain, and a spread (std 5.57 dB).
    env = small_env(channel="rayleigh")
    env.reset(seed=0, options=STRAIGHT)
    hold = np.zeros(env.action_space.shape, dtype=np.float32)
    fading = []
    for _ in range(2000):
        _, _, _, _, info = env.step(hold)
        ix, iy = env.radio_map.cell_index(env.positions)
        fading.append(info["gain_db"] + env.radio_map.path_loss_db["ap"][ix, iy])
    fading = np.array(fading)
    assert abs(fading.mean() - EXPECTED_FADING_DB) < 0.4
    assert 5.0 < fading.std() < 6.2


def test_observation_layout():
    env = small_env(observation="destinations")
    env.reset(seed=0, options=STRAIGHT)
    obs, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    obs = obs.reshape(env.n_robots, 6)
    room = np.array([env.scenario.room.width, env.scenario.room.depth])
    np.testing.assert_allclose(obs[:, 0:2], 2 * env.positions / room - 1, atol=1e-6)
    np.testing.assert_allclose(obs[:, 2:4], 2 * np.array(STRAIGHT["destinations"]) / room - 1, atol=1e-6)
    low, high = NomaRadioMapEnv.GAIN_DB_RANGE
    np.testing.assert_allclose(obs[:, 4], np.clip(2 * (info["gain_db"] - low) / (high - low) - 1, -1, 1), atol=1e-6)
    np.testing.assert_array_equal(obs[:, 5], 0.0)


def test_random_rollout_stays_in_spaces_and_free_cells():
    env = NomaRadioMapEnv(scenario="mall", channel="rayleigh")
    for record in rollout(env, seed=5, n_steps=400):
        obs = record if isinstance(record, np.ndarray) else record[0]
        assert env.observation_space.contains(obs)
        assert not env.radio_map.blocked[env.radio_map.cell_index(env.positions)].any()


# --- rewards, phases, MQI ------------------------------------------------------------------------------

PHASE_FORMULAS = {
    "destination": lambda c: c["time"] + c["inducing"] + c["arrival"] + c["success"],
    "mqi": lambda c: c["time"] + c["qos"] + c["arrival"] + c["success"],
    "combined": lambda c: c["time"] + c["inducing"] + c["qos"] + c["arrival"] + c["success"],
}


@pytest.mark.parametrize("phase", NomaRadioMapEnv.REWARD_PHASES)
def test_phase_reward_equals_formula(phase):
    env = small_env(reward_phase=phase)
    weights = env.reward_weights()
    assert set(weights) == set(NomaRadioMapEnv.REWARD_COMPONENTS)
    env.reset(seed=0, options=STRAIGHT)
    seen = set()
    terminated = False
    rng = np.random.default_rng(0)
    while not terminated:
        action = drive_straight(env)
        action[2::3] = rng.uniform(-1, 1, env.n_robots)  # vary the power so that outages happen too
        _, reward, terminated, truncated, info = env.step(action)
        components = info["reward_components"]
        assert reward == pytest.approx(PHASE_FORMULAS[phase](components), abs=1e-12)
        assert reward == pytest.approx(sum(weights[k] * components[k] for k in components), abs=1e-12)
        seen |= {k for k, v in components.items() if v != 0}
        assert not truncated
    assert seen == set(NomaRadioMapEnv.REWARD_COMPONENTS)


def test_set_reward_phase_and_weights():
    env = small_env()
    assert env.reward_phase == "destination"
    assert env.reward_weights("mqi") == {"time": 1.0, "inducing": 0.0, "qos": 1.0, "arrival": 1.0, "success": 1.0}
    env.set_reward_phase("mqi")
    assert env.reward_phase == "mqi"
    assert env.reward_weights() == env.reward_weights("mqi")
    with pytest.raises(ValueError, match=r"reward_phase.*'nope'"):
        env.set_reward_phase("nope")
    with pytest.raises(ValueError, match=r"phase.*'nope'"):
        env.reward_weights("nope")


def test_scripted_episode_mqi_by_hand():
    env = small_env(reward_phase="combined")
    scenario = env.scenario
    env.reset(seed=0, options=STRAIGHT)
    starts, goals = np.array(STRAIGHT["starts"]), np.array(STRAIGHT["destinations"])
    step_length = scenario.robot.v_max * scenario.mission.time_step
    # Straight line at full speed: robot u arrives on the first step whose distance covered reaches d_u - r.
    arrival_steps = np.ceil((np.linalg.norm(goals - starts, axis=1) - scenario.robot.arrival_radius) / step_length)
    infos, rewards = [], []
    terminated = truncated = False
    while not (terminated or truncated):
        _, reward, terminated, truncated, info = env.step(drive_straight(env))
        infos.append(info)
        rewards.append(reward)
    assert terminated and not truncated
    assert len(infos) == arrival_steps.max()
    outage = np.array([info["outage"] for info in infos])
    # A robot's outage only counts until it arrives.
    for u in range(env.n_robots):
        assert not outage[int(arrival_steps[u]) :, u].any()
    expected_mqi = scenario.mission.t_total - (arrival_steps + scenario.mission.outage_penalty * outage.sum(axis=0)).sum()
    last = infos[-1]
    assert last["is_success"] is True
    assert last["mqi"] == pytest.approx(expected_mqi)
    np.testing.assert_array_equal(last["mission_time"], arrival_steps)
    np.testing.assert_array_equal(last["outage_steps"], outage.sum(axis=0))
    # Time cost -1 per robot per step until arrival; +10 on each arrival step; +200 at the end.
    assert sum(i["reward_components"]["time"] for i in infos) == -arrival_steps.sum()
    for k, info in enumerate(infos, start=1):
        assert info["reward_components"]["arrival"] == 10.0 * np.sum(arrival_steps == k)
        assert info["reward_components"]["success"] == (200.0 if k == len(infos) else 0.0)
        # The summary as of each step: success only at the end, the MQI counting the robots still on their way
        assert info["is_success"] is (k == len(infos))
        assert (info["mission_time"] <= np.where(arrival_steps <= k, arrival_steps, env.max_steps)).all()
    # The MQI phase's return is exactly what the MQI counts, plus the arrival and success bonuses.
    mqi_return = sum(
        i["reward_components"]["time"] + i["reward_components"]["qos"] + i["reward_components"]["arrival"] for i in infos
    )
    assert mqi_return == pytest.approx(expected_mqi - scenario.mission.t_total + 10.0 * env.n_robots)
    # Stepping on after the end (outside the Gymnasium contract) pays nothing more.
    _, reward, _, _, info = env.step(drive_straight(env))
    assert reward == 0.0 and not any(info["reward_components"].values())


def test_arrived_robot_stops_gets_no_power_and_no_cost():
    env = small_env(observation="destinations")
    options = {"starts": [[1.25, 1.25], [1.25, 6.75]], "destinations": [[2.5, 1.25], [5.0, 7.0]]}
    env.reset(seed=0, options=options)
    _, _, _, _, info = env.step(drive_straight(env))  # robot 0: 1.25 m away, radius 1 m -> arrives now
    assert env.arrived.tolist() == [True, False]
    assert info["reward_components"]["arrival"] == 10.0
    assert info["reward_components"]["time"] == -2.0
    parked = env.positions[0].copy()
    action = np.ones(env.action_space.shape, dtype=np.float32)  # full power and motion requested for both
    obs, _, _, _, info = env.step(action)
    np.testing.assert_array_equal(env.positions[0], parked)
    assert info["power_w"][0] == 0.0
    assert info["power_w"][1] == pytest.approx(dbm_to_watt(env.scenario.ap.max_power_dbm))
    assert info["reward_components"]["time"] == -1.0
    assert not info["outage"][0]
    obs = obs.reshape(env.n_robots, 6)
    assert obs[0, 5] == 1.0 and obs[1, 5] == 0.0


def test_truncation_and_mqi_when_nobody_arrives():
    wrapped = gym.make("NomaRadioMap-v0", scenario="small")
    env = wrapped.unwrapped
    wrapped.reset(seed=0, options=STRAIGHT)
    hold = np.zeros(env.action_space.shape, dtype=np.float32)
    hold[2::3] = -1.0  # no power at all: every robot is in outage every step
    max_steps = env.scenario.mission.max_steps
    for k in range(1, max_steps + 1):
        _, _, terminated, truncated, info = wrapped.step(hold)
        assert not terminated
        assert truncated == (k == max_steps)
    assert info["is_success"] is False
    np.testing.assert_array_equal(info["mission_time"], [max_steps, max_steps])
    np.testing.assert_array_equal(info["outage_steps"], [max_steps, max_steps])
    expected = env.scenario.mission.t_total - 2 * (max_steps + env.scenario.mission.outage_penalty * max_steps)
    assert info["mqi"] == pytest.approx(expected)


def test_time_limit_of_registered_id_ends_episode_with_summary():
    env = gym.make("NomaRadioMap-v0")
    env.reset(seed=0)
    hold = np.zeros(env.action_space.shape, dtype=np.float32)
    for _ in range(MALL_STEPS):
        _, _, terminated, truncated, info = env.step(hold)
    assert truncated and not terminated
    assert "mqi" in info and info["is_success"] is False


def test_geodesic_inducing_uses_grid_distance():
    env = small_env(inducing="geodesic")
    # Robot 0 behind the wall (x = 6 m, doorway at y in [5, 6.5]) from its destination: geodesic > Euclidean.
    options = {"starts": [[4.75, 1.25], [1.25, 6.75]], "destinations": [[8.0, 1.25], [4.0, 7.0]]}
    env.reset(seed=0, options=options)
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    fields = [env.radio_map.distance_field(d) for d in env.destinations]
    cells = env.radio_map.cell_index(env.positions)
    geodesic = np.array([field[cells[0][u], cells[1][u]] for u, field in enumerate(fields)])
    d_max = math.hypot(env.scenario.room.width, env.scenario.room.depth)
    assert info["reward_components"]["inducing"] == pytest.approx(np.sum(1 - geodesic / d_max))
    euclidean = np.linalg.norm(env.positions - env.destinations, axis=1)
    assert geodesic[0] > euclidean[0] + 2.0


# --- reset options ------------------------------------------------------------------------------------


def closet_scenario() -> Scenario:
    """`small` plus a closed closet in the bottom-right corner (x in [11, 12], y in [0, 1]): unreachable."""
    data = load_scenario("small").to_dict()
    data["obstacles"].append({"name": "closet", "boxes": [[10.5, 1.0, 12.0, 1.5, 0.0, 3.0], [10.5, 0.0, 11.0, 1.0, 0.0, 3.0]]})
    return Scenario.from_dict(data)


@pytest.mark.parametrize(
    "options,match",
    [
        ({"starts": [[1.0, 1.0]]}, r"options\['starts'\].*2 finite points"),
        ({"destinations": [[1.0, 1.0], [2.0]]}, r"options\['destinations'\]"),
        ({"starts": [[1.0, 1.0], [float("nan"), 1.0]]}, r"options\['starts'\]"),
        ({"starts": [[1.0, 1.0], [-0.5, 1.0]]}, r"options\['starts'\]\[1\].*outside the room or in a blocked cell"),
        ({"starts": [[6.25, 1.0], [1.0, 7.0]]}, r"options\['starts'\]\[0\].*blocked"),
        ({"destinations": [[11.5, 0.5], [4.0, 7.0]]}, r"unreachable"),
        ({"starts": [[4.5, 3.0], [1.25, 6.75]], "destinations": [[5.0, 3.0], [4.0, 7.0]]}, r"arrival_radius"),
        ({"start": [[1.0, 1.0], [1.0, 7.0]]}, r"options.*unknown keys \['start'\]"),
        ({"starts": "here"}, r"options\['starts'\]"),
    ],
)
def test_reset_options_validation(options, match):
    env = NomaRadioMapEnv(scenario=closet_scenario())
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)


def test_reset_options_fix_the_mission():
    env = small_env()
    env.reset(seed=0, options=STRAIGHT)
    np.testing.assert_array_equal(env.positions, STRAIGHT["starts"])
    np.testing.assert_array_equal(env.destinations, STRAIGHT["destinations"])
    # Only destinations given: starts are drawn from the start regions.
    env.reset(seed=0, options={"destinations": STRAIGHT["destinations"]})
    np.testing.assert_array_equal(env.destinations, STRAIGHT["destinations"])
    for u, robot in enumerate(env.scenario.robots):
        x0, y0, x1, y1 = robot.start
        assert x0 <= env.positions[u, 0] <= x1 and y0 <= env.positions[u, 1] <= y1


def test_given_starts_draw_only_the_destinations_a_mission_from_them_can_have():
    # Robot 0 of `small` goes to (10, 2) or (10, 6): from (10, 2.5) it is already at the first, so every reset must
    # send it to the second (it was refused on about one seed in four), and robot 1 to either of its two.
    env = small_env()
    drawn = set()
    for seed in range(40):
        env.reset(seed=seed, options={"starts": [[10.0, 2.5], [1.0, 6.0]]})
        assert env.destinations[0].tolist() == [10.0, 6.0]
        drawn.add(tuple(env.destinations[1]))
    assert drawn == {(9.0, 4.0), (11.0, 7.0)}
    # A start from which no destination can be had (the closet's, unreachable) is refused, naming it.
    with pytest.raises(
        ValueError, match=r"options\['starts'\]\[0\]: \[11\.5, 0\.5\] is within arrival_radius of, or unreachable"
    ):
        NomaRadioMapEnv(scenario=closet_scenario()).reset(seed=0, options={"starts": [[11.5, 0.5], [1.0, 6.0]]})


def test_given_destinations_draw_starts_uniformly_from_the_start_region():
    # Robot 0 also lists (1, 1), inside its start region: the cells near it are no less likely than the others
    # for a destination given elsewhere (they were drawn half as often).
    data = load_scenario("small").to_dict()
    data["robots"][0]["destinations"] = [[1.0, 1.0], [10.0, 2.0]]
    env = NomaRadioMapEnv(scenario=Scenario.from_dict(data))
    env.reset(seed=0)
    counts: dict[tuple[float, float], int] = {}
    for _ in range(4000):
        env.reset(options={"destinations": [[10.0, 6.0], [9.0, 4.0]]})
        start = tuple(env.positions[0])
        counts[start] = counts.get(start, 0) + 1
    near = [n for (x, y), n in counts.items() if np.hypot(x - 1.0, y - 1.0) <= 1.0]
    far = [n for (x, y), n in counts.items() if np.hypot(x - 1.0, y - 1.0) > 1.0]
    assert near and far
    assert 0.8 < np.mean(near) / np.mean(far) < 1.25


# --- pickling, vec envs, rendering --------------------------------------------------------------------


def test_pickle_round_trip_continues_identically():
    env = small_env(channel="rayleigh", render_mode="rgb_array")
    env.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(3):
        env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
    env.render()
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(10):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        assert_same(env.step(action), clone.step(action))
    assert clone.render().shape == env.render().shape


def test_set_reward_phase_through_dummy_vec_env():
    vec_env = make_vec_env("NomaRadioMap-v0", n_envs=2, env_kwargs={"scenario": "small"}, vec_env_cls=DummyVecEnv)
    vec_env.env_method("set_reward_phase", "mqi")
    assert vec_env.get_attr("reward_phase") == ["mqi", "mqi"]
    assert vec_env.env_method("reward_weights", indices=0)[0]["inducing"] == 0.0
    vec_env.close()


def test_subproc_vec_env_spawn_with_module_prefixed_id():
    vec_env = make_vec_env(
        "noma_radiomap:NomaRadioMap-v0",
        n_envs=2,
        seed=0,
        env_kwargs={"scenario": "small"},
        vec_env_cls=SubprocVecEnv,
        vec_env_kwargs={"start_method": "spawn"},
    )
    try:
        obs = vec_env.reset()
        assert obs.shape == (2, 18)  # the default "goal" layout
        vec_env.env_method("set_reward_phase", "combined")
        assert vec_env.get_attr("reward_phase") == ["combined", "combined"]
        obs, rewards, _, infos = vec_env.step(np.zeros((2, 6), dtype=np.float32))
        assert obs.shape == (2, 18) and rewards.shape == (2,)
        assert set(infos[0]["reward_components"]) == set(NomaRadioMapEnv.REWARD_COMPONENTS)
    finally:
        vec_env.close()


def test_render_rgb_array_draws_robots_and_trajectories():
    env = small_env(render_mode="rgb_array")
    env.reset(seed=0, options=STRAIGHT)
    first = env.render()
    assert first.ndim == 3 and first.shape[2] == 3 and first.dtype == np.uint8
    for _ in range(3):
        env.step(drive_straight(env))
    second = env.render()
    assert second.shape == first.shape
    assert not np.array_equal(first, second)
    env.close()


def test_render_human_is_safe_without_display():
    import matplotlib

    matplotlib.use("Agg")
    env = small_env(render_mode="human")
    env.reset(seed=0)
    assert env.render() is None
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()


def test_package_exports():
    assert noma_radiomap.NomaRadioMapEnv is NomaRadioMapEnv
    assert isinstance(small_env().radio_map, RadioMap)
    assert "NomaRadioMap-v0" in gym.registry
