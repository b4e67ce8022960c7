"""What limits DT-DPG's learning on NomaRadioMap-v0: ablations of phase 1 ("destination") on the same seeds.

Each configuration is a change to one base set-up (``--base``: the tuned settings, ``sb3_dtdpg.baselines.TUNED_KWARGS``);
every run trains phase 1 of the curriculum (the "destination" reward) on ``mall`` for at most ``--episodes``
episodes and records, per episode, the training success (with exploration noise), and every ``--eval-every``
episodes the *deterministic* policy's success on ``--eval-missions`` fixed missions (radio-map channel), its mean
mission time and the share of saturated action components (``|a| > 0.99``). A run stops when its deterministic
success reaches ``--stop-at`` on two evaluations in a row, or at ``--episodes``.

Figures per run: ``train95`` (the first episode at which the training success over the last 20 episodes is
>= 95 %, the curriculum's early-transfer rule) and ``eval95`` (the first evaluation at which the deterministic
policy brings both robots home in >= 95 % of the fixed missions).

    python benchmarks/diagnosis.py --configs base no_norm sac --seeds 0 1       # 2 processes
    python benchmarks/diagnosis.py --list                                        # the configurations
    python benchmarks/diagnosis.py --configs relgoal goal_vec8_gs2_lr2e3 --seeds 0 1 --sooner-than relgoal

With ``--sooner-than CONFIG``: also, per configuration, how much sooner than ``CONFIG`` each seed reached its first
deterministic 95 % evaluation, in CPU time of the run (CONFIG's over the configuration's), and the mean over the
seeds where both reached it.

Runs are independent processes (one torch thread each), written to ``<out>/<config>_seed<k>.json`` as they finish
(beside the model, ``<config>_seed<k>.zip``, and ``<config>_seed<k>.log``, one line per evaluation as it happens,
started afresh with each run); finished runs are skipped when the command is repeated, so an interrupted sweep
resumes. A record stores the settings of its run (``--env``, ``--base``, ``--episodes``, ``--eval-every``,
``--eval-missions``, ``--stop-at``), and a repeated command with other settings is refused before anything runs (use
another ``--out``).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import time
from concurrent.futures import FIRST_COMPLETED, Future, wait
from typing import Any

import numpy as np

from sb3_dtdpg.arguments import positive_int, seed_int
from sb3_dtdpg.common.files import write_json
from sb3_dtdpg.experiments.storage import reuse_error

#: Changes to the base set-up. Keys: ``algo`` (dtdpg, ddpg, td3, sac), ``kwargs`` (algorithm kwargs merged into the
#: base, ``policy_kwargs`` merged key by key), ``phase`` (fields of the phase-1 :class:`Phase`: the OU schedule),
#: ``noise`` ("ou" or "normal" with ``noise_sigma``), ``env`` (env kwargs), ``n_envs`` (train on the batched vector env
#: of that many missions).
CONFIGS: dict[str, dict[str, Any]] = {
    "base": {},
    # exploration
    "ou0.2": {"phase": {"sigma": 0.2, "final_sigma": 0.05}},
    "ou0.8": {"phase": {"sigma": 0.8, "final_sigma": 0.1}},
    "ou_fast_decay": {"phase": {"sigma": 0.5, "final_sigma": 0.05, "decay_episodes": 100}},
    "normal0.2": {"noise": "normal", "noise_sigma": 0.2},
    # normalisation
    "no_norm": {"kwargs": {"policy_kwargs": {"actor_norm": "none", "critic_norm": "none"}}},
    "actor_bn_only": {"kwargs": {"policy_kwargs": {"critic_norm": "none"}}},
    "critic_bn_only": {"kwargs": {"policy_kwargs": {"actor_norm": "none"}}},
    "layer_norm": {"kwargs": {"policy_kwargs": {"actor_norm": "layer", "critic_norm": "layer"}}},
    "critic_ln": {"kwargs": {"policy_kwargs": {"critic_norm": "layer"}}},
    # returns
    "gamma0.99": {"kwargs": {"gamma": 0.99}},
    "gamma0.9": {"kwargs": {"gamma": 0.9}},
    "nstep1": {"kwargs": {"n_steps": 1}},
    "nstep5": {"kwargs": {"n_steps": 5}},
    # optimisation
    "lr3e-4": {"kwargs": {"learning_rate": 3e-4}},
    "tau0.02": {"kwargs": {"tau": 0.02}},
    "batch256": {"kwargs": {"batch_size": 256}},
    "net256": {"kwargs": {"policy_kwargs": {"net_arch": [256, 256]}}},
    "utd2": {"kwargs": {"gradient_steps": 2}},
    "ls500": {"kwargs": {"learning_starts": 500}},
    # rewards
    "geodesic": {"env": {"inducing": "geodesic"}},
    # extensions (not the paper's method): replay seeded with the comm-aware planner's episodes
    "demos20": {"demos": 20},
    "demos20_ls500": {"demos": 20, "kwargs": {"learning_starts": 500}},
    # extension: a goal-conditioned observation (noma_radiomap.wrappers.RelativeGoalObservation)
    "relgoal": {"wrapper": "relative_goal"},
    "relgoal_sac": {"algo": "sac", "wrapper": "relative_goal"},
    # anchors: SB3's own algorithms with the same shared settings (plain MLPs)
    "sac": {"algo": "sac"},
    "td3": {"algo": "td3", "noise": "normal", "noise_sigma": 0.1},
    "ddpg": {"algo": "ddpg", "noise": "normal", "noise_sigma": 0.1},
    # fewer gradient steps per env step (one update every 2 or 4 env steps): what trades learning for speed
    "tf2": {"kwargs": {"train_freq": 2}},
    "tf4": {"kwargs": {"train_freq": 4}},
    # N missions per step (sb3_dtdpg.vec_env.make_mission_vec_env): one update per transition, or fewer
    "vec4": {"n_envs": 4, "kwargs": {"train_freq": 1, "gradient_steps": -1}},
    "vec4_gs1": {"n_envs": 4, "kwargs": {"train_freq": 1, "gradient_steps": 1}},
    "vec8_gs2": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 2}},
    "vec16_gs2": {"n_envs": 16, "kwargs": {"train_freq": 1, "gradient_steps": 2}},
    "vec16_gs4": {"n_envs": 16, "kwargs": {"train_freq": 1, "gradient_steps": 4}},
    "vec8_gs1": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 1}},
    "vec16_gs1": {"n_envs": 16, "kwargs": {"train_freq": 1, "gradient_steps": 1}},
    "vec2_gs1": {"n_envs": 2, "kwargs": {"train_freq": 1, "gradient_steps": 1}},
    # fewer, larger updates: a minibatch of 512 costs little more than one of 128 on a CPU
    "vec4_gs1_b512": {"n_envs": 4, "kwargs": {"train_freq": 1, "gradient_steps": 1, "batch_size": 512}},
    "vec4_gs1_b256": {"n_envs": 4, "kwargs": {"train_freq": 1, "gradient_steps": 1, "batch_size": 256}},
    "vec8_gs1_b256": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 1, "batch_size": 256}},
    # fewer updates, each a larger step
    "vec4_gs1_lr2e3": {"n_envs": 4, "kwargs": {"train_freq": 1, "gradient_steps": 1, "learning_rate": 2e-3}},
    "vec8_gs1_lr2e3": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 1, "learning_rate": 2e-3}},
    "vec8_gs2_lr2e3": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 2, "learning_rate": 2e-3}},
    "vec8_gs2_lr3e3": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 2, "learning_rate": 3e-3}},
    "vec8_gs3_lr2e3": {"n_envs": 8, "kwargs": {"train_freq": 1, "gradient_steps": 3, "learning_rate": 2e-3}},
    "vec12_gs3_lr2e3": {"n_envs": 12, "kwargs": {"train_freq": 1, "gradient_steps": 3, "learning_rate": 2e-3}},
    "vec8_gs2_lr2e3_tau0.01": {
        "n_envs": 8,
        "kwargs": {"train_freq": 1, "gradient_steps": 2, "learning_rate": 2e-3, "tau": 0.01},
    },
    "vec6_gs2_lr2e3": {"n_envs": 6, "kwargs": {"train_freq": 1, "gradient_steps": 2, "learning_rate": 2e-3}},
}
#: The same ablations with the goal-conditioned observation: ``goal_<name>``.
CONFIGS.update(
    {
        f"goal_{name}": {**config, "wrapper": "relative_goal"}
        for name, config in list(CONFIGS.items())
        if not name.startswith("relgoal") and "demos" not in config
    }
)


def build_model(config: dict[str, Any], seed: int, base: dict[str, Any], episodes: int, env: Any) -> Any:
    """The model of one configuration (not yet trained)."""
    from stable_baselines3 import DDPG, SAC, TD3
    from stable_baselines3.common.noise import NormalActionNoise

    from sb3_dtdpg import DTDPG
    from sb3_dtdpg.common.phases import Phase

    algo = config.get("algo", "dtdpg")
    kwargs = copy.deepcopy(base)
    for key, value in config.get("kwargs", {}).items():
        if key == "policy_kwargs":
            kwargs["policy_kwargs"] = {**kwargs.get("policy_kwargs", {}), **value}
        else:
            kwargs[key] = value
    n_actions = env.action_space.shape[0]
    if config.get("noise") == "normal":
        kwargs["action_noise"] = NormalActionNoise(np.zeros(n_actions), config["noise_sigma"] * np.ones(n_actions))
    if algo == "dtdpg":
        phase = {"name": "destination", "n_episodes": episodes, "sigma": 0.5, "final_sigma": 0.1, "decay_episodes": 500}
        phase.update(config.get("phase", {}))
        if "action_noise" in kwargs:
            phase.update(sigma=None, final_sigma=None, decay_episodes=None)
        return DTDPG("MlpPolicy", env, seed=seed, phases=[Phase(**phase)], **kwargs)
    if algo == "sac":
        # SAC's own defaults for what is not shared: a squashed Gaussian policy, two critics, automatic entropy
        policy_kwargs = {k: v for k, v in kwargs.pop("policy_kwargs", {}).items() if k == "net_arch"}
        return SAC("MlpPolicy", env, seed=seed, policy_kwargs=policy_kwargs, **kwargs)
    policy_kwargs = {k: v for k, v in kwargs.pop("policy_kwargs", {}).items() if k == "net_arch"}
    cls = {"td3": TD3, "ddpg": DDPG}[algo]
    return cls("MlpPolicy", env, seed=seed, policy_kwargs=policy_kwargs, **kwargs)


def evaluate_deterministic(model: Any, env: Any, n_missions: int) -> dict[str, Any]:
    """Deterministic policy on fixed missions (seeds 10 000 + i): success rate, mean time, saturation share, and
    for each robot that did not arrive its destination and final distance to it."""
    successes, times, saturated, components, misses = 0, [], 0, 0, []
    for i in range(n_missions):
        obs, _ = env.reset(seed=10_000 + i)
        done, steps = False, 0
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            saturated += int((np.abs(action) > 0.99).sum())
            components += action.size
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
        successes += bool(info["is_success"])
        times.append(steps)
        base = env.unwrapped
        for u in np.flatnonzero(~base.arrived):
            distance = float(np.hypot(*(base.positions[u] - base.destinations[u])))
            misses.append([int(u), base.destinations[u].tolist(), base.positions[u].round(1).tolist(), round(distance, 1)])
    return {
        "success": successes / n_missions,
        "mean_steps": float(np.mean(times)),
        "saturated": saturated / components,
        "misses": misses,
    }


def run(name: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    """Train one configuration on one seed; return its curves and figures."""
    import gymnasium as gym
    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback

    import noma_radiomap  # noqa: F401
    from sb3_dtdpg.baselines import TUNED_KWARGS

    th.set_num_threads(1)
    log_path = run_path(args.out, name, seed, ".log")
    # the run starts afresh (its record is not stored): an interrupted run's evaluations would read as this one's
    open(log_path, "w").close()
    config = CONFIGS[name]
    # Without the goal features: positions, destinations, gains and arrived flags (the env's "destinations" layout).
    observation = "goal" if config.get("wrapper") == "relative_goal" else "destinations"
    env_kwargs = {"reward_phase": "destination", "observation": observation, **config.get("env", {})}
    eval_env = gym.make(args.env, **env_kwargs)
    if config.get("n_envs"):
        from sb3_dtdpg.vec_env import make_mission_vec_env

        env = make_mission_vec_env(args.env, config["n_envs"], seed=seed, env_kwargs=env_kwargs)
    else:
        env = gym.make(args.env, **env_kwargs)
    base = copy.deepcopy(TUNED_KWARGS) if args.base == "tuned" else {}
    model = build_model(config, seed, base, args.episodes, env)
    record: dict[str, Any] = {
        "config": name,
        "seed": seed,
        "settings": run_settings(args),
        "train_success": [],
        "evals": [],
    }
    # wall clock, and this process's CPU time (one torch thread: the wall clock of an undisturbed core)
    start, cpu_start = time.perf_counter(), time.process_time()

    class Recorder(BaseCallback):
        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                if not done:
                    continue
                record["train_success"].append(bool(info.get("is_success", False)))
                n = len(record["train_success"])
                if n % args.eval_every == 0:
                    result = evaluate_deterministic(self.model, eval_env, args.eval_missions)
                    result.update(
                        episode=n,
                        timesteps=self.num_timesteps,
                        seconds=time.perf_counter() - start,
                        cpu_seconds=time.process_time() - cpu_start,
                    )
                    record["evals"].append(result)
                    with open(log_path, "a") as log:
                        print(json.dumps({k: v for k, v in result.items() if k != "misses"}), file=log)
                    recent = [e["success"] for e in record["evals"][-2:]]
                    if len(recent) == 2 and min(recent) >= args.stop_at:
                        return False
                if n >= args.episodes:
                    return False
            return True

    callbacks: list[BaseCallback] = [Recorder()]
    if config.get("demos"):
        from noma_radiomap.planners import CommAwarePlanner
        from sb3_dtdpg.common.demonstrations import DemonstrationCallback

        callbacks.insert(0, DemonstrationCallback(CommAwarePlanner(), config["demos"]))
    model.learn(10**9, callback=callbacks)
    record["seconds"] = time.perf_counter() - start
    record["cpu_seconds"] = time.process_time() - cpu_start
    model.save(os.path.join(args.out, f"{name}_seed{seed}"))
    record["timesteps"] = int(model.num_timesteps)
    record.update(figures(record["train_success"], record["evals"]))
    return record


def figures(train_success: list[bool], evals: list[dict[str, Any]], window: int = 20) -> dict[str, Any]:
    """``train95``: first episode with >= 95 % training success over ``window`` episodes; ``eval95``: first
    evaluation episode with >= 95 % deterministic success (None: not reached)."""
    s = np.asarray(train_success, dtype=float)
    train95 = None
    if len(s) >= window:
        rolling = np.convolve(s, np.ones(window) / window, mode="valid")
        hits = np.flatnonzero(rolling >= 0.95 - 1e-9)
        train95 = int(hits[0] + window) if hits.size else None
    eval95 = next((e["episode"] for e in evals if e["success"] >= 0.95), None)
    best_eval = max((e["success"] for e in evals), default=float("nan"))
    return {"train95": train95, "eval95": eval95, "best_eval_success": best_eval, "episodes": len(s)}


def run_path(out: str, name: str, seed: int, suffix: str = ".json") -> str:
    """
    A file of one run: ``<out>/<config>_seed<k><suffix>``.

    :param out: the output folder
    :param name: the configuration
    :param seed: the run's seed
    :param suffix: ``.json`` (the record) or ``.log`` (its evaluations as they happen)
    :return: the file's path
    """
    return os.path.join(out, f"{name}_seed{seed}{suffix}")


def run_settings(args: argparse.Namespace) -> dict[str, Any]:
    """
    The options that determine a run's result, stored in its record and compared when the command is repeated.

    :param args: the command's options
    :return: per option (its ``argparse`` dest), its value
    """
    names = ["env", "base", "episodes", "eval_every", "eval_missions", "stop_at"]
    return {name: getattr(args, name) for name in names}


def _record(out: str, name: str, seed: int) -> dict[str, Any] | None:
    """A finished run's record (None: not run)."""
    path = run_path(out, name, seed)
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def summary_rows(out: str, names: list[str], seeds: list[int]) -> list[str]:
    """One Markdown row per configuration: train95 / eval95 per seed, best deterministic success, wall time."""
    rows = [
        "| config | train95 per seed | eval95 per seed | best det. success | saturated (last eval) | wall s |",
        "|---|---|---|---|---|---|",
    ]
    for name in names:
        results = [r for r in (_record(out, name, seed) for seed in seeds) if r is not None]
        if not results:
            continue

        def cells(values: list[Any]) -> str:
            return " / ".join("-" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v) for v in values)

        saturated = [r["evals"][-1]["saturated"] if r["evals"] else None for r in results]
        rows.append(
            f"| {name} | {cells([r['train95'] for r in results])} | {cells([r['eval95'] for r in results])} "
            f"| {cells([r['best_eval_success'] for r in results])} | {cells(saturated)} "
            f"| {cells([str(round(r['seconds'])) for r in results])} |"
        )
    return rows


