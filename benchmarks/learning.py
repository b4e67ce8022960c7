"""DT-DPG learning benchmark on NomaRadioMap-v0.

1. Phase 1 ("destination"): DT-DPG with its defaults trains until the robots reach their destinations in >= 95 % of
   the last 20 episodes (the curriculum's early-transfer rule) or until the phase's episode budget (500) is spent.
   Bar: >= 95 % success within 500 episodes for at least 2 of 3 seeds.
2. Phase 2 ("mqi"): from each seed's phase-1 checkpoint and replay buffer, the same phase-2 run is repeated with
   each replay handling at the transfer (keep / clear / relabel) and the same seed, then the final policy is
   evaluated on 20 missions with random fading (the paper's test setting).

Seeds and branches run in parallel processes (one torch thread each). Writes ``<out>/learning.json`` (everything,
incl. per-episode curves) and ``<out>/learning.csv`` (one row per seed and replay handling; with ``--phase1-only``
one per seed), rewritten as each run finishes, so that an interruption (Ctrl-C) keeps the finished runs.

    python benchmarks/learning.py                      # 3 seeds, 500 + 150 episodes, 2 processes
    python benchmarks/learning.py --seeds 0 --phase1-episodes 20 --phase2-episodes 5 --eval-episodes 2  # smoke run
"""

import argparse
import csv
import json
import os
import shutil
import time
from concurrent.futures import FIRST_COMPLETED, Future, wait
from typing import Any

import numpy as np

from sb3_dtdpg.arguments import positive_int, seed_int

HANDLINGS = ("keep", "clear", "relabel")


def _phases(phase1_episodes: int, phase2_episodes: int, handling: str) -> list[Any]:
    from sb3_dtdpg.missions import default_phases

    destination, mqi = default_phases(destination_episodes=phase1_episodes, replay_handling=handling)
    # A phase-2 budget, so that each branch stops by itself (the curriculum stops after its last budget)
    return [destination, type(mqi)(**{**mqi.to_dict(), "n_episodes": phase2_episodes})]


def _episode_recorder(bar_position: int, total: int, desc: str) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class EpisodeRecorder(BaseCallback):
        """Per-episode success and MQI, with a progress bar in episodes."""

        def __init__(self) -> None:
            super().__init__()
            self.success: list[bool] = []
            self.mqi: list[float] = []
            self.bar = tqdm(total=total, desc=desc, position=bar_position, leave=False, unit="ep")

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                if done:
                    self.success.append(bool(info.get("is_success", False)))
                    self.mqi.append(float(info.get("mqi", np.nan)))
                    self.bar.update(1)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return EpisodeRecorder()


def run_phase1(seed: int, args: argparse.Namespace, slot: int) -> dict[str, Any]:
    """Train phase 1 until its transfer; keep the checkpoint and the replay buffer for the phase-2 branches."""
    import gymnasium as gym
    import torch as th

    import noma_radiomap  # noqa: F401  (registers the env)
    from sb3_dtdpg import DTDPG

    th.set_num_threads(1)
    run_dir = os.path.join(args.out, f"seed_{seed}")
    # A benchmark run into an earlier one's --out starts each seed afresh (its report is replaced too): the
    # curriculum refuses to write over phase files another run left in its folder
    shutil.rmtree(run_dir, ignore_errors=True)
    os.makedirs(run_dir, exist_ok=True)
    env = gym.make(args.env)
    phases = _phases(args.phase1_episodes, args.phase2_episodes, "keep")
    # Reward components stored in every run, so that the phase-2 branches start from the same buffer
    model = DTDPG(
        "MlpPolicy",
        env,
        phases=phases,
        seed=seed,
        curriculum_save_path=run_dir,
        **_components_buffer(args.hyperparams),
        **args.hyperparams,
    )
    recorder = _episode_recorder(slot, args.phase1_episodes, f"seed {seed} phase 1")
    start = time.perf_counter()

    stop_at_transfer = _stop_at_phase(1)
    model.learn(10**9, callback=[recorder, stop_at_transfer])
    elapsed = time.perf_counter() - start
    model.save_replay_buffer(os.path.join(run_dir, "phase_0_buffer.pkl"))
    first = model.curriculum_state["history"][0]
    reached = first["reason"] == "success rate"
    return {
        "seed": seed,
        "phase1_reached_95": reached,
        "phase1_episodes": first["episodes"],
        "phase1_timesteps": first["timesteps"],
        "phase1_seconds": elapsed,
        "phase1_success_curve": recorder.success,
        "phase1_mqi_curve": recorder.mqi,
    }


