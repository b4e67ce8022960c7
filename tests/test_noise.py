import copy
import pickle
import re

import numpy as np
import pytest
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise, VectorizedActionNoise

from sb3_dtdpg import DTDPG
from sb3_dtdpg.common.noise import (
    LinearDecayOUNoise,
    NormalNoise,
    OrnsteinUhlenbeckNoise,
    noise_settings,
    noise_sigma,
    rearm_noise,
)


def _expected_sigma(sigma: float, final_sigma: float, decay_episodes: int, k: int) -> float:
    # The schedule as the docs state it, independent of the implementation
    return sigma + (final_sigma - sigma) * k / decay_episodes if k < decay_episodes else final_sigma


def _run_episode(noise, steps: int = 3) -> None:
    for _ in range(steps):
        noise()
    noise.reset()


@pytest.mark.parametrize("sigma, final_sigma, decay", [(0.5, 0.05, 7), (0.4, 0.1, 1), (0.1, 0.3, 4), (0.3, 0.3, 2)])
def test_sigma_follows_the_linear_formula_exactly(sigma, final_sigma, decay):
    noise = LinearDecayOUNoise(np.zeros(2), sigma, final_sigma, decay)
    for k in range(decay + 5):
        assert noise.episode == k
        np.testing.assert_array_equal(noise.current_sigma, np.full(2, _expected_sigma(sigma, final_sigma, decay, k)))
        assert noise_sigma(noise) == _expected_sigma(sigma, final_sigma, decay, k)
        _run_episode(noise)
    np.testing.assert_array_equal(noise.current_sigma, np.full(2, final_sigma))


def test_per_dimension_sigma():
    noise = LinearDecayOUNoise(np.zeros(2), np.array([0.5, 1.0]), np.array([0.1, 0.0]), 4)
    for _ in range(2):
        _run_episode(noise)
    np.testing.assert_array_equal(noise.current_sigma, [0.5 + (0.1 - 0.5) * 2 / 4, 1.0 + (0.0 - 1.0) * 2 / 4])


def test_noise_scale_is_the_scheduled_sigma():
    """The OU increments have standard deviation sigma_k * sqrt(dt) in episode k."""
    np.random.seed(0)
    dt = 0.5
    noise = LinearDecayOUNoise(np.zeros(20_000), 1.0, 0.2, 2, theta=1e-9, dt=dt)
    first = noise()
    assert abs(first.std() - 1.0 * np.sqrt(dt)) < 0.02
    noise.reset()
    noise.reset()  # no draw since the last reset: not an episode
    noise()
    noise.reset()
    assert noise.episode == 2
    assert abs(noise().std() - 0.2 * np.sqrt(dt)) < 0.01


def test_reset_without_draws_does_not_advance_and_resets_state():
    noise = LinearDecayOUNoise(np.zeros(3), 0.5, 0.1, 10, initial_noise=np.ones(3))
    for _ in range(4):
        noise.reset()
    assert noise.episode == 0
    noise()
    assert not np.allclose(noise.noise_prev, 1.0)
    noise.reset()
    assert noise.episode == 1
    np.testing.assert_array_equal(noise.noise_prev, np.ones(3))


def test_rearm_restarts_the_schedule():
    noise = LinearDecayOUNoise(np.zeros(1), 0.5, 0.1, 4)
    for _ in range(3):
        _run_episode(noise)
    noise()  # an episode in progress at the transfer does not count for the new schedule
    noise.rearm(0.4)
    assert noise.episode == 0
    np.testing.assert_array_equal(noise.current_sigma, [0.4])
    noise.reset()
    assert noise.episode == 0
    _run_episode(noise)
    np.testing.assert_array_equal(noise.current_sigma, [_expected_sigma(0.4, 0.1, 4, 1)])
    noise.rearm(0.3, final_sigma=0.0, decay_episodes=2)
    _run_episode(noise)
    np.testing.assert_array_equal(noise.current_sigma, [_expected_sigma(0.3, 0.0, 2, 1)])


