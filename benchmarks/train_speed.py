"""
Training speed of DTDPG vs SB3's DDPG, measured side by side in one process.

Both learn with the same network sizes, batch size, buffer size, learning starts and env, with an OU action noise
(DTDPG: its default linearly decayed OU noise; DDPG: SB3's constant OU noise of the same initial scale), one
gradient step per env step. DDPG runs twice: as SB3 builds it (default Adam), and with the fused Adam that DTDPG
uses by default, which isolates the cost of the batch norm layers. After a warm-up, the models alternate
``learn(--steps, reset_num_timesteps=False)`` chunks ``--repeats`` times, so that load changes on the machine hit
all alike. Printed: the median steps/s (wall clock) of each, and the median of the per-repeat ratios
DTDPG / baseline, from wall-clock and from process CPU time.

    python benchmarks/train_speed.py                      # Pendulum-v1, and NomaRadioMap-v0 if installed
    python benchmarks/train_speed.py --envs Pendulum-v1 --steps 1000 --repeats 9
    python benchmarks/train_speed.py --vec-envs 8          # DTDPG on 1 env vs the batched vector env of 8

With ``--vec-envs N``: DTDPG on one ``NomaRadioMap-v0`` env against DTDPG on ``MissionVecEnv`` of N missions,
``train_freq=1`` and ``gradient_steps=-1`` (N gradient steps per vector step: the single env's one update per
transition), and with ``gradient_steps=1`` (one update per N transitions); steps/s count env steps.
"""

import argparse
import time

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import DDPG
from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise

from sb3_dtdpg import DTDPG


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


def benchmark(env_id: str, net_arch: list[int], batch_size: int, steps: int, repeats: int, seed: int) -> dict[str, dict]:
    common = dict(batch_size=batch_size, buffer_size=50_000, learning_starts=100, learning_rate=1e-4, tau=0.002, seed=seed)
    dtdpg = DTDPG("MlpPolicy", env_id, policy_kwargs=dict(net_arch=net_arch), **common)
    n_actions = int(np.prod(dtdpg.action_space.shape))
    sigma = float(np.mean(dtdpg.action_noise.current_sigma))

    def ddpg(**policy_kwargs) -> DDPG:
        noise = OrnsteinUhlenbeckActionNoise(np.zeros(n_actions), sigma * np.ones(n_actions))
        return DDPG("MlpPolicy", env_id, action_noise=noise, policy_kwargs=dict(net_arch=net_arch, **policy_kwargs), **common)

    # DDPG as SB3 builds it (default Adam), and with the fused Adam that DTDPG uses by default
    models = {"DDPG": ddpg(), "DDPG fused Adam": ddpg(optimizer_kwargs=dict(fused=True)), "DTDPG": dtdpg}
    for model in models.values():  # warm-up: fill past learning_starts, first gradient steps
        model.learn(max(300, steps // 4))
    wall: dict[str, list[float]] = {name: [] for name in models}
    cpu: dict[str, list[float]] = {name: [] for name in models}
    for repeat in range(repeats):
        order = list(models) if repeat % 2 == 0 else list(models)[::-1]
        for name in order:
            steps_per_s_wall, steps_per_s_cpu = _timed_learn(models[name], steps)
            wall[name].append(steps_per_s_wall)
            cpu[name].append(steps_per_s_cpu)
    dtdpg_wall, dtdpg_cpu = np.array(wall["DTDPG"]), np.array(cpu["DTDPG"])
    return {
        name: dict(
            steps_per_s=float(np.median(wall[name])),
            ratio_wall=float(np.median(dtdpg_wall / np.array(wall[name]))),
            ratio_cpu=float(np.median(dtdpg_cpu / np.array(cpu[name]))),
        )
        for name in models
    }


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
    parser.add_argument("--net-arch", type=int, nargs="+", default=[128, 64], help="hidden layers (DTDPG's default)")
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--vec-envs", type=int, default=0, help="compare DTDPG on 1 env with the vector env of N (0: skip)")
    parser.add_argument("--steps", type=int, default=1000, help="env steps per timed chunk")
    parser.add_argument("--repeats", type=int, default=7, help="timed chunks per algorithm, alternating")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads (1: fastest for small nets)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    try:
        import noma_radiomap  # noqa: F401  (registers NomaRadioMap-v0)
    except ImportError:
        pass

    print(f"net_arch={args.net_arch} batch_size={args.batch_size} steps={args.steps} x {args.repeats} threads={args.threads}")
    if args.vec_envs > 0:
        results = vec_benchmark(args.vec_envs, args.net_arch, args.batch_size, args.steps, args.repeats, args.seed)
        base = results["1 env"]["cpu_steps_per_s"]
        print(f"{'DTDPG on NomaRadioMap-v0':<40} {'steps/s (wall)':>14} {'(CPU)':>8} {'ratio (CPU)':>12}")
        for name, r in results.items():
            print(f"{name:<40} {r['steps_per_s']:>14.0f} {r['cpu_steps_per_s']:>8.0f} {r['cpu_steps_per_s'] / base:>11.2f}x")
        return
    print(f"{'env':<18} {'baseline':<17} {'steps/s':>8} {'DTDPG/baseline (wall)':>22} {'(CPU time)':>11}")
    for env_id in args.envs:
        if not _available(env_id):
            print(f"{env_id:<18} (not available, skipped)")
            continue
        results = benchmark(env_id, args.net_arch, args.batch_size, args.steps, args.repeats, args.seed)
        for name, r in results.items():
            print(f"{env_id:<18} {name:<17} {r['steps_per_s']:>8.0f} {r['ratio_wall']:>21.2f}x {r['ratio_cpu']:>10.2f}x")


if __name__ == "__main__":
    main()