def _components_buffer(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """The DTDPG kwargs of a replay buffer that stores reward components, with the run's n-step returns."""
    import inspect

    from sb3_dtdpg import DTDPG
    from sb3_dtdpg.common.buffers import reward_components_buffer

    gamma = hyperparams.get("gamma", inspect.signature(DTDPG).parameters["gamma"].default)
    buffer_class, buffer_kwargs = reward_components_buffer(hyperparams.get("n_steps", 1), gamma)
    return {"replay_buffer_class": buffer_class, "replay_buffer_kwargs": buffer_kwargs}


def _stop_at_phase(index: int) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class StopAtPhase(BaseCallback):
        def _on_step(self) -> bool:
            return self.model.curriculum_state["phase_index"] < index

    return StopAtPhase()


def run_phase2(seed: int, handling: str, args: argparse.Namespace, slot: int) -> dict[str, Any]:
    """Continue from the phase-1 checkpoint with one replay handling; evaluate the final policy."""
    import gymnasium as gym
    import torch as th
    from stable_baselines3.common.utils import set_random_seed

    import noma_radiomap  # noqa: F401
    from sb3_dtdpg import DTDPG
    from sb3_dtdpg.common.buffers import RewardComponentsReplayBuffer
    from sb3_dtdpg.evaluation import evaluate

    th.set_num_threads(1)
    run_dir = os.path.join(args.out, f"seed_{seed}")
    env = gym.make(args.env)
    model = DTDPG.load(os.path.join(run_dir, "phase_0_destination.zip"), env=env, device="cpu")
    model.load_replay_buffer(os.path.join(run_dir, "phase_0_buffer.pkl"))
    assert handling != "relabel" or isinstance(model.replay_buffer, RewardComponentsReplayBuffer)
    model.phases = _phases(args.phase1_episodes, args.phase2_episodes, handling)
    model.curriculum_save_path = os.path.join(run_dir, handling)
    recorder = _episode_recorder(slot, args.phase2_episodes, f"seed {seed} {handling}")
    set_random_seed(seed)  # the same stream in every branch of this seed
    start = time.perf_counter()
    model.learn(10**9, callback=recorder, reset_num_timesteps=False)
    elapsed = time.perf_counter() - start
    result = evaluate(model, args.env, n_episodes=args.eval_episodes, seed=10_000 + seed, channel="rayleigh")
    summary = result.summary()
    tail = recorder.mqi[-args.tail :]
    return {
        "seed": seed,
        "replay_handling": handling,
        "phase2_episodes": len(recorder.mqi),
        "phase2_seconds": elapsed,
        "phase2_train_mqi_tail": float(np.mean(tail)) if tail else float("nan"),
        "phase2_train_success_tail": float(np.mean(recorder.success[-args.tail :])) if recorder.success else float("nan"),
        "eval_success_rate": summary["success_rate"],
        "eval_mqi": summary["mqi"],
        "eval_mqi_ci": summary["mqi_ci"],
        "phase2_mqi_curve": recorder.mqi,
    }


def _json_object(text: str) -> dict[str, Any]:
    """argparse type: a JSON object (DTDPG keyword arguments)."""
    try:
        value = json.loads(text)
    except ValueError:
        value = None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object of DTDPG keyword arguments, got {text!r}")
    return value


def _parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="NomaRadioMap-v0")
    parser.add_argument("--seeds", type=seed_int, nargs="+", default=[0, 1, 2], help="seeds (each runs once)")
    parser.add_argument("--phase1-episodes", type=positive_int, default=500, help="phase-1 episode budget (the bar's horizon)")
    parser.add_argument("--phase2-episodes", type=positive_int, default=150, help="phase-2 episodes per replay handling")
    parser.add_argument("--handlings", nargs="+", default=list(HANDLINGS), choices=HANDLINGS)
    parser.add_argument("--eval-episodes", type=positive_int, default=20, help="test missions with random fading")
    parser.add_argument("--tail", type=positive_int, default=30, help="phase-2 training episodes averaged at the end")
    parser.add_argument(
        "--hyperparams", type=_json_object, default={}, help="DTDPG kwargs as a JSON object, e.g. '{\"tau\": 0.005}'"
    )
    parser.add_argument("--phase1-only", action="store_true", help="skip the phase-2 replay-handling comparison")
    parser.add_argument("--workers", type=positive_int, default=2)
    parser.add_argument("--out", default="results/learning")
    args = parser.parse_args()
    args.seeds = list(dict.fromkeys(args.seeds))  # a seed given twice would write one run folder from two processes
    args.handlings = list(dict.fromkeys(args.handlings))
    return args


