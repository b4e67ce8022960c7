import numpy as np
import pytest
from gymnasium import spaces
from phased_env import PHASE_WEIGHTS, PhasedPointEnv
from stable_baselines3 import DDPG
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env

from sb3_dtdpg.common.buffers import (
    FastNStepReplayBuffer,
    RewardComponentsNStepReplayBuffer,
    RewardComponentsReplayBuffer,
)

REWARD_COMPONENTS = ("time", "inducing", "qos", "arrival", "success")

OBS_SPACE = spaces.Box(-1, 1, (2,), np.float32)
ACT_SPACE = spaces.Box(-1, 1, (1,), np.float32)


def make_buffer(size=8, n_envs=2, **kwargs):
    kwargs.setdefault("component_keys", REWARD_COMPONENTS)
    return RewardComponentsReplayBuffer(size, OBS_SPACE, ACT_SPACE, device="cpu", n_envs=n_envs, **kwargs)


def random_components(rng):
    return {key: float(rng.normal()) for key in REWARD_COMPONENTS}


def add_transitions(buffer, n_steps, rng):
    """Add n_steps vector steps; return the components and rewards added, as arrays (n_steps, n_envs, ...)."""
    comps, rewards = [], []
    for _ in range(n_steps):
        infos = [{"reward_components": random_components(rng)} for _ in range(buffer.n_envs)]
        reward = rng.normal(size=buffer.n_envs).astype(np.float32)
        obs = rng.uniform(-1, 1, (buffer.n_envs, 2)).astype(np.float32)
        next_obs = rng.uniform(-1, 1, (buffer.n_envs, 2)).astype(np.float32)
        action = rng.uniform(-1, 1, (buffer.n_envs, 1)).astype(np.float32)
        buffer.add(obs, next_obs, action, reward, np.zeros(buffer.n_envs), infos)
        comps.append([[info["reward_components"][key] for key in REWARD_COMPONENTS] for info in infos])
        rewards.append(reward)
    return np.array(comps), np.array(rewards)


@pytest.mark.parametrize("optimize_memory_usage", [False, True])
def test_stores_components_per_transition_and_env(optimize_memory_usage):
    rng = np.random.default_rng(0)
    buffer = make_buffer(
        size=10, n_envs=2, optimize_memory_usage=optimize_memory_usage, handle_timeout_termination=not optimize_memory_usage
    )
    # 5 slots per env; 7 steps wrap around: slots 0, 1 hold steps 5, 6 and slots 2-4 hold steps 2-4
    comps, rewards = add_transitions(buffer, 7, rng)
    assert buffer.buffer_size == 5 and buffer.full and buffer.pos == 2
    expected = np.concatenate([comps[5:7], comps[2:5]])
    np.testing.assert_array_equal(buffer.reward_components, expected)
    np.testing.assert_array_equal(buffer.rewards, np.concatenate([rewards[5:7], rewards[2:5]]))


def test_relabel_recomputes_every_reward():
    rng = np.random.default_rng(1)
    buffer = make_buffer(size=8, n_envs=2)
    comps, _ = add_transitions(buffer, 3, rng)
    weights = {"time": 1.0, "qos": 2.0, "arrival": 0.5, "success": 1.0}  # "inducing" left out: weight 0
    buffer.relabel(weights)
    w = np.array([1.0, 0.0, 2.0, 0.5, 1.0])
    np.testing.assert_allclose(buffer.rewards[:3], np.einsum("tek,k->te", comps, w), rtol=1e-6)
    # Sampling returns the relabelled rewards
    samples = buffer.sample(16)
    flat = buffer.rewards[:3].reshape(-1)
    assert all(np.isclose(flat, r, rtol=1e-6).any() for r in samples.rewards.numpy().reshape(-1))


