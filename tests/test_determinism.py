"""Behaviour fingerprints: seeded env rollouts and a short DT-DPG training hash to recorded digests.

The digests were recorded from the code before a refactoring that must not change behaviour; a change
here means the same seeds no longer give the same transitions or the same trained parameters. When a
change of behaviour is intended, re-record them with ``python tests/test_determinism.py``.

Digests are per kind of CPU (:func:`simd_level`): numpy picks its float64 kernels (``log10``, ``power``, ...) by the
widest SIMD the CPU has, and its AVX-512 kernels differ from its AVX2 ones by a few units in the last place
(relative differences of ~1e-15 in the radio map's gains, in ~7 % of the cells of ``mall``). The same code gives
other bits there, so each kind has its own recorded digests; on a kind with none recorded the tests are skipped.
The training digest depends on torch's matrix kernels instead (:func:`matmul_level`): MKL runs its AVX-512 code on
Intel CPUs only, so an AMD CPU with AVX-512 gives the training digest of an AVX2 machine.
"""

import functools
import hashlib
import platform

import gymnasium as gym
import numpy as np
import pytest

import noma_radiomap  # noqa: F401  (registers the ids)
from noma_radiomap.planners import CommAwarePlanner, ReferencePlanner, ShortestPathPlanner, channel_maps

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


def matmul_level() -> str:
    """The kind of CPU the training digest depends on: the widest SIMD of MKL's matrix kernels (AVX-512 on Intel
    CPUs only)."""
    import torch as th

    capability = th.backends.cpu.get_cpu_capability()
    if capability == "AVX512" and _cpu_vendor() == "GenuineIntel":
        return "x86-64-v4"
    if capability in ("AVX512", "AVX2"):
        return "x86-64-v3"
    return platform.machine()


