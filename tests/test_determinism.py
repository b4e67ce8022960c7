"""Behaviour fingerprints: seeded env rollouts and a short DT-DPG training hash to recorded digests.

The digests were recorded from the code before a refactoring that must not change behaviour; a change
here means the same seeds no longer give the same transitions or the same trained parameters. When a
change of behaviour is intended, re-record them with ``python tests/test_determinism.py``.

Digests are per kind of CPU (:func:`simd_level`): numpy picks its float64 kernels (``log10``, ``power``, ...) by the
widest SIMD the CPU has, and its AVX-512 kernels differ from its AVX2 ones by a few units in the last place
(relative differences of ~1e-15 in the radio map's gains, in ~7 % of the cells of ``mall``). The same code gives
other bits there, so each kind has its own recorded digests; on a kind with none recorded the tests are skipped.
"""

import hashlib
import platform

import gymnasium as gym
import numpy as np
import pytest

import noma_radiomap  # noqa: F401  (registers the ids)
from noma_radiomap.planners import CommAwarePlanner, ShortestPathPlanner, channel_maps

INFO_KEYS = ("rate_bps", "sinr_db", "outage", "power_w", "gain_db", "decoding_order")
SUMMARY_KEYS = ("is_success", "mqi", "mission_time", "outage_steps")
COMPONENTS = ("time", "inducing", "qos", "arrival", "success")
#: The observation the digests were recorded with (positions, destinations, gains, arrived flags), given explicitly
#: so that they do not follow the ids' default layout.
OBSERVATION = {"observation": "destinations"}

ROLLOUTS: dict[str, tuple[str, dict]] = {
    "noma": ("NomaRadioMap-v0", {}),
    "oma": ("NomaRadioMapOMA-v0", {}),
    "noma_rayleigh": ("NomaRadioMapReality-v0", {}),
    "oma_rayleigh": ("NomaRadioMapOMAReality-v0", {}),
    "small": ("NomaRadioMap-v0", {"scenario": "small"}),
    "small_combined_geodesic": (
        "NomaRadioMapReality-v0",
        {"scenario": "small", "reward_phase": "combined", "inducing": "geodesic"},
    ),
    "mqi": ("NomaRadioMap-v0", {"reward_phase": "mqi"}),
}


