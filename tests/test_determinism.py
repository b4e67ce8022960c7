"""Behaviour fingerprints: seeded env rollouts and a short DT-DPG training hash to recorded digests.

The digests were recorded from the code before a refactoring that must not change behaviour; a change
here means the same seeds no longer give the same transitions or the same trained parameters. When a
change of behaviour is intended, re-record them with ``python tests/test_determinism.py``.
"""

import hashlib

import gymnasium as gym
import numpy as np
import pytest
import torch as th

import noma_radiomap  # noqa: F401  (registers the ids)
from sb3_dtdpg import DTDPG
from sb3_dtdpg.common.phases import Phase

INFO_KEYS = ("rate_bps", "sinr_db", "outage", "power_w", "gain_db", "decoding_order")
SUMMARY_KEYS = ("is_success", "mqi", "mission_time", "outage_steps")
COMPONENTS = ("time", "inducing", "qos", "arrival", "success")

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

EXPECTED_ROLLOUTS = {
    "noma": "dc1272a2c8ab0a6d65c0b3f4f7ff1c4746fcedd8565efbe31efc7a7845f3f94e",
    "oma": "df841da602e3c53b38d9ff5d9ac79ea80006c66ab31a2d7520d538ed1157690c",
    "noma_rayleigh": "5685cafd13f8be82bfa34e6cb46aa2b1400bc80ca5a12eec3a6805f2bb0c4a9c",
    "oma_rayleigh": "6826184a8ab64819c5b0805cf6c58d320b2a2e475ad8630625f7eb6d9195fbe6",
    "small": "4fae27defa682ea8a11516fc36d51279234c83b9d491f6d654569a9b16cc77b1",
    "small_combined_geodesic": "c1f9a245226986aa959a9b9d3fcd9f4920bcaeecc1781dc8a5b8d4a58e5fd839",
    "mqi": "a19de226092718a6bd04da1dad5e21b6e6fda99c3b23a69e1c4c79e8238d14fe",
}
EXPECTED_TRAINING = "7c37ea92de25bdf58d29e99de97f21be5e76b720ff59b7d31b6a21ab6a5bb8eb"


def _update(digest: "hashlib._Hash", value) -> None:
    array = np.ascontiguousarray(np.asarray(value))
    digest.update(str(array.dtype).encode() + str(array.shape).encode() + array.tobytes())


def rollout_digest(env_id: str, kwargs: dict, n_steps: int = 400, seed: int = 3) -> str:
    """Hash of a seeded random-action rollout of ``n_steps`` steps across resets."""
    env = gym.make(env_id, **kwargs)
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


def training_digest() -> str:
    """Hash of the parameters after a short seeded DT-DPG training through both phases (transfer included)."""
    th.set_num_threads(1)
    env = gym.make("NomaRadioMap-v0", scenario="small")
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
    assert rollout_digest(env_id, kwargs) == EXPECTED_ROLLOUTS[name]


@pytest.mark.slow
def test_training_fingerprint() -> None:
    assert training_digest() == EXPECTED_TRAINING


if __name__ == "__main__":
    for name, (env_id, kwargs) in ROLLOUTS.items():
        print(f'    "{name}": "{rollout_digest(env_id, kwargs)}",')
    print(f'EXPECTED_TRAINING = "{training_digest()}"')
