"""The training-speed scripts of benchmarks/: what their timed updates run on, and the state they leave behind."""

import pytest
import torch as th
from scripts import load_script
from stable_baselines3 import DDPG

from sb3_dtdpg import DTDPG


@pytest.mark.parametrize("algo", [DTDPG, DDPG])
def test_the_floor_steps_a_fused_copy_of_the_models_adam_state(algo):
    train_speed = load_script("train_speed")
    model = algo("MlpPolicy", "Pendulum-v1", policy_kwargs=dict(net_arch=[8]), learning_starts=10, batch_size=8, seed=0)
    model.learn(40)
    data, _, policy = train_speed._floor_copy(model, batch_size=8)
    assert len(data.observations) == 8
    for name in ("actor", "critic"):
        original, copied = getattr(model, name).optimizer, getattr(policy, name).optimizer
        assert copied.param_groups[0]["fused"] and bool(original.param_groups[0].get("fused")) == (algo is DTDPG)
        for key in ("lr", "betas", "eps", "weight_decay"):
            assert copied.param_groups[0][key] == original.param_groups[0][key]
        originals = [p for group in original.param_groups for p in group["params"]]
        copies = list(getattr(policy, name).parameters())
        assert len(originals) == len(copies) and {id(p) for p in copies}.isdisjoint(id(p) for p in originals)
        for source, target in zip(originals, copies, strict=True):
            state, state_copy = original.state[source], copied.state[target]
            assert state_copy.keys() == state.keys()
            for key, value in state.items():
                assert th.equal(state_copy[key], value) and state_copy[key].data_ptr() != value.data_ptr(), key
    before = {key: value.clone() for key, value in model.critic.optimizer.state_dict()["state"][0].items()}
    update = train_speed.floor_update(model, batch_size=8)  # ten updates of the copy, then one more
    update()
    after = model.critic.optimizer.state_dict()["state"][0]
    assert all(th.equal(after[key], value) for key, value in before.items())


def _flushes_subnormals() -> bool:
    return float((th.tensor([1e-39]) * 1.0).item()) == 0.0


def test_the_breakdown_restores_the_snapshot_and_leaves_subnormals_on(monkeypatch):
    update_breakdown = load_script("update_breakdown")
    monkeypatch.setattr(update_breakdown, "N_BATCHES", 4)
    model = DTDPG("MlpPolicy", "Pendulum-v1", seed=0, **{**update_breakdown.SETTINGS, "learning_starts": 20})
    model.learn(40)
    model.policy.set_training_mode(True)
    snapshot = update_breakdown.Snapshot(model)
    for variant in update_breakdown.update_variants(model).values():
        variant()
    moved = model.policy.state_dict()
    assert any(not th.equal(moved[key], value) for key, value in snapshot.policy.items())
    snapshot.restore()
    assert all(th.equal(model.policy.state_dict()[key], value) for key, value in snapshot.policy.items())
    restored = model.critic.optimizer.state_dict()["state"]
    assert all(
        th.equal(restored[index][key], value)
        for index, state in snapshot.optimizers[1]["state"].items()
        for key, value in state.items()
    )
    results = update_breakdown.breakdown("Pendulum-v1", warm_up=120, updates=2, repeats=2, seed=0)
    assert set(results) == set(update_breakdown.update_variants(model)) and not _flushes_subnormals()
    assert all(times[False] > 0 and times[True] > 0 for times in results.values())