def simd_level() -> str:
    """The kind of CPU the digests depend on: the widest SIMD level numpy dispatches its kernels to here."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_features__ as features
    if features.get("AVX512_SKX"):
        return "x86-64-v4"
    if features.get("AVX2"):
        return "x86-64-v3"
    return platform.machine()


#: The scenarios whose radio maps are fingerprinted.
MAP_SCENARIOS: tuple[str, ...] = ("mall", "small")
#: The planners' digests are the same on both kinds of CPU recorded below.
PLANNER_DIGESTS: dict[str, str] = {
    "shortest": "362e0cd9e9c043c96e2662dd393a552da3d44c753952ddf8d0a9a9d3e88cd13d",
    "comm_aware": "93d467a892c24aa94153660912ba6e96224683502eb6ccfd4730560bf196cdd7",
    "comm_aware_oma": "1378beb50df2c787370508b6b1dbc3febc206679723024949fa80d7e5cad0c95",
}
#: Digests per :func:`simd_level`: ``x86-64-v3`` recorded on an AVX2 machine, ``x86-64-v4`` on an AVX-512 one (the same
#: code: the v3 digests also come out on the AVX-512 machine with numpy's AVX-512 kernels switched off,
#: ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"``, except the training digest, where torch's kernels differ too).
EXPECTED: dict[str, dict] = {
    "x86-64-v3": {
        "rollouts": {
            "noma": "dc1272a2c8ab0a6d65c0b3f4f7ff1c4746fcedd8565efbe31efc7a7845f3f94e",
            "oma": "df841da602e3c53b38d9ff5d9ac79ea80006c66ab31a2d7520d538ed1157690c",
            "noma_rayleigh": "5685cafd13f8be82bfa34e6cb46aa2b1400bc80ca5a12eec3a6805f2bb0c4a9c",
            "oma_rayleigh": "6826184a8ab64819c5b0805cf6c58d320b2a2e475ad8630625f7eb6d9195fbe6",
            "small": "4fae27defa682ea8a11516fc36d51279234c83b9d491f6d654569a9b16cc77b1",
            "small_combined_geodesic": "c1f9a245226986aa959a9b9d3fcd9f4920bcaeecc1781dc8a5b8d4a58e5fd839",
            "mqi": "a19de226092718a6bd04da1dad5e21b6e6fda99c3b23a69e1c4c79e8238d14fe",
        },
        "maps": {
            "mall": "cac89913551549bfed886c018962e2da4fc58a760951ae1cbe4d7d3fb2c17bbc",
            "small": "76470d7a6d7d5b1eecd5de568b595015ba383f215442b57d2d82c462a7664eea",
        },
        "planners": PLANNER_DIGESTS,
        "training": "7c37ea92de25bdf58d29e99de97f21be5e76b720ff59b7d31b6a21ab6a5bb8eb",
    },
    "x86-64-v4": {
        "rollouts": {
            "noma": "1290746810936d692891b88b7d55804e59c0a5a5532fd2b8123af0aa56211a94",
            "oma": "5e46386c2a81bfc58ab2696fb8de07d0f64df2aac505a497b3886b535b72759c",
            "noma_rayleigh": "7cdb77b082c0dde301bd169a0bf551d3c8bccfd1419fb48d34024fab63192a3d",
            "oma_rayleigh": "993442117a24f176d12cc4cdeafda3e27c6485194e920a7e1ba2a90c4906a4d7",
            "small": "e9699c5db1a99505f12c79474302ed7d6542fd44d3a3d546b4b527801d5ad58b",
            "small_combined_geodesic": "b3a905d1ce9f7f30a82a993d041a05d930f0f6c98bdb9fe1a713b444935ed512",
            "mqi": "934ec6dd3db93827a3c16954e0f1315c1e320dcb2e96e341d2f056e2c8245765",
        },
        "maps": {
            "mall": "563a69babf31458155e372e991a5498434ecc91cbf1f2c38ba44098155c66cf7",
            "small": "af596e12ed6b715f0e374d3f79fcf86a428fc1035f59588273d42efb9a7108df",
        },
        "planners": PLANNER_DIGESTS,
        "training": "6726978da515208445ab30d0f96d82933a4c65488a32ae2641466df394a18d3a",
    },
}


def expected(kind: str) -> dict[str, str] | str:
    """The recorded digests of ``kind`` on this machine's :func:`simd_level`; skips the test where none are recorded."""
    level = simd_level()
    if level not in EXPECTED:
        pytest.skip(f"no digests recorded for this kind of CPU ({level}); record them with python tests/test_determinism.py")
    return EXPECTED[level][kind]


def _update(digest: "hashlib._Hash", value) -> None:
    array = np.ascontiguousarray(np.asarray(value))
    digest.update(str(array.dtype).encode() + str(array.shape).encode() + array.tobytes())


def rollout_digest(env_id: str, kwargs: dict, n_steps: int = 400, seed: int = 3) -> str:
    """Hash of a seeded random-action rollout of ``n_steps`` steps across resets."""
    env = gym.make(env_id, **OBSERVATION, **kwargs)
    rng = np.random.default_rng(seed)
    env.action_space.seed(seed)
    digest = hashlib.sha256()
    obs, _ = env.reset(seed=seed)
    _update(digest, obs)
    for _ in range(n_steps):
        action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        for value in (obs, reward, terminated, truncated):
            _update(digest, value)
        for key in INFO_KEYS:
            _update(digest, info[key])
        for key in COMPONENTS:
            _update(digest, info["reward_components"][key])
        if terminated or truncated:
            for key in SUMMARY_KEYS:
                _update(digest, info[key])
            obs, _ = env.reset()
            _update(digest, obs)
    env.close()
    return digest.hexdigest()


