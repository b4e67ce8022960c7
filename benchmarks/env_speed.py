"""Env speed: steps/s of the NOMA radio-map env vs Pendulum-v1, measured side by side in one process.

Both go through ``gymnasium.make`` (same wrappers: PassiveEnvChecker, OrderEnforcing, TimeLimit); episodes are
reset when they end. Two measures: the env alone, stepping through actions drawn from ``action_space.sample()``
before the timed loop (the bars apply to it), and, as SB3 does before ``learning_starts``, with
``action_space.sample()`` inside the timed loop (about half of Pendulum-v1's step, so that ratio flatters a slower
env). Time is this process's CPU time, rounds alternate between the envs and each env's best round is kept (like
``timeit``): both make the ratios less sensitive to other load on a shared machine, not immune to it (on a 2-vCPU VM
a process on the other vCPU slows this one, by different amounts for numpy-bound and Python-bound code).
Bars (env alone): >= 0.3x Pendulum-v1 in ``radio_map`` mode, >= 0.25x in ``rayleigh`` mode.

Vector envs (same run, same way): SB3's ``DummyVecEnv`` of 16 single envs (``gymnasium.make``) against the
batched SB3 face ``sb3_dtdpg.vec_env.MissionVecEnv`` with 16 and more missions, and Gymnasium's
``gymnasium.make_vec`` (the batched ``NomaRadioMapVecEnv``); steps/s count env steps (N per vector step),
actions are uniform random batches. Bar: the batched env >= 10x the ``DummyVecEnv``.

Also prints the radio-map build figures of ``benchmarks/radiomap_build.py`` when that script exists.

Usage: ``python benchmarks/env_speed.py [--steps 2500] [--rounds 10] [--vec-steps 10000]``

Short rounds and many of them: on a shared VM the best of many short rounds is the least disturbed.
"""

import argparse
import importlib.util
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv

import noma_radiomap  # noqa: F401  (registers the ids)
from sb3_dtdpg.arguments import non_negative_int, positive_int

CASES: dict[str, tuple[str, dict]] = {
    "Pendulum-v1": ("Pendulum-v1", {}),
    "NomaRadioMap-v0 (radio_map, NOMA)": ("NomaRadioMap-v0", {}),
    "NomaRadioMapReality-v0 (rayleigh, NOMA)": ("NomaRadioMapReality-v0", {}),
    "NomaRadioMapOMA-v0 (radio_map, OMA)": ("NomaRadioMapOMA-v0", {}),
}
BARS = {"NomaRadioMap-v0 (radio_map, NOMA)": 0.3, "NomaRadioMapReality-v0 (rayleigh, NOMA)": 0.25}
VEC_REFERENCE = "DummyVecEnv, 16 single envs"
VEC_BAR = 10.0
#: Defaults of the command line and of the functions: steps per round, alternating rounds, vector-env steps.
STEPS, ROUNDS, VEC_STEPS = 2500, 10, 10000


def vec_cases() -> dict[str, object]:
    """The vector envs compared (NomaRadioMap-v0: mall, NOMA, radio_map)."""
    from sb3_dtdpg.vec_env import MissionVecEnv

    return {
        VEC_REFERENCE: DummyVecEnv([lambda: gym.make("NomaRadioMap-v0")] * 16),
        "MissionVecEnv (SB3), N = 16": MissionVecEnv.from_id("NomaRadioMap-v0", 16),
        "MissionVecEnv (SB3), N = 64": MissionVecEnv.from_id("NomaRadioMap-v0", 64),
        "MissionVecEnv (SB3), N = 256": MissionVecEnv.from_id("NomaRadioMap-v0", 256),
        "gymnasium.make_vec, N = 64": gym.make_vec("NomaRadioMap-v0", num_envs=64),
        "MissionVecEnv (SB3), rayleigh, N = 64": MissionVecEnv.from_id("NomaRadioMapReality-v0", 64),
    }