def test_vectorized_noise_separate_states_shared_schedule():
    n_envs, decay = 2, 6
    base = LinearDecayOUNoise(np.zeros(2), 0.5, 0.1, decay)
    vec_noise = VectorizedActionNoise(base, n_envs)  # deep-copies base per env, and resets each copy
    assert base.episode == 0
    np.random.seed(1)
    draws = vec_noise()
    assert draws.shape == (n_envs, 2)
    # separate OU states: the two envs' processes differ, and resetting env 0 leaves env 1 alone
    assert not np.allclose(vec_noise.noises[0].noise_prev, vec_noise.noises[1].noise_prev)
    state_1 = vec_noise.noises[1].noise_prev.copy()
    vec_noise.reset(indices=[0])
    np.testing.assert_array_equal(vec_noise.noises[0].noise_prev, np.zeros(2))
    np.testing.assert_array_equal(vec_noise.noises[1].noise_prev, state_1)
    # one shared episode count: every finished episode of any env advances the schedule once
    assert [noise.episode for noise in (base, *vec_noise.noises)] == [1, 1, 1]
    vec_noise()
    vec_noise.reset(indices=[1])
    vec_noise.reset(indices=[0])
    vec_noise()
    vec_noise.reset()  # both envs finish an episode
    assert base.episode == 5
    for noise in vec_noise.noises:
        np.testing.assert_array_equal(noise.current_sigma, np.full(2, _expected_sigma(0.5, 0.1, decay, 5)))
    assert noise_sigma(vec_noise) == _expected_sigma(0.5, 0.1, decay, 5)
    rearm_noise(vec_noise, 0.4, decay_episodes=3)
    assert [noise.episode for noise in (base, *vec_noise.noises)] == [0, 0, 0]
    assert noise_sigma(vec_noise) == 0.4
    vec_noise()
    vec_noise.reset(indices=[0])
    assert noise_sigma(vec_noise) == _expected_sigma(0.4, 0.1, 3, 1)


@pytest.mark.parametrize("vectorized", [False, True])
def test_pickle_round_trip_keeps_schedule_position(vectorized):
    noise = LinearDecayOUNoise(np.zeros(2), 0.5, 0.1, 20)
    if vectorized:
        noise = VectorizedActionNoise(noise, 2)
    for _ in range(3):
        noise()
        noise.reset()
    noise()  # mid-episode
    restored = pickle.loads(pickle.dumps(noise))
    assert noise_sigma(restored) == noise_sigma(noise)
    originals = noise.noises if vectorized else [noise]
    copies = restored.noises if vectorized else [restored]
    for original, clone in zip(originals, copies, strict=True):
        np.testing.assert_array_equal(clone.noise_prev, original.noise_prev)
    # the next episodes follow the same schedule in both
    for _ in range(2):
        for n in (noise, restored):
            n()
            n.reset()
        assert noise_sigma(restored) == noise_sigma(noise)
    episodes = restored.base_noise.episode if vectorized else restored.episode
    assert episodes == (5 * 2 if vectorized else 5)
    if vectorized:  # the copies still share one schedule after the round trip
        assert restored.noises[0]._schedule is restored.noises[1]._schedule is restored.base_noise._schedule


def test_deepcopy_of_a_single_noise_shares_only_the_schedule():
    noise = LinearDecayOUNoise(np.zeros(2), 0.5, 0.1, 10)
    clone = copy.deepcopy(noise)
    clone()
    assert not np.allclose(clone.noise_prev, noise.noise_prev)
    clone.reset()
    assert noise.episode == 1


def test_a_deep_copy_of_what_holds_the_noise_has_a_schedule_of_its_own():
    """A copied model trains without moving the original's schedule; its per-env copies still share one."""
    vectorized = VectorizedActionNoise(LinearDecayOUNoise(np.zeros(1), 0.5, 0.1, 10), 2)
    model = DTDPG("MlpPolicy", "Pendulum-v1", seed=0)
    model.action_noise = vectorized
    copied = copy.deepcopy(model)
    copied.action_noise.noises[1]()
    copied.action_noise.noises[1].reset()
    assert copied.action_noise.noises[0].episode == copied.action_noise.base_noise.episode == 1
    assert model.action_noise.noises[0].episode == 0
    holder = copy.deepcopy([model.action_noise.noises[0]])
    _run_episode(holder[0])
    assert model.action_noise.noises[0].episode == 0