def _cpu_vendor() -> str:
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("vendor_id"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


#: The scenarios whose radio maps are fingerprinted.
MAP_SCENARIOS: tuple[str, ...] = ("mall", "small")
#: The planners' digests are the same on both kinds of CPU recorded below.
PLANNER_DIGESTS: dict[str, str] = {
    "shortest": "362e0cd9e9c043c96e2662dd393a552da3d44c753952ddf8d0a9a9d3e88cd13d",
    "comm_aware": "93d467a892c24aa94153660912ba6e96224683502eb6ccfd4730560bf196cdd7",
    "comm_aware_oma": "1378beb50df2c787370508b6b1dbc3febc206679723024949fa80d7e5cad0c95",
    "shortest_best_power": "7d8daa446ec04f52756069f068e81850745050f878c127e80baeaa82605a0fe3",
    "reference": "a3f47ba14d73b0f2464a6a664acaa496596d2057b069285792d457743db75e16",
    "reference_oma_rayleigh": "caf8b824837c5520debd46dcfd2de7b5979c16cfffd3ee5452c8d27d6c329e6d",
}
#: Digests per :func:`simd_level`: ``x86-64-v3`` recorded on an AVX2 machine, ``x86-64-v4`` on an AVX-512 one (the same
#: code: the v3 digests also come out on the AVX-512 machine with numpy's AVX-512 kernels switched off,
#: ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"``, except the training digest, where torch's kernels differ too).
EXPECTED: dict[str, dict] = {
    "x86-64-v3": {
        "rollouts": {
            "noma": "39227c6237970789f1a5786f7914d1a9f46b37946bfb866e46ea5d956121da9d",
            "oma": "118ed82e3a9d5b9f8f73a6102f982b27a8c63f7b0c70b54a0cdbd97045ae9803",
            "noma_rayleigh": "f57200548f4e19320f844eb95a03672dd0ca1031d85aae91fb9884be3aa2c34d",
            "oma_rayleigh": "dbda5d9a49a8259bf631f69a908300f1dd3f00bd56608bf5ce186d77ac0917b4",
            "small": "4fae27defa682ea8a11516fc36d51279234c83b9d491f6d654569a9b16cc77b1",
            "small_combined_geodesic": "c1f9a245226986aa959a9b9d3fcd9f4920bcaeecc1781dc8a5b8d4a58e5fd839",
            "mqi": "db4ab8dfd2b5dce92eba7bd886fe2e0898d9754c0c154c006c58f980fe370758",
        },
        "maps": {
            "mall": "14793050f79f65eeb797f7176bbb3bca9682dac912ba077e5bc63a380069fa1f",
            "small": "76470d7a6d7d5b1eecd5de568b595015ba383f215442b57d2d82c462a7664eea",
        },
        "planners": PLANNER_DIGESTS,
        "training": "7c37ea92de25bdf58d29e99de97f21be5e76b720ff59b7d31b6a21ab6a5bb8eb",
    },
    "x86-64-v4": {
        "rollouts": {
            "noma": "2c823e82388caf4cdba6f15ba5944e850ef667caa290b217100902a2c2b99f6c",
            "oma": "0ac34ac54933cfc27a3d963861178653141f30686a6079a576287755c94c2fbd",
            "noma_rayleigh": "b5b8315b75713be7fd60c366c21f7f6e2311cae85d80ee201c2e4fa7b22bc8a5",
            "oma_rayleigh": "2f4781353e4e902dace6beb4a870bd612a8582c442eecaebc17a53205064122f",
            "small": "e9699c5db1a99505f12c79474302ed7d6542fd44d3a3d546b4b527801d5ad58b",
            "small_combined_geodesic": "b3a905d1ce9f7f30a82a993d041a05d930f0f6c98bdb9fe1a713b444935ed512",
            "mqi": "d267664b678da31a0963224f34516d3eb8daf13d738f3e480468713321a3cf1f",
        },
        "maps": {
            "mall": "fee363b5d4607bd8bb8b957ceab90348a0975ead0fed9ea58ad11abd8dcc7990",
            "small": "af596e12ed6b715f0e374d3f79fcf86a428fc1035f59588273d42efb9a7108df",
        },
        "planners": PLANNER_DIGESTS,
        "training": "6726978da515208445ab30d0f96d82933a4c65488a32ae2641466df394a18d3a",
    },
}


def expected(kind: str, name: str | None = None, level: str | None = None) -> dict[str, str] | str:
    """The recorded digests of ``kind`` (its ``name`` entry if given) on this machine's ``level`` (default:
    :func:`simd_level`); skips the test where none is recorded."""
    level = simd_level() if level is None else level
    if level not in EXPECTED:
        pytest.skip(f"no digests recorded for this kind of CPU ({level}); record them with python tests/test_determinism.py")
    recorded = EXPECTED[level][kind]
    if name is None:
        return recorded
    if name not in recorded:
        pytest.skip(f"no {kind} digest of {name!r} recorded for this kind of CPU ({level})")
    return recorded[name]


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
    "shortest_best_power": ("NomaRadioMapReality-v0", functools.partial(ShortestPathPlanner, power="best")),
    "reference": ("NomaRadioMap-v0", ReferencePlanner),
    "reference_oma_rayleigh": ("NomaRadioMapOMAReality-v0", ReferencePlanner),
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
    assert rollout_digest(env_id, kwargs) == expected("rollouts", name)


@pytest.mark.parametrize("scenario", MAP_SCENARIOS)
def test_radio_map_fingerprint(scenario: str) -> None:
    assert map_digest(scenario) == expected("maps", scenario)


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_planner_fingerprint(name: str) -> None:
    assert planner_digest(name) == expected("planners", name)


@pytest.mark.slow
def test_training_fingerprint() -> None:
    assert training_digest() == expected("training", level=matmul_level())


if __name__ == "__main__":
    import sys

    if "--no-training" in sys.argv:
        training_digest = lambda: "(skipped)"  # noqa: E731
    print(f"EXPECTED[{simd_level()!r}] = (training: EXPECTED[{matmul_level()!r}]) ", end="")
    print(
        {
            "rollouts": {name: rollout_digest(env_id, kwargs) for name, (env_id, kwargs) in ROLLOUTS.items()},
            "maps": {scenario: map_digest(scenario) for scenario in MAP_SCENARIOS},
            "planners": {name: planner_digest(name) for name in PLANNERS},
            "training": training_digest(),
        }
    )