def main() -> None:
    args = _parse_args()
    os.makedirs(args.out, exist_ok=True)

    phase1: dict[int, dict[str, Any]] = {}
    phase2: list[dict[str, Any]] = []
    started = time.perf_counter()
    # Phase-1 runs first; each seed's phase-2 branches start as soon as its phase 1 is done
    from sb3_dtdpg.evaluation import format_ci
    from sb3_dtdpg.experiments.runs import worker_pool  # its workers end with this process

    try:
        with worker_pool(args.workers) as pool:
            jobs: dict[Future, tuple[str, int, str | None]] = {}
            for i, seed in enumerate(args.seeds):
                jobs[pool.submit(run_phase1, seed, args, i % args.workers)] = ("phase1", seed, None)
            n_submitted = len(jobs)
            while jobs:
                done, _ = wait(jobs, return_when=FIRST_COMPLETED)
                for future in done:
                    kind, seed, handling = jobs.pop(future)
                    result = future.result()
                    if kind == "phase1":
                        phase1[seed] = result
                        _write_report(args, phase1, phase2, started, complete=False)
                        print(
                            f"seed {seed}: phase 1 {'reached' if result['phase1_reached_95'] else 'did NOT reach'} 95 % "
                            f"after {result['phase1_episodes']} episodes ({result['phase1_seconds']:.0f} s)",
                            flush=True,
                        )
                        for h in [] if args.phase1_only else args.handlings:
                            jobs[pool.submit(run_phase2, seed, h, args, n_submitted % args.workers)] = ("phase2", seed, h)
                            n_submitted += 1
                    else:
                        phase2.append(result)
                        _write_report(args, phase1, phase2, started, complete=False)
                        print(
                            f"seed {seed} {handling}: eval MQI {format_ci(result['eval_mqi'], result['eval_mqi_ci'])}, "
                            f"success {result['eval_success_rate']:.2f} ({result['phase2_seconds']:.0f} s)",
                            flush=True,
                        )
    except KeyboardInterrupt:
        if not phase1:  # nothing finished: an earlier benchmark's report in --out stays
            raise SystemExit("interrupted before any run finished") from None
        _write_report(args, phase1, phase2, started, complete=False)
        raise SystemExit(f"interrupted: the finished runs are in {args.out}/learning.json and learning.csv") from None
    report = _write_report(args, phase1, phase2, started, complete=True)
    _print_report(args, report)