def _cpu_to_eval95(out: str, name: str, seed: int) -> float | None:
    """The run's CPU seconds at its ``eval95`` evaluation (None: not reached, or not run)."""
    record = _record(out, name, seed)
    if record is None or record["eval95"] is None:
        return None
    return next(e["cpu_seconds"] for e in record["evals"] if e["episode"] == record["eval95"])


def sooner_rows(out: str, names: list[str], seeds: list[int], reference: str) -> list[str]:
    """One Markdown row per configuration: ``reference``'s CPU time to the first 95 % evaluation over the
    configuration's, per seed (``-``: not reached), and their mean over the seeds where both reached it."""
    rows = [f"| config | reached 95 % | sooner than {reference}, per seed | mean |", "|---|---|---|---|"]
    base = {seed: _cpu_to_eval95(out, reference, seed) for seed in seeds}
    for name in names:
        if name == reference:
            continue
        own = {seed: _cpu_to_eval95(out, name, seed) for seed in seeds}
        ratios = [base[s] / own[s] if base[s] is not None and own[s] is not None else None for s in seeds]
        reached = [r for r in ratios if r is not None]
        mean = f"{np.mean(reached):.2f}x" if reached else "-"
        cells = " / ".join("-" if r is None else f"{r:.2f}" for r in ratios)
        rows.append(f"| {name} | {sum(v is not None for v in own.values())} of {len(seeds)} | {cells} | {mean} |")
    return rows


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """
    The command's options, checked before anything runs: counts, configuration names, the env id, and the runs
    already stored in ``--out`` (each must have this command's settings, :func:`~sb3_dtdpg.experiments.storage.reuse_error`).

    :param argv: the arguments (None: ``sys.argv``)
    :return: the options, ``--configs`` and ``--seeds`` without repeats
    :raises SystemExit: (code 2, one error line naming the option and its value) an option cannot be used
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--configs", nargs="+", default=["base"], help="configurations to run (see --list)")
    parser.add_argument("--seeds", type=seed_int, nargs="+", default=[0, 1])
    parser.add_argument("--episodes", type=positive_int, default=300, help="phase-1 episode budget per run")
    parser.add_argument("--eval-every", type=positive_int, default=25, help="episodes between deterministic evaluations")
    parser.add_argument("--eval-missions", type=positive_int, default=20, help="fixed missions per evaluation")
    parser.add_argument("--stop-at", type=float, default=0.95, help="stop after two evaluations at this success")
    parser.add_argument("--base", choices=["tuned", "defaults"], default="tuned", help="the set-up the configs change")
    parser.add_argument("--env", default="NomaRadioMap-v0")
    parser.add_argument("--workers", type=positive_int, default=2)
    parser.add_argument("--out", default="results/diagnosis")
    parser.add_argument("--list", action="store_true", help="print the configurations and exit")
    parser.add_argument(
        "--sooner-than", metavar="CONFIG", help="also print how much sooner (CPU time) each config reached 95 %% than this one"
    )
    args = parser.parse_args(argv)
    if args.list:
        return args
    if not np.isfinite(args.stop_at):
        parser.error(f"--stop-at {args.stop_at}: expected a success rate")
    unknown = sorted(set(args.configs) - set(CONFIGS) | ({args.sooner_than} - set(CONFIGS) - {None}))
    if unknown:
        parser.error(f"unknown configuration(s) {unknown}; known: {sorted(CONFIGS)}")
    args.configs, args.seeds = list(dict.fromkeys(args.configs)), list(dict.fromkeys(args.seeds))
    import gymnasium as gym

    import noma_radiomap  # noqa: F401  (registers its env ids)

    try:
        gym.spec(args.env)
    except gym.error.Error as error:
        parser.error(f"--env {args.env}: {error}")
    # --sooner-than's runs are read too: they must have been run with these settings as well
    names = args.configs + ([args.sooner_than] if args.sooner_than not in (None, *args.configs) else [])
    settings = run_settings(args)
    error = reuse_error((run_path(args.out, name, seed), settings) for name in names for seed in args.seeds)
    if error is not None:
        parser.error(error)
    return args


def main(argv: list[str] | None = None) -> None:
    """
    Run the configurations and seeds not yet stored in ``--out``, then print the summary.

    :param argv: the arguments (None: ``sys.argv``)
    """
    args = parse_args(argv)
    if args.list:
        for name, config in CONFIGS.items():
            print(f"{name:16s} {config}")
        return
    os.makedirs(args.out, exist_ok=True)
    todo = [(n, s) for n in args.configs for s in args.seeds if not os.path.exists(run_path(args.out, n, s))]
    print(f"{len(todo)} runs to do ({len(args.configs) * len(args.seeds) - len(todo)} already done) -> {args.out}")
    from sb3_dtdpg.experiments.runs import worker_pool  # its workers end with this process

    with worker_pool(args.workers) as pool:
        jobs: dict[Future, tuple[str, int]] = {pool.submit(run, n, s, args): (n, s) for n, s in todo}
        while jobs:
            done, _ = wait(jobs, return_when=FIRST_COMPLETED)
            for future in done:
                name, seed = jobs.pop(future)
                record = future.result()
                write_json(run_path(args.out, name, seed), record)
                evals = " ".join(f"{e['success']:.2f}" for e in record["evals"])
                print(
                    f"{time.strftime('%H:%M:%S')} {name} seed {seed}: train95 {record['train95']} eval95 {record['eval95']} "
                    f"({record['episodes']} ep, {record['seconds']:.0f} s); det. success per eval: {evals}",
                    flush=True,
                )
    print("\n".join(summary_rows(args.out, args.configs, args.seeds)))
    if args.sooner_than:
        print("\n".join(sooner_rows(args.out, args.configs, args.seeds, args.sooner_than)))


if __name__ == "__main__":
    main()
