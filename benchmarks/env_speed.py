"""Env speed: steps/s of the NOMA radio-map env vs Pendulum-v1, measured side by side in one process.

Both go through ``gymnasium.make`` (same wrappers: PassiveEnvChecker, OrderEnforcing, TimeLimit) and take
random actions from ``action_space.sample()``; episodes are reset when they end. Time is this process's
CPU time, rounds alternate between the envs and each env's best round is kept (like ``timeit``): both make
the ratios robust to other load on a shared machine.
Bars: >= 0.3x Pendulum-v1 in ``radio_map`` mode, >= 0.25x in ``rayleigh`` mode.

Also prints the radio-map build figures of ``benchmarks/radiomap_build.py`` when that script exists.

Usage: ``python benchmarks/env_speed.py [--steps 5000] [--rounds 5]``
"""

import argparse
import importlib.util
import time
from pathlib import Path

import gymnasium as gym

import noma_radiomap  # noqa: F401  (registers the ids)

CASES: dict[str, tuple[str, dict]] = {
    "Pendulum-v1": ("Pendulum-v1", {}),
    "NomaRadioMap-v0 (radio_map, NOMA)": ("NomaRadioMap-v0", {}),
    "NomaRadioMapReality-v0 (rayleigh, NOMA)": ("NomaRadioMapReality-v0", {}),
    "NomaRadioMapOMA-v0 (radio_map, OMA)": ("NomaRadioMapOMA-v0", {}),
}
BARS = {"NomaRadioMap-v0 (radio_map, NOMA)": 0.3, "NomaRadioMapReality-v0 (rayleigh, NOMA)": 0.25}


def steps_per_second(env: gym.Env, n_steps: int) -> float:
    """Random-action steps per CPU second of this process (resets included)."""
    start = time.process_time()
    for _ in range(n_steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return n_steps / (time.process_time() - start)


def run_env_benchmark(n_steps: int = 5000, n_rounds: int = 5) -> dict[str, float]:
    """
    :param n_steps: steps per round
    :param n_rounds: alternating rounds; the best round of each env counts
    :return: best steps/s per case
    """
    envs = {}
    for name, (env_id, kwargs) in CASES.items():
        env = gym.make(env_id, **kwargs)
        env.reset(seed=0)
        env.action_space.seed(0)
        steps_per_second(env, 200)  # warm-up
        envs[name] = env
    best = dict.fromkeys(CASES, 0.0)
    for _ in range(n_rounds):
        for name, env in envs.items():
            best[name] = max(best[name], steps_per_second(env, n_steps))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000, help="steps per round")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds (best kept)")
    args = parser.parse_args()

    best = run_env_benchmark(args.steps, args.rounds)
    reference = best["Pendulum-v1"]
    print(f"{'env':<42} {'steps/s':>10} {'ratio':>7} {'bar':>6}")
    for name, rate in best.items():
        bar = BARS.get(name)
        verdict = "" if bar is None else f">={bar:.2f} {'ok' if rate / reference >= bar else 'FAIL'}"
        print(f"{name:<42} {rate:>10.0f} {rate / reference:>7.3f} {verdict:>6}")

    build_script = Path(__file__).with_name("radiomap_build.py")
    if build_script.exists():
        spec = importlib.util.spec_from_file_location("radiomap_build", build_script)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        if hasattr(module, "run_radiomap_benchmark"):
            print("\nradio-map build (benchmarks/radiomap_build.py):")
            for key, value in module.run_radiomap_benchmark().items():
                print(f"  {key}: {value}")


if __name__ == "__main__":
    main()
