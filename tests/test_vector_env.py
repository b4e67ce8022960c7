"""The batched mission env (NomaRadioMapVecEnv, MissionVecEnv): same transitions as N single envs, the SB3 and
Gymnasium vector-env contracts, and DT-DPG / the baselines training from it."""

import dataclasses
import json
import re

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.noise import VectorizedActionNoise
from stable_baselines3.common.vec_env import DummyVecEnv

import noma_radiomap  # noqa: F401
from noma_radiomap.vector import NomaRadioMapVecEnv
from sb3_dtdpg import DTDPG, Phase
from sb3_dtdpg.baselines import make_model
from sb3_dtdpg.common.buffers import RewardComponentsReplayBuffer
from sb3_dtdpg.common.noise import LinearDecayOUNoise
from sb3_dtdpg.vec_env import MissionVecEnv, make_mission_vec_env


def assert_same(a, b, path="info"):
    """Equal values, keys and (for scalars) types, recursively."""
    if isinstance(a, dict):
        assert set(a) == set(b), (path, set(a) ^ set(b))
        for key in a:
            assert_same(a[key], b[key], f"{path}[{key!r}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert np.asarray(a).dtype == np.asarray(b).dtype, path
        np.testing.assert_array_equal(a, b, err_msg=path)
    else:
        assert type(a) is type(b) and a == b, (path, a, b)


def homing_actions(obs: np.ndarray, rng: np.random.Generator, n_robots: int = 2) -> np.ndarray:
    """Head for the destinations with noise (episodes that end by arrival and by truncation), random powers."""
    per_robot = obs[:, : 6 * n_robots].reshape(len(obs), n_robots, 6)  # the paper's part of the observation
    actions = np.empty((len(obs), per_robot.shape[1], 3), dtype=np.float32)
    actions[..., :2] = 3.0 * (per_robot[..., 2:4] - per_robot[..., 0:2]) + rng.normal(0.0, 0.7, per_robot[..., :2].shape)
    actions[..., 2] = rng.uniform(-1.0, 1.0, per_robot.shape[:2])
    return np.clip(actions, -1.0, 1.0).reshape(len(obs), -1)


CASES = [
    ("NomaRadioMap-v0", {}),
    ("NomaRadioMapOMAReality-v0", {}),
    ("NomaRadioMapReality-v0", {"inducing": "geodesic", "reward_phase": "combined"}),
    ("NomaRadioMapReality-v0", {"observation": "goal"}),
]


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_sb3_face_gives_the_transitions_of_a_dummy_vec_env(env_id, kwargs):
    n, seed = 3, 11
    kwargs = {"scenario": "small", **kwargs}
    batched = MissionVecEnv.from_id(env_id, n, **kwargs)
    single = DummyVecEnv([lambda: gym.make(env_id, **kwargs)] * n)
    batched.seed(seed)
    single.seed(seed)
    obs = batched.reset()
    np.testing.assert_array_equal(obs, single.reset())
    rng = np.random.default_rng(0)
    ends = {"terminated": 0, "truncated": 0}
    for t in range(400):
        if t == 150:  # a phase switch on one mission only
            for env in (batched, single):
                env.env_method("set_reward_phase", "mqi", indices=[1])
        actions = homing_actions(obs, rng)
        obs, rewards, dones, infos = batched.step(actions)
        single_obs, single_rewards, single_dones, single_infos = single.step(actions)
        np.testing.assert_array_equal(obs, single_obs)
        assert rewards.dtype == single_rewards.dtype
        np.testing.assert_array_equal(rewards, single_rewards)
        np.testing.assert_array_equal(dones, single_dones)
        for info, single_info in zip(infos, single_infos, strict=True):
            assert_same(info, single_info)
            if "terminal_observation" in info:
                ends["truncated" if info["TimeLimit.truncated"] else "terminated"] += 1
    assert ends["terminated"] >= 3 and ends["truncated"] >= 3, ends
    assert batched.get_attr("reward_phase") == single.get_attr("reward_phase")


@pytest.mark.parametrize(("env_id", "kwargs"), CASES[1:])
def test_make_vec_gives_the_transitions_of_a_sync_vector_env(env_id, kwargs):
    n, seed = 3, 5
    kwargs = {"scenario": "small", **kwargs}
    batched = gym.make_vec(env_id, num_envs=n, **kwargs)
    single = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", **kwargs)
    assert isinstance(batched.unwrapped, NomaRadioMapVecEnv)
    assert batched.metadata["autoreset_mode"] == single.metadata["autoreset_mode"]
    obs, _ = batched.reset(seed=seed)
    np.testing.assert_array_equal(obs, single.reset(seed=seed)[0])
    rng = np.random.default_rng(1)
    n_ends = 0
    for _ in range(250):
        actions = homing_actions(obs, rng)
        obs, rewards, terminated, truncated, infos = batched.step(actions)
        single_obs, single_rewards, single_terminated, single_truncated, single_infos = single.step(actions)
        for a, b in (
            (obs, single_obs),
            (rewards, single_rewards),
            (terminated, single_terminated),
            (truncated, single_truncated),
        ):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        assert_same(infos, single_infos)
        n_ends += int(np.sum(terminated | truncated))
    assert n_ends >= 6
    assert batched.call("reward_weights", "mqi") == single.call("reward_weights", "mqi")
    assert batched.get_attr("reward_phase") == single.get_attr("reward_phase")


def test_move_batch_gives_the_bits_of_move():
    env = gym.make("NomaRadioMap-v0").unwrapped
    motion, rng = env.core.motion, np.random.default_rng(3)
    free = np.argwhere(~env.radio_map.blocked)
    positions = (
        free[rng.integers(len(free), size=(64, 2))] + rng.uniform(0.0, 1.0, (64, 2, 2))
    ) * env.scenario.room.resolution
    destinations = (free[rng.integers(len(free), size=(64, 2))] + 0.5) * env.scenario.room.resolution
    active = np.ones((64, 2), dtype=bool)
    for _ in range(60):
        actions = rng.uniform(-1.5, 1.5, (64, 2, 2))
        actions[rng.random((64, 2)) < 0.1] = 0.0
        new, arrived = motion.move_batch(positions, actions, destinations, active)
        for i in range(len(positions)):
            one, one_arrived = motion.move(positions[i], actions[i], destinations[i], active[i])
            np.testing.assert_array_equal(new[i], one)
            np.testing.assert_array_equal(arrived[i], one_arrived)
        positions, active = new, active & ~arrived


def test_env_method_reward_phases_and_components():
    env = MissionVecEnv(4, scenario="small")
    env.seed(0)
    env.reset()
    env.env_method("set_reward_phase", "mqi", indices=[0, 2])
    assert env.get_attr("reward_phase") == ["mqi", "destination", "mqi", "destination"]
    assert env.env_method("reward_weights") == [env.get_attr("reward_weights")[i]() for i in range(4)]
    _, rewards, _, infos = env.step(np.zeros((4, 6), dtype=np.float32))
    for i, info in enumerate(infos):
        weights = env.env_method("reward_weights", indices=[i])[0]
        assert rewards[i] == np.float32(sum(weights[k] * v for k, v in info["reward_components"].items()))
    assert env.env_method("reward_weights", "destination")[0]["qos"] == 0.0
    assert env.get_attr("scenario", indices=[3])[0].name == "small"
    assert env.get_attr("step_count") == [1, 1, 1, 1]
    with pytest.raises(ValueError, match="reward_phase"):
        env.env_method("set_reward_phase", "fast")


def test_seed_and_set_options_give_the_missions_of_a_dummy_vec_env():
    n, kwargs = 3, {"scenario": "small"}
    batched = MissionVecEnv.from_id("NomaRadioMap-v0", n, **kwargs)
    single = DummyVecEnv([lambda: gym.make("NomaRadioMap-v0", **kwargs)] * n)

    def missions(env):
        """Starts and destinations of every mission, (N, U, 2) each."""
        return np.stack(env.get_attr("positions")), np.stack(env.get_attr("destinations"))

    def assert_same_resets():
        np.testing.assert_array_equal(batched.reset(), single.reset())
        for batched_points, single_points in zip(missions(batched), missions(single), strict=True):
            np.testing.assert_array_equal(batched_points, single_points)

    assert batched.seed(7) == list(single.seed(7)) == [7, 8, 9]
    assert_same_resets()
    starts, destinations = missions(batched)
    assert_same_resets()  # the seeds serve one reset: the generators go on
    for env in (batched, single):
        env.set_options({"starts": starts[0]})
    assert_same_resets()
    np.testing.assert_array_equal(missions(batched)[0], np.broadcast_to(starts[0], starts.shape))
    per_mission = [{} if i == 1 else {"starts": starts[i], "destinations": destinations[i]} for i in range(n)]
    for env in (batched, single):
        env.seed(3)
        env.set_options(per_mission)
    assert_same_resets()
    np.testing.assert_array_equal(missions(batched)[1][[0, 2]], destinations[[0, 2]])
    np.random.seed(5)
    drawn = batched.seed()
    np.random.seed(5)
    assert drawn == list(single.seed())
    assert_same_resets()


def test_make_mission_vec_env_monitors_episodes():
    env = make_mission_vec_env("NomaRadioMap-v0", n_envs=2, seed=0, env_kwargs={"scenario": "small", "max_episode_steps": 5})
    env.reset()
    for _ in range(5):
        _, _, dones, infos = env.step(np.zeros((2, 6), dtype=np.float32))
    assert dones.all()
    for info in infos:
        assert set(info["episode"]) == {"r", "l", "t", "is_success"} and info["episode"]["l"] == 5
        assert info["TimeLimit.truncated"] and "mqi" in info and info["terminal_observation"].shape == (18,)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"num_envs": 0}, "num_envs"),
        ({"num_envs": 10**8}, r"num_envs: 100,000,000 missions need about 223\.52 GiB .* more than the cap"),
        ({"render_mode": "human"}, "render_mode"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
    ],
)
def test_bad_arguments_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        NomaRadioMapVecEnv(**{"scenario": "small", **kwargs})