def _write_report(
    args: argparse.Namespace, phase1: dict[int, dict[str, Any]], phase2: list[dict[str, Any]], started: float, complete: bool
) -> dict[str, Any]:
    """Write ``learning.json`` and ``learning.csv`` from the runs finished so far (rewritten after each run, so an
    interruption keeps them); ``complete`` says whether every run has finished."""
    seeds = [seed for seed in args.seeds if seed in phase1]
    reached = [seed for seed in seeds if phase1[seed]["phase1_reached_95"]]
    bar_ok = len(reached) >= min(2, len(args.seeds))
    rows = []
    if args.phase1_only:
        rows = [{k: v for k, v in phase1[seed].items() if not k.endswith("_curve")} for seed in seeds]
    for r in sorted(phase2, key=lambda r: (r["seed"], HANDLINGS.index(r["replay_handling"]))):
        rows.append(
            {
                "seed": r["seed"],
                "phase1_reached_95": phase1[r["seed"]]["phase1_reached_95"],
                "phase1_episodes": phase1[r["seed"]]["phase1_episodes"],
                **{k: v for k, v in r.items() if k not in ("seed", "phase2_mqi_curve")},
            }
        )
    per_handling = {}
    for h in [] if args.phase1_only else args.handlings:
        sel = [r for r in phase2 if r["replay_handling"] == h]
        if not sel:
            continue
        per_handling[h] = {
            "eval_mqi_mean": float(np.mean([r["eval_mqi"] for r in sel])),
            "eval_success_mean": float(np.mean([r["eval_success_rate"] for r in sel])),
            "train_mqi_tail_mean": float(np.mean([r["phase2_train_mqi_tail"] for r in sel])),
        }
    report = {
        "args": vars(args),
        "complete": complete,
        "seconds": time.perf_counter() - started,
        "phase1": [phase1[s] for s in seeds],
        "phase2": phase2,
        "bar_95_within_budget": {"seeds_reached": reached, "holds": bar_ok},
        "replay_handling": per_handling,
    }
    with open(os.path.join(args.out, "learning.json"), "w") as f:
        json.dump(report, f, indent=1)
    with open(os.path.join(args.out, "learning.csv"), "w", newline="") as f:  # an earlier run's rows never stay
        if rows:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return report


def _print_report(args: argparse.Namespace, report: dict[str, Any]) -> None:
    """Print the phase-1 bar and the phase-2 table of a finished benchmark."""
    phase1 = {p["seed"]: p for p in report["phase1"]}
    per_handling = report["replay_handling"]
    print(f"\nPhase 1 (>= 95 % success over 20 episodes within {args.phase1_episodes} episodes):")
    for seed in args.seeds:
        p = phase1[seed]
        status = f"reached after {p['phase1_episodes']} episodes" if p["phase1_reached_95"] else "not reached"
        print(f"  seed {seed}: {status} ({p['phase1_timesteps']} steps, {p['phase1_seconds']:.0f} s)")
    bar = f">= {min(2, len(args.seeds))} of {len(args.seeds)} seeds"
    print(f"  bar ({bar}): {'HOLDS' if report['bar_95_within_budget']['holds'] else 'FAILS'}")
    if args.phase1_only:
        print(f"\nwrote {args.out}/learning.json and learning.csv in {report['seconds']:.0f} s")
        return
    print(f"\nPhase 2 ({args.phase2_episodes} episodes), final policy on {args.eval_episodes} rayleigh missions (seed mean):")
    print(f"  {'handling':<10}{'eval MQI':>10}{'eval success':>14}{'train MQI (tail)':>18}")
    for h, v in per_handling.items():
        print(f"  {h:<10}{v['eval_mqi_mean']:>10.1f}{v['eval_success_mean']:>14.2f}{v['train_mqi_tail_mean']:>18.1f}")
    print(f"\nwrote {args.out}/learning.json and learning.csv in {report['seconds']:.0f} s")


if __name__ == "__main__":
    main()