def test_n_step_returns_after_relabel_are_the_new_phase_sums():
    gamma, n = 0.9, 3
    buffer = RewardComponentsNStepReplayBuffer(16, OBS_SPACE, ACT_SPACE, device="cpu", n_envs=1, n_steps=n, gamma=gamma)
    rng = np.random.default_rng(3)
    dones = [0, 0, 0, 1, 0, 0, 0, 0, 0, 0]  # an episode ends on step 3: returns must not cross it
    comps = []
    for done in dones:
        info = {"reward_components": random_components(rng)}
        obs, next_obs = rng.uniform(-1, 1, (2, 1, 2)).astype(np.float32)
        buffer.add(obs, next_obs, np.zeros((1, 1), np.float32), np.zeros(1, np.float32), np.array([done]), [info])
        comps.append([info["reward_components"][key] for key in REWARD_COMPONENTS])
    weights = {"time": -1.0, "qos": 2.0, "success": 10.0}
    buffer.relabel(weights)
    one_step = np.array(comps) @ np.array([weights.get(key, 0.0) for key in REWARD_COMPONENTS])

    starts = np.arange(len(dones) - n)
    samples = buffer._get_samples(starts)
    expected, discounts = [], []
    for start in starts:
        total, k = 0.0, 0
        while k < n:
            total += gamma**k * one_step[start + k]
            k += 1
            if dones[start + k - 1]:
                break
        expected.append(total)
        discounts.append(gamma**k)
    np.testing.assert_allclose(samples.rewards.numpy().ravel(), expected, rtol=1e-5)
    np.testing.assert_allclose(samples.discounts.numpy().ravel(), discounts, rtol=1e-6)


def test_relabel_rejects_unknown_component():
    buffer = make_buffer()
    with pytest.raises(ValueError, match="speed"):
        buffer.relabel({"speed": 1.0})


def test_missing_components_name_the_key():
    buffer = make_buffer(n_envs=2)
    obs = np.zeros((2, 2), np.float32)
    act = np.zeros((2, 1), np.float32)
    good = {"reward_components": dict.fromkeys(REWARD_COMPONENTS, 0.0)}
    bad = {"reward_components": {k: 0.0 for k in REWARD_COMPONENTS if k != "qos"}}
    with pytest.raises(ValueError, match="'qos'"):
        buffer.add(obs, obs, act, np.zeros(2), np.zeros(2), [good, bad])
    with pytest.raises(ValueError, match="reward_components"):
        buffer.add(obs, obs, act, np.zeros(2), np.zeros(2), [good, {}])
    assert buffer.size() == 0  # nothing half-written


def test_component_keys_as_one_string_are_refused():
    # a string is a sequence: "time" was taken as the keys t, i, m, e, failing only at the first add
    with pytest.raises(ValueError, match=r"component_keys must be a sequence of names, got the string 'time'"):
        make_buffer(component_keys="time")


def test_clear_empties():
    buffer = make_buffer()
    add_transitions(buffer, 3, np.random.default_rng(2))
    assert buffer.size() == 3  # rows of n_envs transitions
    buffer.clear()
    assert buffer.size() == 0 and not buffer.full


def test_pickle_keeps_components(tmp_path):
    from stable_baselines3.common.save_util import load_from_pkl, save_to_pkl

    buffer = make_buffer()
    comps, _ = add_transitions(buffer, 3, np.random.default_rng(3))
    save_to_pkl(tmp_path / "rb.pkl", buffer)
    loaded = load_from_pkl(tmp_path / "rb.pkl")
    np.testing.assert_array_equal(loaded.reward_components[:3], comps)
    assert loaded.component_keys == REWARD_COMPONENTS


class _RecordInfos(BaseCallback):
    def __init__(self):
        super().__init__()
        self.components, self.rewards = [], []

    def _on_step(self) -> bool:
        self.components.append([[info["reward_components"][k] for k in REWARD_COMPONENTS] for info in self.locals["infos"]])
        self.rewards.append(np.array(self.locals["rewards"]))
        return True


def test_with_ddpg_on_phased_env():
    env = make_vec_env(PhasedPointEnv, n_envs=2, seed=0)
    model = DDPG(
        "MlpPolicy",
        env,
        learning_starts=20,
        policy_kwargs={"net_arch": [8]},
        replay_buffer_class=RewardComponentsReplayBuffer,
        seed=0,
    )
    recorder = _RecordInfos()
    model.learn(30, callback=recorder)
    buffer = model.replay_buffer
    assert buffer.pos == 15
    np.testing.assert_array_equal(buffer.reward_components[:15], np.array(recorder.components))
    np.testing.assert_array_equal(buffer.rewards[:15], np.array(recorder.rewards, dtype=np.float32))
    # The env's reward is the weighted sum of its components
    w = np.array([PHASE_WEIGHTS["destination"][k] for k in REWARD_COMPONENTS])
    np.testing.assert_allclose(buffer.rewards[:15], buffer.reward_components[:15] @ w, rtol=1e-6)


