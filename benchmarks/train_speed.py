"""
Training speed of DTDPG vs SB3's DDPG, measured side by side in one process.

All learn with the same hyperparameters (learning rate 1e-3, tau 0.005, gamma 0.95, 3-step returns; network
sizes, batch size, buffer size and learning starts from the command line) on the same env, with an OU action noise
(DTDPG: its default linearly decayed OU noise; DDPG: SB3's constant OU noise of the same initial scale), one
gradient step per env step. Variants: SB3's DDPG as SB3 builds it (default Adam), with the fused Adam that DTDPG
uses by default, and with the lean training step (``LeanDDPG``: SB3's DDPG bit for bit, its MLPs written out);
DTDPG with its lean training step (the default: the backward passes written out), the lean step through autograd
(``backprop=False``) and SB3's generic step (``lean=False``), all three the same numbers, bit for bit. After a
warm-up, the models alternate
``learn(--steps, reset_num_timesteps=False)`` chunks ``--repeats`` times (the order reversed every other round),
so that load changes on the machine hit all alike. Printed: the median steps/s (wall clock) of each, and the
median of the per-repeat ratios DTDPG / variant, from wall-clock (with their range: how much the machine's load
moved them) and from process CPU time, and variant / SB3 DDPG (CPU time).

The floors: copies of the same networks doing their forward passes, backward passes and fused Adam steps (on a copy
of the model's Adam state, with its settings) on one fixed batch (no env, no replay buffer, no target update, no
logging), timed in the same rounds as the chunks:
updates/s, what steps/s would be at one update per step if nothing else cost anything. Through autograd for both
algorithms' networks, and written out (:mod:`sb3_dtdpg.dtdpg.backprop`) for DTDPG's. The ceiling: the written-out
floor plus SB3's rollout loop and replay sampling, timed as a DTDPG whose gradient steps only sample their batches
(``1 / ceiling = 1 / floor + 1 / loop``): what DTDPG's steps/s could reach inside SB3's loop with nothing else in
the update.

    python benchmarks/train_speed.py                      # Pendulum-v1, and NomaRadioMap-v0 if installed
    python benchmarks/train_speed.py --net-arch 400 300   # the networks of the DDPG paper
    python benchmarks/train_speed.py --envs Pendulum-v1 --steps 1000 --repeats 9
    python benchmarks/train_speed.py --vec-envs 8          # DTDPG on 1 env vs the batched vector env of 8
    python benchmarks/train_speed.py --flush-denormals     # all with subnormal floats flushed to zero

Adam's moments of the weights whose gradients stay zero (those of ReLU units that no sample activates) decay by
``beta1`` per update through the subnormal floats, which some CPUs compute on a slow path; with
``--flush-denormals`` (``torch.set_flush_denormal(True)``, in every model and floor alike) those become zero: faster
on such CPUs, and no longer the default's numbers bit for bit.

With ``--vec-envs N``: DTDPG on one ``NomaRadioMap-v0`` env against DTDPG on ``MissionVecEnv`` of N missions,
``train_freq=1`` and ``gradient_steps=-1`` (N gradient steps per vector step: the single env's one update per
transition), and with ``gradient_steps=1`` (one update per N transitions); steps/s count env steps.
"""

import argparse
import copy
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import DDPG
from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise
from torch.nn import functional as F

from sb3_dtdpg import DTDPG
from sb3_dtdpg.arguments import checked, non_negative_int, positive_int
from sb3_dtdpg.dtdpg.backprop import BackpropNetworks
from sb3_dtdpg.dtdpg.lean import FusedAdamStep, LeanDDPG

#: The model whose ratios to the others are printed, and the baseline of the bar.
DTDPG_LEAN, BASELINE = "DTDPG", "SB3 DDPG"
#: DTDPG whose gradient steps only sample their batches: SB3's rollout loop and the replay sampling alone.
NO_UPDATES = "DTDPG without updates"
#: The floor of DTDPG's update with its backward passes written out, and the ceiling it sets with SB3's loop around it.
WRITTEN_OUT_FLOOR, CEILING = "floor, DTDPG's written out", "ceiling, floor + loop"
#: An argparse type: a minibatch size (batch normalisation needs two samples).
BATCH_SIZE = checked(int, lambda n: n >= 2, "a batch size >= 2")
#: Hyperparameters shared by all models (the tuned set's, :data:`sb3_dtdpg.presets.TUNED`), besides the command line's.
SHARED = dict(learning_rate=1e-3, tau=0.005, gamma=0.95, n_steps=3)