@pytest.mark.parametrize("n_envs", [0, -1, 2.0, True])
def test_make_mission_vec_env_names_its_own_argument(n_envs):
    with pytest.raises(ValueError, match=rf"n_envs must be an integer >= 1, got {n_envs!r}"):
        make_mission_vec_env(n_envs=n_envs, env_kwargs={"scenario": "small"})


@pytest.mark.parametrize("n_envs", [2, 4])
def test_dtdpg_curriculum_on_the_vector_env(tmp_path, n_envs):
    env = make_mission_vec_env(n_envs=n_envs, seed=0, env_kwargs={"scenario": "small", "max_episode_steps": 10})
    phases = [
        Phase("destination", n_episodes=5, sigma=0.5, final_sigma=0.1, decay_episodes=6),
        Phase("mqi", sigma=0.3, final_sigma=0.05, decay_episodes=10, replay_handling="relabel"),
    ]
    model = DTDPG(
        "MlpPolicy",
        env,
        phases=phases,
        learning_starts=20,
        batch_size=16,
        train_freq=1,
        gradient_steps=n_envs,
        policy_kwargs={"net_arch": [16]},
        curriculum_save_path=str(tmp_path),
        seed=0,
    )
    model.learn(120)
    # Episodes are counted over all missions: phase 1 ends after 5 of them (<= 30 steps of each mission)
    assert model.curriculum_state["phase_index"] == 1
    assert (tmp_path / "phase_0_destination.zip").exists()
    assert env.get_attr("reward_phase") == ["mqi"] * n_envs
    assert isinstance(model.replay_buffer, RewardComponentsReplayBuffer) and model.replay_buffer.n_envs == n_envs
    # Relabelled: every stored reward is the mqi reward of its components
    buffer, weights = model.replay_buffer, env.env_method("reward_weights", "mqi", indices=[0])[0]
    size = buffer.pos
    stored = buffer.rewards[:size]
    relabelled = sum(weights[k] * buffer.reward_components[:size, :, j] for j, k in enumerate(buffer.component_keys))
    np.testing.assert_allclose(stored, relabelled, rtol=1e-6)
    # One noise schedule for all missions
    noise = model.action_noise
    assert isinstance(noise, VectorizedActionNoise) and len(noise.noises) == n_envs
    assert all(isinstance(k, LinearDecayOUNoise) for k in noise.noises)
    assert len({id(k._schedule) for k in noise.noises}) == 1
    # The model saves and resumes on the vector env
    model.save(tmp_path / "model.zip")
    loaded = DTDPG.load(tmp_path / "model.zip", env=env)
    assert loaded.curriculum_state["phase_index"] == 1
    loaded.learn(2 * n_envs, reset_num_timesteps=False)


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
def test_baselines_train_from_the_vector_env(algo):
    env = make_mission_vec_env(n_envs=3, seed=0, env_kwargs={"scenario": "small", "reward_phase": "combined"})
    model = make_model(
        algo, env, seed=0, learning_starts=10, batch_size=16, train_freq=1, gradient_steps=3, policy_kwargs={"net_arch": [16]}
    )
    model.learn(30)
    assert model.num_timesteps == 30 and model.replay_buffer.pos == 10


