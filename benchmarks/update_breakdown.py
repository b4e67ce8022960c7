"""
Where the time of one DTDPG update goes between the bare math and the update inside SB3's training loop.

A DTDPG model ([128, 128], batch 128, the hyperparameters of ``benchmarks/train_speed.py``) learns ``--warm-up``
steps, then its lean update (target, critic and actor steps with the backward passes written out) is timed in
``--repeats`` rounds of ``--updates`` updates each, in these variants, the rounds alternating:

- one fixed batch, the same every update (the floor of ``train_speed.py``);
- 1000 batches sampled beforehand, one after the other (other data, the same code);
- one fixed batch, with a replay-buffer sample drawn and discarded before each update (the code between updates);
- one fixed batch, with one ``np.random.randint`` call (a batch's indices) before each update;
- a fresh sample per update (what the training step does);
- the whole training step, ``train(gradient_steps=1)`` (with the target noise, the Polyak updates, the logging);
- the sample alone.

Every round starts from the same snapshot of the networks and optimizer states, so that each variant updates the
same Adam moments: those of the weights whose gradients stay zero (ReLU units no sample activates) decay by
``beta1`` per update through the subnormal floats, which some CPUs compute on a slow path. Each variant
is timed as trained and with subnormal floats flushed to zero (``torch.set_flush_denormal``; the numbers then differ
from the default's). Printed: microseconds per update (median over rounds) and the difference to the fixed batch.

    python benchmarks/update_breakdown.py                     # Pendulum-v1
    python benchmarks/update_breakdown.py --env NomaRadioMap-v0
"""

import argparse
import copy
import itertools
import time
from collections.abc import Callable

import numpy as np
import torch as th

from sb3_dtdpg import DTDPG
from sb3_dtdpg.arguments import positive_int
from sb3_dtdpg.dtdpg import lean

#: Hyperparameters of ``benchmarks/train_speed.py``'s models.
SETTINGS = dict(
    policy_kwargs=dict(net_arch=[128, 128]),
    batch_size=128,
    buffer_size=50_000,
    learning_starts=100,
    learning_rate=1e-3,
    tau=0.005,
    gamma=0.95,
    n_steps=3,
)
#: Pre-drawn batches the "batches in turn" variant cycles through.
N_BATCHES = 1000


def update_variants(model: DTDPG) -> dict[str, Callable[[], None]]:
    """
    :param model: A DTDPG model past its learning starts, whose networks the lean step writes out
    :return: one function per variant (see the module docstring), each doing one update
    """
    trainer = lean.lean_trainer(model)
    networks = lean._written_out(model, trainer)
    if networks is None:
        raise ValueError("update_breakdown: the model's networks are not written out (an MLP policy on a Box space)")
    batch_size = model.batch_size
    fixed = model.replay_buffer.sample(batch_size)
    batches = itertools.cycle([model.replay_buffer.sample(batch_size) for _ in range(N_BATCHES)])

    def update(data) -> None:
        target = lean._target_q_values(model, data, networks)
        networks.critic_step(data, target, trainer.critic_adam)
        networks.actor_step(data.observations, trainer.actor_adam)

    def sample():
        return model.replay_buffer.sample(batch_size, env=model._vec_normalize_env)

    return {
        "one fixed batch": lambda: update(fixed),
        f"{N_BATCHES} batches in turn": lambda: update(next(batches)),
        "a sample, then the fixed batch": lambda: (sample(), update(fixed)),
        "np.random.randint, then the fixed batch": lambda: (np.random.randint(0, N_BATCHES, size=batch_size), update(fixed)),
        "a fresh sample per update": lambda: update(sample()),
        "the training step, train(1)": lambda: model.train(1, batch_size),
        "the sample alone": sample,
    }


class Snapshot:
    """The networks' parameters and statistics and the optimizers' states of a model, to restore before each round."""

    def __init__(self, model: DTDPG):
        self.model = model
        self.policy = copy.deepcopy(model.policy.state_dict())
        self.optimizers = [copy.deepcopy(o.state_dict()) for o in (model.actor.optimizer, model.critic.optimizer)]

    def restore(self) -> None:
        self.model.policy.load_state_dict(self.policy)  # copies into the model's tensors (the flat buffers stay)
        for optimizer, state in zip((self.model.actor.optimizer, self.model.critic.optimizer), self.optimizers, strict=True):
            optimizer.load_state_dict(copy.deepcopy(state))


def breakdown(env_id: str, warm_up: int, updates: int, repeats: int, seed: int) -> dict[str, dict[bool, float]]:
    """:return: per variant, microseconds per update as trained (False) and with subnormals flushed (True)"""
    model = DTDPG("MlpPolicy", env_id, seed=seed, **SETTINGS)
    model.learn(warm_up)
    model.policy.set_training_mode(True)
    variants = update_variants(model)
    snapshot = Snapshot(model)
    times: dict[str, dict[bool, list[float]]] = {name: {False: [], True: []} for name in variants}
    for repeat in range(repeats):
        for flush in (False, True) if repeat % 2 == 0 else (True, False):
            for name, variant in variants.items():
                snapshot.restore()
                th.set_flush_denormal(flush)
                try:
                    start = time.perf_counter()
                    for _ in range(updates):
                        variant()
                    times[name][flush].append((time.perf_counter() - start) / updates * 1e6)
                finally:
                    th.set_flush_denormal(False)
    return {name: {flush: float(np.median(t)) for flush, t in by_flush.items()} for name, by_flush in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="Pendulum-v1")
    parser.add_argument("--warm-up", type=positive_int, default=1000, help="env steps learned before the timing")
    parser.add_argument("--updates", type=positive_int, default=300, help="updates per timed round")
    parser.add_argument("--repeats", type=positive_int, default=6, help="rounds per variant")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    th.set_num_threads(1)
    if not th.set_flush_denormal(False):
        parser.error("this CPU cannot flush subnormal floats to zero")
    try:
        import noma_radiomap  # noqa: F401  (registers NomaRadioMap-v0)
    except ImportError:
        pass
    results = breakdown(args.env, args.warm_up, args.updates, args.repeats, args.seed)
    base = results["one fixed batch"]
    print(f"{args.env}: microseconds per update, median of {args.repeats} rounds of {args.updates} (torch 1 thread)")
    print(f"{'variant':<40} {'as trained':>11} {'(+ vs fixed)':>13} {'subnormals flushed':>19} {'(+ vs fixed)':>13}")
    for name, r in results.items():
        extra = {flush: "" if name == "the sample alone" else f"{r[flush] - base[flush]:+.0f}" for flush in (False, True)}
        print(f"{name:<40} {r[False]:>11.0f} {extra[False]:>13} {r[True]:>19.0f} {extra[True]:>13}")


if __name__ == "__main__":
    main()