class _NoUpdates(DTDPG):
    """DTDPG that collects and samples as it trains but updates nothing (see :data:`NO_UPDATES`)."""

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        for _ in range(gradient_steps):
            self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)


def _available(env_id: str) -> bool:
    try:
        gym.make(env_id).close()
    except Exception:  # not registered, or its package is missing
        return False
    return True


def _timed_learn(model: DDPG, steps: int) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - wall), steps / (time.process_time() - cpu)


def _fused_copy(optimizer: th.optim.Optimizer) -> th.optim.Adam:
    """:return: a fused Adam optimizer with the settings and a copy of the state of ``optimizer`` (an Adam optimizer
    with one parameter group), so that its steps run on the same moments: Adam's moments of parameters whose
    gradients stay zero decay through subnormal floats, which some CPUs compute far more slowly than normal ones"""
    group = optimizer.param_groups[0]
    params = list(group["params"])
    settings = {key: group[key] for key in ("lr", "betas", "eps", "weight_decay")}
    fused = th.optim.Adam(params, **settings, fused=True)
    for param in params:
        fused.state[param] = {key: value.clone() for key, value in optimizer.state[param].items()}
    return fused


def _floor_copy(model: DDPG, batch_size: int) -> tuple[Any, Any, Any]:
    """:return: one batch of the model's replay buffer, its discounts, and a copy of its policy in training mode
    whose optimizers are fused Adam ones with the model's settings and a copy of its optimizers' state"""
    data = model.replay_buffer.sample(batch_size)
    discounts = data.discounts if data.discounts is not None else model.gamma
    policy = copy.deepcopy(model.policy)  # its optimizers' states follow it to the copied parameters
    policy.set_training_mode(True)
    policy.actor.optimizer = _fused_copy(policy.actor.optimizer)
    policy.critic.optimizer = _fused_copy(policy.critic.optimizer)
    return data, discounts, policy


def floor_update(model: DDPG, batch_size: int) -> Callable[[], None]:
    """
    The bare math of one DDPG update of a copy of ``model``'s networks: target forward passes, critic forward,
    backward and fused Adam step, actor forward, backward and fused Adam step, on one fixed batch of its replay
    buffer (no sampling, no target update, no logging, no env).

    :param model: A DDPG/DTDPG model whose replay buffer holds at least ``batch_size`` transitions
    :param batch_size: Minibatch size
    :return: A function doing one update
    """
    data, discounts, policy = _floor_copy(model, batch_size)
    actor, critic, actor_target, critic_target = policy.actor, policy.critic, policy.actor_target, policy.critic_target
    actor_opt, critic_opt = actor.optimizer, critic.optimizer

    def update() -> None:
        with th.no_grad():
            next_q = critic_target(data.next_observations, actor_target(data.next_observations))[0]
            target = data.rewards + (1 - data.dones) * discounts * next_q
        critic_opt.zero_grad()
        F.mse_loss(critic(data.observations, data.actions)[0], target).backward()
        critic_opt.step()
        actor_opt.zero_grad()
        (-critic.q1_forward(data.observations, actor(data.observations)).mean()).backward()
        actor_opt.step()

    for _ in range(10):
        update()
    return update


def floor_update_written_out(model: DTDPG, batch_size: int) -> Callable[[], None]:
    """
    :func:`floor_update` with the backward passes written out (:class:`~sb3_dtdpg.dtdpg.backprop.BackpropNetworks`).

    :param model: A DTDPG model whose replay buffer holds at least ``batch_size`` transitions
    :param batch_size: Minibatch size
    :return: A function doing one update
    """
    data, discounts, policy = _floor_copy(model, batch_size)
    networks = BackpropNetworks(policy)
    actor_adam, critic_adam = FusedAdamStep(policy.actor.optimizer), FusedAdamStep(policy.critic.optimizer)

    def update() -> None:
        with th.no_grad():
            next_actions = networks.actor_target.forward(data.next_observations)
            next_q = networks.critic_target.forward(data.next_observations, next_actions)
            target = data.rewards + (1 - data.dones) * discounts * next_q
            networks.critic_step(data, target, critic_adam)
            networks.actor_step(data.observations, actor_adam)

    for _ in range(10):  # the first steps create the optimizers' state (then the fused kernel runs on it)
        update()
    return update


def _timed_updates(update: Callable[[], None], n_updates: int) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(n_updates):
        update()
    return n_updates / (time.perf_counter() - wall), n_updates / (time.process_time() - cpu)