def test_study_workers_share_the_runs(tmp_path):
    """Two workers on one JournalFile study run every run once, and a finished run is not run again."""
    from sb3_dtdpg.experiments.distributed import run_study_worker, study_specs
    from sb3_dtdpg.experiments.runs import result_path, run_identity

    specs = study_specs("compare", "tiny", seeds=2)
    ran = []

    def fake_run(spec, out):  # what a run leaves: its result file, with the run's identity
        ran.append(spec.run_id)
        path = result_path(out, spec)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"identity": run_identity(spec)}))

    storage = str(tmp_path / "study.log")
    first = run_study_worker(specs, tmp_path, storage, "job", n_runs=2, run=fake_run)
    second = run_study_worker(specs, tmp_path, storage, "job", run=fake_run)
    assert len(first) == 2 and sorted(first + second) == sorted(spec.run_id for spec in specs)
    assert sorted(ran) == sorted(spec.run_id for spec in specs)
    assert run_study_worker(specs, tmp_path, storage, "job", run=fake_run) == []


def _mission_state(core):
    """Everything a reset changes: the state arrays, the observations and each mission's generator state."""
    arrays = (core.positions, core.destinations, core.arrived, core.step_counts, core.arrival_steps, core.outage_steps)
    return [a.copy() for a in (*arrays, core.gain_db, core.observations())], [r.bit_generator.state for r in core.np_randoms]