def vec_steps_per_second(env: object, n_steps: int, rng: np.random.Generator) -> float:
    """Env steps (N per vector step) per CPU second of this process, random actions, auto-reset."""
    n = env.num_envs
    n_calls = max(1, n_steps // n)
    actions = rng.uniform(-1.0, 1.0, (n_calls, n, *env.action_space.shape[-1:])).astype(np.float32)
    start = time.process_time()
    for action in actions:
        env.step(action)
    return n_calls * n / (time.process_time() - start)


def run_vec_benchmark(n_steps: int = VEC_STEPS, n_rounds: int = ROUNDS) -> dict[str, float]:
    """
    :param n_steps: env steps per round (rounded down to whole vector steps)
    :param n_rounds: alternating rounds; the best round of each env counts
    :return: best env steps/s per case
    """
    rng = np.random.default_rng(0)
    envs = vec_cases()
    for env in envs.values():
        if isinstance(env, gym.vector.VectorEnv):
            env.reset(seed=0)
        else:
            env.seed(0)
            env.reset()
        vec_steps_per_second(env, 2000, rng)  # warm-up
    best = dict.fromkeys(envs, 0.0)
    for _ in range(n_rounds):
        for name, env in envs.items():
            best[name] = max(best[name], vec_steps_per_second(env, n_steps, rng))
    return best


def steps_per_second(env: gym.Env, n_steps: int, sample_in_loop: bool = False) -> float:
    """
    Random-action steps per CPU second of this process (resets included).

    :param env: The env (reset)
    :param n_steps: Steps timed
    :param sample_in_loop: Draw each action with ``action_space.sample()`` inside the timed loop; False: all are
        drawn before it, and only the env is timed
    :return: Steps per CPU second
    """
    if sample_in_loop:
        start = time.process_time()
        for _ in range(n_steps):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
        return n_steps / (time.process_time() - start)
    actions = [env.action_space.sample() for _ in range(n_steps)]
    start = time.process_time()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return n_steps / (time.process_time() - start)


def run_env_benchmark(n_steps: int = STEPS, n_rounds: int = ROUNDS) -> dict[str, dict[str, float]]:
    """
    :param n_steps: steps per round
    :param n_rounds: alternating rounds (both measures in each); the best round of each env and measure counts
    :return: best steps/s per case: ``"env"`` (pre-drawn actions) and ``"with_sample"`` (drawn in the loop)
    """
    envs = {}
    for name, (env_id, kwargs) in CASES.items():
        env = gym.make(env_id, **kwargs)
        env.reset(seed=0)
        env.action_space.seed(0)
        steps_per_second(env, 200)  # warm-up
        envs[name] = env
    best = {name: {"env": 0.0, "with_sample": 0.0} for name in CASES}
    for _ in range(n_rounds):
        for name, env in envs.items():
            best[name]["env"] = max(best[name]["env"], steps_per_second(env, n_steps))
            best[name]["with_sample"] = max(best[name]["with_sample"], steps_per_second(env, n_steps, sample_in_loop=True))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=positive_int, default=STEPS, help="steps per round")
    parser.add_argument("--rounds", type=positive_int, default=ROUNDS, help="alternating rounds (best kept)")
    parser.add_argument(
        "--vec-steps", type=non_negative_int, default=VEC_STEPS, help="env steps per round of the vector envs (0: skip)"
    )
    args = parser.parse_args()

    best = run_env_benchmark(args.steps, args.rounds)
    reference = best["Pendulum-v1"]
    print(f"{'env':<42} {'env alone':>10} {'ratio':>7} {'bar':>9} {'with sample()':>14} {'ratio':>7}")
    for name, rates in best.items():
        ratio, ratio_sample = rates["env"] / reference["env"], rates["with_sample"] / reference["with_sample"]
        bar = BARS.get(name)
        verdict = "" if bar is None else f">={bar:.2f} {'ok' if ratio >= bar else 'FAIL'}"
        print(
            f"{name:<42} {rates['env']:>10.0f} {ratio:>7.3f} {verdict:>9} {rates['with_sample']:>14.0f} {ratio_sample:>7.3f}"
        )

    if args.vec_steps > 0:
        vec_best = run_vec_benchmark(args.vec_steps, args.rounds)
        vec_reference = vec_best[VEC_REFERENCE]
        print(f"\n{'vector env (NomaRadioMap-v0)':<42} {'steps/s':>10} {'ratio':>7} {'bar':>6}")
        for name, rate in vec_best.items():
            ratio = rate / vec_reference
            verdict = "" if name == VEC_REFERENCE else f">={VEC_BAR:.0f} {'ok' if ratio >= VEC_BAR else 'FAIL'}"
            print(f"{name:<42} {rate:>10.0f} {ratio:>7.2f} {verdict:>6}")

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