def test_rearm_and_sigma_of_the_constant_noises():
    ou = VectorizedActionNoise(OrnsteinUhlenbeckNoise(np.zeros(2), 0.3 * np.ones(2)), 2)
    ou.noises[0]()
    state = ou.noises[0].noise_prev.copy()
    rearm_noise(ou, 0.2)
    assert noise_sigma(ou) == pytest.approx(0.2)
    assert all(np.allclose(n.sigma, 0.2) for n in ou.noises)
    np.testing.assert_array_equal(ou.noises[0].noise_prev, state)  # the process goes on from where it was
    np.random.seed(0)
    drawn = ou.noises[0]()
    np.random.seed(0)
    reference = OrnsteinUhlenbeckActionNoise(np.zeros(2), 0.2 * np.ones(2))
    reference.noise_prev = state
    np.testing.assert_array_equal(drawn, reference())  # SB3's draws at the new scale
    normal = NormalNoise(np.zeros(1), np.ones(1))
    with pytest.warns(UserWarning, match="final_sigma"):
        rearm_noise(normal, 0.5, final_sigma=0.1)
    assert noise_sigma(normal) == 0.5
    assert noise_settings(normal) == {
        "type": "stable_baselines3.common.noise.NormalActionNoise",
        "mean": [0.0],
        "sigma": [0.5],
    }
    assert noise_sigma(None) == 0.0
    rearm_noise(None, 0.5)


@pytest.mark.parametrize("noise_class", [NormalActionNoise, OrnsteinUhlenbeckActionNoise])
def test_sb3s_own_noises_are_left_as_they_are_with_the_noise_to_use(noise_class):
    noise = noise_class(np.zeros(2), 0.3 * np.ones(2))
    public = {NormalActionNoise: "NormalNoise", OrnsteinUhlenbeckActionNoise: "OrnsteinUhlenbeckNoise"}[noise_class]
    np.random.seed(0)
    before = noise()
    with pytest.warns(UserWarning, match=f"not re-armed to sigma=0.1; pass sb3_dtdpg.common.noise.{public}"):
        rearm_noise(noise, 0.1)
    noise.reset()
    np.random.seed(0)
    np.testing.assert_array_equal(noise(), before)  # the same scale as before
    assert np.isnan(noise_sigma(noise))
    with pytest.raises(TypeError, match=f"keeps them private: use sb3_dtdpg.common.noise.{public}"):
        noise_settings(noise)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(sigma=-0.1), "sigma must be finite and >= 0, got -0.1"),
        (dict(final_sigma=float("nan")), "final_sigma must be finite"),
        (dict(sigma=np.ones(3)), "sigma must be a number or an array broadcastable"),
        (dict(decay_episodes=0), "decay_episodes must be an integer >= 1, got 0"),
        (dict(decay_episodes=2.5), "decay_episodes must be an integer >= 1, got 2.5"),
        (dict(theta=0.0), "theta must be finite and > 0, got 0.0"),
        (dict(dt=-1.0), "dt must be finite and > 0"),
        (dict(theta="0.15"), "theta must be finite and > 0, got '0.15'"),  # was numpy's "ufunc 'isfinite' not supported"
        (dict(mean=np.full(2, np.nan)), "mean must be an array of finite numbers"),  # was blamed on the action
        (dict(initial_noise=np.zeros(3)), "initial_noise must be None or finite numbers of the mean's shape"),
    ],
)
def test_bad_arguments(kwargs, match):
    args = dict(mean=np.zeros(2), sigma=0.5, final_sigma=0.1, decay_episodes=10) | kwargs
    with pytest.raises(ValueError, match=match):
        LinearDecayOUNoise(**args)
    noise = LinearDecayOUNoise(np.zeros(2), 0.5, 0.1, 10)
    if "sigma" in kwargs or "final_sigma" in kwargs or "decay_episodes" in kwargs:
        rearm_args = {k: v for k, v in kwargs.items() if k in ("sigma", "final_sigma", "decay_episodes")}
        with pytest.raises(ValueError, match=match):
            noise.rearm(**({"sigma": 0.5} | rearm_args))


@pytest.mark.parametrize(
    "make",
    [
        lambda theta, dt: LinearDecayOUNoise(np.zeros(6), 0.5, 0.1, 10, theta=theta, dt=dt),
        lambda theta, dt: OrnsteinUhlenbeckNoise(np.zeros(6), 0.5 * np.ones(6), theta=theta, dt=dt),
    ],
)
def test_an_ou_process_whose_steps_diverge_is_refused(make):
    """SB3's Euler step x += theta * (mean - x) * dt is stable for theta * dt < 2 only (was: draws of inf, then NaN)."""
    for theta, dt in ((5.0, 1.0), (2.0, 1.0), (200.0, 1e-2)):
        match = f"theta * dt must be < 2 (from 2 on the OU process's steps grow without bound), got theta={theta!r}, dt="
        with pytest.raises(ValueError, match=re.escape(match) + r".*: theta \* dt = "):
            make(theta, dt)
    noise = make(1.9, 1.0)  # below the bound: it oscillates, and stays bounded
    np.random.seed(0)
    assert np.all(np.abs([noise() for _ in range(1000)]) < 100)