def _assert_same_state(before, after):
    for a, b in zip(before[0], after[0], strict=True):
        np.testing.assert_array_equal(a, b)
    assert before[1] == after[1]


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"reset_mask": [True] * 5}, r"options\['reset_mask'\]: expected 3 booleans \(one per mission\), got shape \(5,\)"),
        ({"reset_mask": [1, 0, 1]}, r"options\['reset_mask'\]: expected booleans \(dtype bool\), got dtype int"),
        ({"reset_mask": [[True, False]]}, r"options\['reset_mask'\]: expected 3 booleans .* got shape \(1, 2\)"),
        ({"starts": [[1.0, 1.0], [100.0, 100.0]]}, r"options\['starts'\]\[1\]: \[100\.0, 100\.0\] is outside the room"),
        (
            {"starts": [[1.0, 1.0], [1.0, 6.0]], "destinations": [[1.2, 1.2], [9.0, 4.0]]},
            r"options: start \[1\.0, 1\.0\] of robot 0 is already within arrival_radius",
        ),
        ({"speed": 2}, r"options: unknown keys \['speed'\]"),
    ],
)
def test_a_refused_vector_reset_leaves_every_mission_as_it_was(options, match):
    rng = np.random.default_rng(1)
    envs = [gym.make_vec("NomaRadioMap-v0", num_envs=3, scenario="small") for _ in range(2)]
    for env in envs:
        env.reset(seed=0)
    for _ in range(4):
        actions = rng.uniform(-1, 1, (3, 6))
        for env in envs:
            env.step(actions)
    env, twin = envs
    before = _mission_state(env.core)
    with pytest.raises(ValueError, match=match):
        env.reset(seed=5, options=options)
    _assert_same_state(before, _mission_state(env.core))
    # The refused reset left no trace: the env goes on as its twin that never saw it
    for _ in range(3):
        actions = rng.uniform(-1, 1, (3, 6))
        for a, b in zip(env.step(actions), twin.step(actions), strict=True):
            np.testing.assert_equal(a, b)
    np.testing.assert_array_equal(env.core.step_counts, [7, 7, 7])
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])