def map_digest(scenario: str) -> str:
    """Hash of a scenario's radio map: the outage map, the SINR map to 1e-9 dB and the planners' channel maps."""
    env = gym.make("NomaRadioMap-v0", scenario=scenario).unwrapped
    radio_map = env.radio_map
    digest = hashlib.sha256()
    _update(digest, radio_map.outage_map())
    _update(digest, np.round(radio_map.sinr_map_db, 9))
    for array in channel_maps(env):
        _update(digest, array)
    return digest.hexdigest()


PLANNERS = {
    "shortest": ("NomaRadioMap-v0", ShortestPathPlanner),
    "comm_aware": ("NomaRadioMapReality-v0", CommAwarePlanner),
    "comm_aware_oma": ("NomaRadioMapOMA-v0", CommAwarePlanner),
}


def planner_digest(name: str, n_episodes: int = 3, seed: int = 5) -> str:
    """Hash of the actions, rewards and end-of-episode figures of a planner's seeded episodes on ``small``."""
    env_id, planner_class = PLANNERS[name]
    env = gym.make(env_id, scenario="small", **OBSERVATION)
    planner = planner_class()
    digest = hashlib.sha256()
    for episode in range(n_episodes):
        obs, _ = env.reset(seed=seed + episode)
        planner.reset(env.unwrapped)
        done = False
        while not done:
            action = planner.act(env.unwrapped, obs)
            obs, reward, terminated, truncated, info = env.step(action)
            for value in (action, obs, reward):
                _update(digest, value)
            done = terminated or truncated
        for key in SUMMARY_KEYS:
            _update(digest, info[key])
    return digest.hexdigest()


def training_digest() -> str:
    """Hash of the parameters after a short seeded DT-DPG training through both phases (transfer included)."""
    import torch as th

    from sb3_dtdpg import DTDPG
    from sb3_dtdpg.common.phases import Phase

    th.set_num_threads(1)
    env = gym.make("NomaRadioMap-v0", scenario="small", **OBSERVATION)
    phases = [
        Phase("destination", n_timesteps=700, sigma=0.5, final_sigma=0.1, decay_episodes=20),
        Phase("mqi", sigma=0.4, final_sigma=0.05, decay_episodes=20, replay_handling="relabel"),
    ]
    model = DTDPG(
        "MlpPolicy",
        env,
        learning_rate=1e-4,
        buffer_size=50_000,
        learning_starts=200,
        batch_size=64,
        tau=0.002,
        gamma=0.99,
        train_freq=1,
        gradient_steps=1,
        n_steps=1,
        policy_kwargs={"net_arch": [128, 64]},
        phases=phases,
        seed=0,
        device="cpu",
    )
    model.learn(1500)
    digest = hashlib.sha256()
    for name, tensor in sorted(model.policy.state_dict().items()):
        digest.update(name.encode())
        _update(digest, tensor.cpu().numpy())
    _update(digest, model.replay_buffer.rewards[: model.replay_buffer.size()])
    return digest.hexdigest()


@pytest.mark.parametrize("name", sorted(ROLLOUTS))
def test_rollout_fingerprint(name: str) -> None:
    env_id, kwargs = ROLLOUTS[name]
    assert rollout_digest(env_id, kwargs) == expected("rollouts")[name]


@pytest.mark.parametrize("scenario", MAP_SCENARIOS)
def test_radio_map_fingerprint(scenario: str) -> None:
    assert map_digest(scenario) == expected("maps")[scenario]


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_planner_fingerprint(name: str) -> None:
    assert planner_digest(name) == expected("planners")[name]


@pytest.mark.slow
def test_training_fingerprint() -> None:
    assert training_digest() == expected("training")


if __name__ == "__main__":
    import sys

    if "--no-training" in sys.argv:
        training_digest = lambda: "(skipped)"  # noqa: E731
    print(f"EXPECTED[{simd_level()!r}] = ", end="")
    print(
        {
            "rollouts": {name: rollout_digest(env_id, kwargs) for name, (env_id, kwargs) in ROLLOUTS.items()},
            "maps": {scenario: map_digest(scenario) for scenario in MAP_SCENARIOS},
            "planners": {name: planner_digest(name) for name in PLANNERS},
            "training": training_digest(),
        }
    )