def benchmark(env_id: str, net_arch: list[int], batch_size: int, steps: int, repeats: int, seed: int) -> dict[str, dict]:
    common = dict(batch_size=batch_size, buffer_size=50_000, learning_starts=100, seed=seed, **SHARED)
    dtdpg = DTDPG("MlpPolicy", env_id, policy_kwargs=dict(net_arch=net_arch), **common)
    n_actions = int(np.prod(dtdpg.action_space.shape))
    sigma = float(np.mean(dtdpg.action_noise.current_sigma))

    def ddpg(cls: type[DDPG] = DDPG, **policy_kwargs) -> DDPG:
        noise = OrnsteinUhlenbeckActionNoise(np.zeros(n_actions), sigma * np.ones(n_actions))
        return cls("MlpPolicy", env_id, action_noise=noise, policy_kwargs=dict(net_arch=net_arch, **policy_kwargs), **common)

    models = {
        BASELINE: ddpg(),
        "SB3 DDPG fused Adam": ddpg(optimizer_kwargs=dict(fused=True)),
        "LeanDDPG": ddpg(LeanDDPG),  # SB3's DDPG (default Adam) with the lean step: the same weights bit for bit
        "DTDPG lean=False": DTDPG("MlpPolicy", env_id, policy_kwargs=dict(net_arch=net_arch), lean=False, **common),
        "DTDPG autograd": DTDPG("MlpPolicy", env_id, policy_kwargs=dict(net_arch=net_arch), backprop=False, **common),
        DTDPG_LEAN: dtdpg,
        NO_UPDATES: _NoUpdates("MlpPolicy", env_id, policy_kwargs=dict(net_arch=net_arch), **common),
    }
    for model in models.values():  # warm-up: fill past learning_starts, first gradient steps
        model.learn(max(300, steps // 4))
    floors = {
        "floor, DDPG's networks": floor_update(models[BASELINE], batch_size),
        "floor, DTDPG's networks": floor_update(dtdpg, batch_size),
        WRITTEN_OUT_FLOOR: floor_update_written_out(dtdpg, batch_size),
    }
    wall: dict[str, list[float]] = {name: [] for name in [*models, *floors]}
    cpu: dict[str, list[float]] = {name: [] for name in [*models, *floors]}
    for repeat in range(repeats):
        order = list(models) if repeat % 2 == 0 else list(models)[::-1]
        for name in order:
            steps_per_s_wall, steps_per_s_cpu = _timed_learn(models[name], steps)
            wall[name].append(steps_per_s_wall)
            cpu[name].append(steps_per_s_cpu)
        for name, update in floors.items():  # as many updates as a chunk has steps, in the same round
            updates_per_s_wall, updates_per_s_cpu = _timed_updates(update, steps)
            wall[name].append(updates_per_s_wall)
            cpu[name].append(updates_per_s_cpu)
    lean_wall, lean_cpu = np.array(wall[DTDPG_LEAN]), np.array(cpu[DTDPG_LEAN])
    base_wall, base_cpu = np.array(wall[BASELINE]), np.array(cpu[BASELINE])
    wall_ratios = {name: lean_wall / np.array(wall[name]) for name in models}
    results = {
        name: dict(
            steps_per_s=float(np.median(wall[name])),
            ratio_wall=float(np.median(wall_ratios[name])),
            ratio_wall_range=(float(np.min(wall_ratios[name])), float(np.max(wall_ratios[name]))),
            ratio_cpu=float(np.median(lean_cpu / np.array(cpu[name]))),
            over_ddpg_cpu=float(np.median(np.array(cpu[name]) / base_cpu)),
        )
        for name in models
    }
    # What DTDPG would reach with the bare update and nothing but SB3's rollout loop and replay sampling around it
    for times in (wall, cpu):
        times[CEILING] = list(1 / (1 / np.array(times[NO_UPDATES]) + 1 / np.array(times[WRITTEN_OUT_FLOOR])))
    for name in [*floors, CEILING]:
        results[name] = dict(
            steps_per_s=float(np.median(wall[name])),
            over_ddpg_wall=float(np.median(np.array(wall[name]) / base_wall)),
            over_ddpg_cpu=float(np.median(np.array(cpu[name]) / base_cpu)),
        )
    return results


def vec_benchmark(n_envs: int, net_arch: list[int], batch_size: int, steps: int, repeats: int, seed: int) -> dict[str, dict]:
    """DTDPG on one env vs on the batched vector env (see the module docstring); chunks alternate."""
    from sb3_dtdpg.vec_env import make_mission_vec_env

    common = dict(
        batch_size=batch_size, buffer_size=50_000, learning_starts=100, policy_kwargs=dict(net_arch=net_arch), seed=seed
    )
    models = {
        "1 env": DTDPG("MlpPolicy", "NomaRadioMap-v0", **common),
        f"vec env N={n_envs}, gradient_steps=N": DTDPG(
            "MlpPolicy", make_mission_vec_env(n_envs=n_envs, seed=seed), train_freq=1, gradient_steps=-1, **common
        ),
        f"vec env N={n_envs}, gradient_steps=1": DTDPG(
            "MlpPolicy", make_mission_vec_env(n_envs=n_envs, seed=seed), train_freq=1, gradient_steps=1, **common
        ),
    }
    for model in models.values():
        model.learn(max(300, steps // 4))
    cpu: dict[str, list[float]] = {name: [] for name in models}
    wall: dict[str, list[float]] = {name: [] for name in models}
    for _ in range(repeats):
        for name, model in models.items():
            steps_per_s_wall, steps_per_s_cpu = _timed_learn(model, steps)
            wall[name].append(steps_per_s_wall)
            cpu[name].append(steps_per_s_cpu)
    return {
        name: dict(steps_per_s=float(np.median(wall[name])), cpu_steps_per_s=float(np.median(cpu[name]))) for name in models
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["Pendulum-v1", "NomaRadioMap-v0"])
    parser.add_argument("--net-arch", type=positive_int, nargs="+", default=[128, 128], help="hidden layers (the tuned set's)")
    parser.add_argument("--batch-size", type=BATCH_SIZE, default=128, help="minibatch size (the tuned set's)")
    parser.add_argument(
        "--vec-envs", type=non_negative_int, default=0, help="compare DTDPG on 1 env with the vector env of N (0: skip)"
    )
    parser.add_argument("--steps", type=positive_int, default=500, help="env steps per timed chunk")
    parser.add_argument("--repeats", type=positive_int, default=5, help="timed chunks per algorithm, alternating")
    parser.add_argument("--threads", type=positive_int, default=1, help="torch intra-op threads (1: fastest for small nets)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--flush-denormals",
        action="store_true",
        help="flush subnormal floats to zero in every model and floor (torch.set_flush_denormal): faster on CPUs slow "
        "with them, no longer the default's numbers bit for bit",
    )
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    if args.flush_denormals and not th.set_flush_denormal(True):
        parser.error("--flush-denormals: this CPU cannot flush subnormal floats to zero")
    try:
        import noma_radiomap  # noqa: F401  (registers NomaRadioMap-v0)
    except ImportError:
        pass

    print(
        f"net_arch={args.net_arch} batch_size={args.batch_size} steps={args.steps} x {args.repeats} threads={args.threads}"
        f" flush_denormals={args.flush_denormals}"
    )
    if args.vec_envs > 0:
        results = vec_benchmark(args.vec_envs, args.net_arch, args.batch_size, args.steps, args.repeats, args.seed)
        base = results["1 env"]["cpu_steps_per_s"]
        print(f"{'DTDPG on NomaRadioMap-v0':<40} {'steps/s (wall)':>14} {'(CPU)':>8} {'ratio (CPU)':>12}")
        for name, r in results.items():
            print(f"{name:<40} {r['steps_per_s']:>14.0f} {r['cpu_steps_per_s']:>8.0f} {r['cpu_steps_per_s'] / base:>11.2f}x")
        return
    print(
        f"{'env':<18} {'variant':<25} {'steps/s':>8} {'DTDPG/variant (wall)':>21} {'range':>11} {'(CPU time)':>11} "
        f"{'variant/SB3 DDPG (CPU)':>23}"
    )
    for env_id in args.envs:
        if not _available(env_id):
            print(f"{env_id:<18} (not available, skipped)")
            continue
        results = benchmark(env_id, args.net_arch, args.batch_size, args.steps, args.repeats, args.seed)
        for name, r in results.items():
            if "ratio_wall" in r:
                low, high = r["ratio_wall_range"]
                spread = f"{low:.2f}-{high:.2f}"
                print(
                    f"{env_id:<18} {name:<25} {r['steps_per_s']:>8.0f} {r['ratio_wall']:>20.2f}x {spread:>11} "
                    f"{r['ratio_cpu']:>10.2f}x {r['over_ddpg_cpu']:>22.2f}x"
                )
            else:
                print(
                    f"{env_id:<18} {name:<25} {r['steps_per_s']:>8.0f}   updates/s: {r['over_ddpg_wall']:.2f}x SB3 DDPG's "
                    f"steps/s (wall), {r['over_ddpg_cpu']:.2f}x (CPU time)"
                )


if __name__ == "__main__":
    main()