def test_a_refused_sb3_reset_leaves_the_missions_drawn_before_it_as_they_were():
    """Per-mission options: mission 0 is drawn (from its generator) before mission 1's option is refused."""
    envs = [MissionVecEnv(3, scenario="small") for _ in range(2)]
    rng = np.random.default_rng(2)
    for env in envs:
        env.seed(0)
        env.reset()
    for _ in range(4):
        actions = rng.uniform(-1, 1, (3, 6)).astype(np.float32)
        for env in envs:
            env.step(actions)
    env, twin = envs
    before = _mission_state(env.vec_env.core)
    env.set_options([{}, {"starts": [[1, 1], [100, 100]]}, {}])
    with pytest.raises(ValueError, match=r"options\['starts'\]\[1\]: \[100\.0, 100\.0\] is outside the room"):
        env.reset()
    _assert_same_state(before, _mission_state(env.vec_env.core))
    env.set_options([{}, {}])
    with pytest.raises(ValueError, match=r"options: expected one dict per reset mission \(3\), got a list of 2"):
        env.reset()
    env.set_options(["starts", {}, {}])
    with pytest.raises(ValueError, match=r"options\[0\]: expected a dict of reset options \(or None\), got str"):
        env.reset()
    _assert_same_state(before, _mission_state(env.vec_env.core))
    # The refused options served their reset, as SB3's serve one: the next reset draws the missions anew
    actions = rng.uniform(-1, 1, (3, 6)).astype(np.float32)
    for a, b in zip(env.step(actions), twin.step(actions), strict=True):
        np.testing.assert_equal(a, b)
    np.testing.assert_array_equal(env.reset(), twin.reset())


@pytest.mark.parametrize(
    ("name", "instead"),
    [
        ("trajectory", r"the vector env keeps no trajectories: record get_attr\('positions'\)"),
        ("render", r"the vector env does not render: render a single env"),
        ("reset", r"reset the vector env"),
        ("core", r"the vector env.s engine is vec_env\.core"),
        ("step_counts", r"a mission has .*positions, .*step_count"),
        ("np_randoms", r"a mission has .*np_random,"),
    ],
)
def test_a_mission_of_the_vector_envs_answers_its_own_values_or_names_the_attribute(name, instead):
    gym_env, sb3_env = NomaRadioMapVecEnv(3, scenario="small"), MissionVecEnv(3, scenario="small")
    gym_env.reset(seed=0)
    sb3_env.reset()
    match = rf"'{name}': not an attribute of a mission of the vector env; {instead}"
    for get in (gym_env.get_attr, gym_env.call, sb3_env.get_attr, sb3_env.env_method):
        with pytest.raises(AttributeError, match=match):
            get(name)
    assert not sb3_env.has_attr(name)
    # The values a mission has are its own, or those every mission shares
    core = gym_env.core
    for i, positions in enumerate(gym_env.get_attr("positions")):
        np.testing.assert_array_equal(positions, core.positions[i])
    assert gym_env.get_attr("np_random") == tuple(core.np_randoms)
    assert gym_env.get_attr("step_count") == (0, 0, 0)
    assert gym_env.get_attr("render_mode") == (None, None, None) and sb3_env.render_mode is None
    assert gym_env.get_attr("REWARD_PHASES")[2] == NomaRadioMapVecEnv.REWARD_PHASES
    assert gym_env.get_attr("scenario")[1] is core.scenario and gym_env.get_attr("max_episode_steps") == (60, 60, 60)
    assert sb3_env.has_attr("reward_weights") and not sb3_env.has_attr("default_curriculum")


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda env: env.reset(options=[{}]), ValueError, r"options: expected a dict of reset options \(or None\), got list"),
        (lambda env: env.reset(options="starts"), ValueError, r"options: expected a dict .* got str"),
        (lambda env: env.reset(seed=1.5), ValueError, r"seed: expected an integer >= 0, a list of 3 .* got 1\.5"),
        (lambda env: env.reset(seed=-1), ValueError, r"seed: expected an integer >= 0, .* got -1"),
        (lambda env: env.reset(seed="7"), ValueError, r"seed: expected an integer >= 0, .* got '7'"),
        (lambda env: env.reset(seed=[0, 1]), ValueError, r"seed: expected 3 seeds \(one per mission\), got 2"),
        (lambda env: env.reset(seed=[0, 1.5, None]), ValueError, r"seed\[1\]: expected an integer >= 0 or None, got 1\.5"),
        (lambda env: env.set_reward_phase("mqi", 10), IndexError, r"indices: mission indices must be .* \[0, 3\), got 10"),
        (lambda env: env.set_reward_phase("mqi", -1), IndexError, r"indices: mission indices must be .* \[0, 3\), got -1"),
        (lambda env: env.set_reward_phase("mqi", [0, 3]), IndexError, r"indices: .* got 3"),
        (lambda env: env.set_reward_phase("mqi", 1.0), IndexError, r"indices: expected None, a mission index .* got 1\.0"),
    ],
)
def test_bad_reset_and_phase_arguments_of_the_vector_env_are_named(call, error, match):
    env = NomaRadioMapVecEnv(3, scenario="small")
    env.reset(seed=0)
    before = _mission_state(env.core)
    with pytest.raises(error, match=match):
        call(env)
    _assert_same_state(before, _mission_state(env.core))
    assert env.reward_phases == ["destination"] * 3