def test_component_keys_default_to_the_first_info():
    buffer = RewardComponentsReplayBuffer(8, OBS_SPACE, ACT_SPACE, device="cpu")
    assert buffer.component_keys is None
    buffer.relabel({"a": 1.0})  # nothing stored yet: a no-op
    info = {"reward_components": {"b": 2.0, "a": 1.0}}
    obs = np.zeros((1, *OBS_SPACE.shape), dtype=np.float32)
    action = np.zeros((1, *ACT_SPACE.shape), dtype=np.float32)
    buffer.add(obs, obs, action, np.zeros(1), np.zeros(1), [info])
    assert buffer.component_keys == ("b", "a")
    buffer.relabel({"a": 3.0})
    assert buffer.rewards[0, 0] == pytest.approx(3.0)


def _fill_episodes(buffers, steps, n_envs, rng):
    """The same random transitions into every buffer: episodes that end (done) or are cut (time limit) at random."""
    for _ in range(steps):
        obs = rng.standard_normal((n_envs, 2)).astype(np.float32)
        next_obs = rng.standard_normal((n_envs, 2)).astype(np.float32)
        action = rng.uniform(-1, 1, (n_envs, 1)).astype(np.float32)
        reward = (rng.standard_normal(n_envs) * 3).astype(np.float32)
        done = rng.random(n_envs) < 0.1
        truncated = done & (rng.random(n_envs) < 0.4)
        infos = [{"TimeLimit.truncated": bool(cut), "reward_components": random_components(rng)} for cut in truncated]
        for buffer in buffers:
            buffer.add(obs, next_obs, action, reward, done, infos)


@pytest.mark.parametrize(
    ("size", "steps", "n_envs", "n_steps"),
    [(64, 40, 1, 3), (64, 150, 1, 3), (32, 90, 3, 3), (64, 150, 2, 9), (64, 150, 1, 20)],
)
@pytest.mark.parametrize("fast_class", [FastNStepReplayBuffer, RewardComponentsNStepReplayBuffer])
def test_fast_n_step_sampling_is_sb3_s_bit_for_bit(size, steps, n_envs, n_steps, fast_class):
    # Partly filled and wrapped-around buffers, one env and several: the same draws of numpy's generator give the same
    # batches, every number equal bit for bit (also the sign of a zero), as SB3's NStepReplayBuffer; from 8 steps on,
    # numpy sums a return pairwise.
    kwargs = dict(device="cpu", n_envs=n_envs, n_steps=n_steps, gamma=0.95)
    reference = NStepReplayBuffer(size, OBS_SPACE, ACT_SPACE, **kwargs)
    fast = fast_class(size, OBS_SPACE, ACT_SPACE, **kwargs)
    _fill_episodes([reference, fast], steps, n_envs, np.random.default_rng(steps))
    if fast_class is RewardComponentsNStepReplayBuffer:
        fast.relabel(dict.fromkeys(REWARD_COMPONENTS, 0.0))  # rewards of another phase...
        fast.rewards[...] = reference.rewards  # ...then the same rewards again: the buffer's own arrays are read
    for seed in range(30):
        np.random.seed(seed)
        expected = reference.sample(16)
        next_draw = np.random.randint(1 << 30)
        np.random.seed(seed)
        got = fast.sample(16)
        assert np.random.randint(1 << 30) == next_draw  # the same draws of numpy's generator
        for name, want, have in zip(expected._fields, expected, got, strict=True):
            assert have.dtype == want.dtype and have.shape == want.shape, name
            assert have.numpy().tobytes() == want.numpy().tobytes(), (name, seed)


def test_dtdpg_samples_n_step_returns_with_the_fast_buffer_and_the_same_weights():
    from sb3_dtdpg import DTDPG

    def train(**kwargs):
        model = DTDPG(
            "MlpPolicy", "Pendulum-v1", n_steps=3, learning_starts=50, batch_size=32, buffer_size=500, seed=3, **kwargs
        )
        model.learn(250)
        return model

    fast = train()
    reference = train(replay_buffer_class=NStepReplayBuffer, replay_buffer_kwargs={"n_steps": 3, "gamma": 0.99})
    assert type(fast.replay_buffer) is FastNStepReplayBuffer
    assert type(reference.replay_buffer) is NStepReplayBuffer
    for (name, a), (_, b) in zip(fast.policy.state_dict().items(), reference.policy.state_dict().items(), strict=True):
        assert a.numpy().tobytes() == b.numpy().tobytes(), name