def test_the_process_is_sb3s_ou_noise_of_the_current_scale():
    """Built through SB3's own constructor: in an episode the draws are exactly SB3's OU noise of that scale."""
    noise = LinearDecayOUNoise(np.zeros(2), 0.5, 0.1, 4, theta=0.2, dt=0.05)
    assert type(noise.process) is OrnsteinUhlenbeckActionNoise
    _run_episode(noise, steps=2)  # episode 1: sigma 0.4
    reference = OrnsteinUhlenbeckActionNoise(np.zeros(2), np.full(2, 0.4), theta=0.2, dt=0.05)
    np.random.seed(3)
    ours = [noise() for _ in range(5)]
    np.random.seed(3)
    theirs = [reference() for _ in range(5)]
    np.testing.assert_array_equal(ours, theirs)


def test_a_scale_change_mid_episode_keeps_the_ou_state():
    """Another env's episode end moves the shared schedule: this env's process goes on from its state."""
    first = LinearDecayOUNoise(np.zeros(1), 0.5, 0.1, 2)
    second = copy.deepcopy(first)
    np.random.seed(0)
    for _ in range(3):
        first()
    state = first.noise_prev.copy()
    _run_episode(second)  # the shared schedule: sigma 0.5 -> 0.3
    np.random.seed(1)
    drawn = first()
    np.random.seed(1)
    expected = state + 0.15 * (0.0 - state) * 1e-2 + 0.3 * np.sqrt(1e-2) * np.random.normal(size=(1,))
    np.testing.assert_allclose(drawn, expected.astype(np.float32), rtol=1e-6)


def test_a_noise_pickled_in_the_former_layout_loads_and_goes_on():
    """Models saved by sb3-dtdpg 0.1.0 pickled the noise with the OU state in its own attributes."""
    noise = LinearDecayOUNoise(np.zeros(2), 0.5, 0.1, 4)
    _run_episode(noise)
    noise()
    schedule = noise._schedule
    del schedule.version
    former = {
        "_schedule": schedule,
        "_steps_since_reset": 1,
        "_theta": 0.15,
        "_mu": np.zeros(2),
        "_dt": 1e-2,
        "_dtype": np.float32,
        "initial_noise": None,
        "noise_prev": noise.noise_prev.copy(),
    }
    restored = LinearDecayOUNoise.__new__(LinearDecayOUNoise)
    restored.__setstate__(former)
    assert restored.episode == 1 and restored._steps_since_reset == 1
    np.testing.assert_array_equal(restored.current_sigma, noise.current_sigma)
    np.random.seed(5)
    expected = noise()
    np.random.seed(5)
    np.testing.assert_array_equal(restored(), expected)
    restored.reset()
    assert restored.episode == 2


@pytest.mark.parametrize("noise_class", [NormalNoise, OrnsteinUhlenbeckNoise])
@pytest.mark.parametrize(
    "mean, sigma, match",
    [
        (np.zeros(2), np.ones(3), "sigma must be a number or an array broadcastable to the action shape (2,)"),
        (np.zeros(2), np.ones((2, 1)), "sigma must be a number or an array broadcastable"),  # widened the action
        (np.zeros(2), -0.1 * np.ones(2), "sigma must be finite and >= 0"),  # numpy's "scale < 0" at the first draw
        (np.zeros(2), np.full(2, np.nan), "sigma must be finite and >= 0"),
        (np.array([0.0, np.inf]), np.ones(2), "mean must be an array of finite numbers"),
    ],
)
def test_the_constant_noises_refuse_settings_they_cannot_draw_with(noise_class, mean, sigma, match):
    with pytest.raises(ValueError, match=re.escape(match)):
        noise_class(mean, sigma)
    noise = noise_class(np.zeros(2), 0.3 * np.ones(2))  # fitting settings: the draws of SB3's noise of that kind
    assert noise().shape == (2,)