@pytest.mark.parametrize("value", [2.7, "5", True, 0, -3])
def test_max_episode_steps_of_the_vector_env_must_be_an_integer(value):
    with pytest.raises(
        ValueError, match=rf"max_episode_steps must be an integer >= 1 \(or None\), got {re.escape(repr(value))}"
    ):
        NomaRadioMapVecEnv(2, scenario="small", max_episode_steps=value)
    assert NomaRadioMapVecEnv(2, scenario="small", max_episode_steps=np.int64(5)).max_episode_steps == 5


def test_max_episode_steps_of_the_vector_env_must_not_exceed_the_missions():
    with pytest.raises(
        ValueError,
        match=r"max_episode_steps must be at most mission\.max_steps = 60 of scenario 'small' \(its missions end there\), "
        r"got 61",
    ):
        gym.make_vec("NomaRadioMap-v0", num_envs=2, scenario="small", max_episode_steps=61)
    with pytest.raises(ValueError, match=r"max_episode_steps must be at most mission\.max_steps = 60 .* got 100"):
        make_mission_vec_env("NomaRadioMap-v0", n_envs=2, seed=0, env_kwargs={"scenario": "small", "max_episode_steps": 100})
    assert NomaRadioMapVecEnv(2, scenario="small", max_episode_steps=60).max_episode_steps == 60
    assert NomaRadioMapVecEnv(2, scenario="small", task="paper", max_episode_steps=1000).max_episode_steps == 1000


@pytest.mark.parametrize(
    ("actions", "match"),
    [
        (np.zeros((5, 6)), r"actions: expected shape \(2, 6\) \(one flat action per mission\), got shape \(5, 6\)"),
        (np.zeros((1, 6)), r"actions: expected shape \(2, 6\) \(one flat action per mission\), got shape \(1, 6\)"),
        (np.zeros((2, 7)), r"actions: expected shape \(2, 6\) .* got shape \(2, 7\)"),
        (np.zeros(3), r"actions: expected shape \(2, 6\) .* got shape \(3,\)"),
        ("garbage", r"actions: expected shape \(2, 6\) .* got shape \(\)"),
        (np.zeros((2, 6), dtype=bool), r"actions: expected real numbers, got dtype bool"),
        ([[0.0] * 6, [0.0] * 5], r"actions: expected an array of shape \(2, 6\), got list"),
        (np.array([[0.0] * 6, [0.0] * 5 + [np.nan]]), r"actions\[1, 5\] \(mission 1, robot 1, power\): expected a finite"),
    ],
    ids=["5_missions", "1_mission", "7_components", "flat", "a_string", "bools", "ragged", "nan"],
)
@pytest.mark.parametrize("ended", [[True, True], [True, False]], ids=["all_resetting", "one_resetting"])
def test_the_action_batch_is_checked_on_an_autoreset_step(actions, match, ended):
    """The step after an episode ends resets its mission and ignores its action, but the batch is checked whole."""
    env = NomaRadioMapVecEnv(2, scenario="small", max_episode_steps=2)
    env.reset(seed=0)
    env.step(np.zeros((2, 6)))
    if not ended[1]:
        env.reset(seed=5, options={"reset_mask": np.array([False, True])})
    assert env.step(np.zeros((2, 6)))[3].tolist() == ended
    before = (env.positions.copy(), env.step_counts.copy(), env.core.outage_steps.copy())
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    for old, new in zip(before, (env.positions, env.step_counts, env.core.outage_steps), strict=True):
        np.testing.assert_array_equal(old, new)
    _, reward, _, truncated, _ = env.step(np.zeros((2, 6)))  # the autoreset step, taken now
    assert env.step_counts.tolist() == [0, 0 if ended[1] else 2] and not truncated[0] and reward[0] == 0.0


def test_study_worker_takes_the_cli_options_and_defaults(monkeypatch, capsys):
    """The worker's runs are those ``sb3-dtdpg reproduce`` / ``compare`` train with the same options (same run ids)."""
    from sb3_dtdpg.experiments import distributed
    from sb3_dtdpg.experiments.budgets import BUDGETS
    from sb3_dtdpg.experiments.compare import compare_specs
    from sb3_dtdpg.experiments.reproduce import DEFAULT_EXPERIMENTS, reproduce_specs

    taken = {}

    def worker(specs, *args):
        taken["ids"] = specs
        return []

    monkeypatch.setattr(distributed, "run_study_worker", worker)
    storage = ["--out", "out", "--storage", "s.log", "--study-name", "job"]
    distributed.main(["reproduce", "--budget", "tiny", *storage])
    by_experiment = reproduce_specs(BUDGETS["tiny"], BUDGETS["tiny"].seeds, "tuned", "goal")
    expected = {spec.run_id for name in DEFAULT_EXPERIMENTS for spec in by_experiment[name]}
    assert {spec.run_id for spec in taken.pop("ids")} == expected
    distributed.main(["compare", "--budget", "tiny", "--seeds", "1", "--hyperparams", "paper", *storage])
    assert [s.run_id for s in taken.pop("ids")] == [s.run_id for s in compare_specs(BUDGETS["tiny"], 1, hyperparams="paper")]
    assert "--seeds is deprecated, use --n-seeds" in capsys.readouterr().err
    # compare's options that pick its runs: algorithms (and so the preset), env id (and so its observation), scenario
    picks = ["--algos", "dtdpg", "td3", "--env", "NomaRadioMapPaper-v0", "--scenario", "small"]
    distributed.main(["compare", "--budget", "tiny", "--n-seeds", "1", *picks, *storage])
    budget = dataclasses.replace(BUDGETS["tiny"], scenario="small")
    expected = compare_specs(budget, 1, ["dtdpg", "td3"], ["noma", "oma"], "NomaRadioMapPaper-v0", "paper", "paper")
    assert [s.run_id for s in taken.pop("ids")] == [s.run_id for s in expected]
    assert {(s.scenario, s.observation, s.env_id) for s in expected} == {("small", "paper", "NomaRadioMapPaper-v0")}
    with pytest.raises(SystemExit):
        distributed.main(["compare", "--env", "Pendulum-v1", *storage])
    assert "env: compare runs on the NomaRadioMap envs, got Pendulum-v1" in capsys.readouterr().err


def test_a_study_worker_without_optuna_names_the_extra_in_one_line(monkeypatch, capsys):
    import sys

    from sb3_dtdpg.experiments import distributed

    monkeypatch.setitem(sys.modules, "optuna", None)  # not installed
    with pytest.raises(SystemExit) as exit_info:
        distributed.main(["compare", "--budget", "tiny", "--out", "out", "--storage", "s.log", "--study-name", "job"])
    errors = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    assert exit_info.value.code == 2 and len(errors) == 1 and "need the 'zoo' extra (optuna is not installed)" in errors[0]


def test_a_study_worker_meeting_another_runs_result_says_so_in_one_line(monkeypatch, capsys):
    from sb3_dtdpg.experiments import distributed
    from sb3_dtdpg.experiments.runs import RunMismatchError

    def worker(specs, *args):
        raise RunMismatchError("runs/ddpg_noma_s0_tuned_goal/result.json belongs to another run with the same id")

    monkeypatch.setattr(distributed, "run_study_worker", worker)
    with pytest.raises(SystemExit) as exit_info:
        distributed.main(["compare", "--budget", "tiny", "--out", "out", "--storage", "s.log", "--study-name", "job"])
    errors = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    assert exit_info.value.code == 2 and len(errors) == 1 and "belongs to another run with the same id" in errors[0]


@pytest.mark.parametrize("seed", [-3, 1.5, True, "0"])
def test_a_seed_no_mission_can_have_is_refused_when_given(seed):
    env = make_mission_vec_env(n_envs=2, env_kwargs={"scenario": "small"})
    with pytest.raises(ValueError, match=re.escape(f"seed must be an integer >= 0 or None, got {seed!r}")):
        env.seed(seed)  # was Gymnasium's error at the next reset (inside learn()); True was taken as seed 1
    with pytest.raises(ValueError, match=re.escape(f"got {seed!r}")):
        make_mission_vec_env(n_envs=2, seed=seed, env_kwargs={"scenario": "small"})
    assert env.seed(np.int64(4)) == [4, 5]
