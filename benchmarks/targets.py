"""The learning targets on a mission env: test success and MQI after the paper's budget of training episodes.

For each seed and method, one run trains for ``--episodes`` episodes in all (the paper's 500; DT-DPG: phase 1
"destination" until >= 95 % success over the last 20 episodes, then phase 2 "mqi" for the rest, replay relabelled;
DDPG: the paper's baseline, plain MLPs, constant OU noise, the "combined" reward), on the radio-map channel, then
the final policy is tested on 20 missions with Rayleigh fading (seeds 10 000 + i, the same missions for every run
and for the comm-aware planner, whose MQI is the yardstick). Both methods use the same shared settings
(``--hyperparams``).

``--algo-kwargs`` passes further constructor arguments to both methods (e.g. ``'{"gradient_steps": 2}'``); such a
variant needs a ``--tag``, which names its result files and summary.

``--observation`` is the env's observation layout for training and test: ``goal`` (the default: positions,
destinations, gains, arrived flags, and each robot's direction and distance to its destination) or
``destinations`` (the same without direction and distance), each reported in its own rows.

    python benchmarks/targets.py --methods dtdpg ddpg --seeds 0 1 2 3 4 --observation goal
    python benchmarks/targets.py --methods dtdpg --seeds 0 --episodes 30 --eval-episodes 2   # smoke run

Runs are independent processes (one torch thread each); each writes its record when it finishes, to
``<out>/<method>_<observation>[_<tag>][_<transfer>]_seed<k>.json`` (``<transfer>``: DT-DPG's runs only, when the
transfer rule is not the default, e.g. ``threshold0.9``, ``no-early-transfer``, ``phase1-max100``). Finished runs are
skipped when the command is repeated; a record stores the settings of its run (``--env``, ``--env-kwargs``,
``--observation``, ``--hyperparams``, ``--algo-kwargs``, ``--episodes``, ``--eval-episodes`` and DT-DPG's transfer
rule), and a repeated command with other settings is refused before anything runs (use another ``--out``). The summary
(per seed, and the paired DT-DPG - DDPG differences with a 95 % t-interval over seeds) is printed and written to
``<out>/summary_<observation>[_<tag>][_<transfer>].md``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from concurrent.futures import FIRST_COMPLETED, Future, wait
from typing import Any

import numpy as np

from sb3_dtdpg.arguments import non_negative_int, positive_int, seed_int
from sb3_dtdpg.common.files import write_json
from sb3_dtdpg.experiments.storage import reuse_error


def _make_env(env_id: str, layout: str, **kwargs: Any) -> Any:
    import gymnasium as gym
    from stable_baselines3.common.monitor import Monitor

    import noma_radiomap  # noqa: F401

    env = gym.make(env_id, **{"observation": layout, **kwargs})  # --env-kwargs may name another layout
    return Monitor(env, info_keywords=("is_success",))


def run(method: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    """Train one method on one seed for the episode budget; test the final policy."""
    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback

    from sb3_dtdpg.baselines import make_model, reward_phase
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.missions import default_phases

    th.set_num_threads(1)
    env = _make_env(args.env, args.observation, reward_phase=reward_phase(method), **args.env_kwargs)
    extra: dict[str, Any] = {}
    if method == "dtdpg":
        extra["phases"] = default_phases(
            destination_episodes=args.destination_episodes or args.episodes,
            success_threshold=args.success_threshold or None,
        )
    model = make_model(method, env, seed=seed, hyperparams=args.hyperparams, **extra, **args.algo_kwargs)
    record: dict[str, Any] = {
        "method": method,
        "seed": seed,
        "observation": args.observation,
        "transfer": transfer_name(args) if method == "dtdpg" else None,
        "algo_kwargs": args.algo_kwargs,
        "settings": run_settings(method, args),
        "success": [],
        "mqi": [],
    }
    start = time.perf_counter()

    class Budget(BaseCallback):
        """Stops after the episode budget; records training success and MQI per episode."""

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                if done:
                    record["success"].append(bool(info.get("is_success", False)))
                    record["mqi"].append(float(info.get("mqi", np.nan)))
            return len(record["success"]) < args.episodes

    model.learn(10**9, callback=Budget())
    record["seconds"] = time.perf_counter() - start
    record["timesteps"] = int(model.num_timesteps)
    if method == "dtdpg":
        history = model.curriculum_state["history"]
        first = history[0]
        record["phase1_episodes"] = int(first["episodes"])
        record["phase1_reached_95"] = len(history) > 1 and first.get("reason") == "success rate"
        record["phase1_rate_at_transfer"] = float(np.mean(record["success"][: first["episodes"]][-20:]))
    test_env = _make_env(args.env, args.observation, channel="rayleigh", reward_phase="mqi", **args.env_kwargs)
    result = evaluate(model, test_env, n_episodes=args.eval_episodes, seed=10_000)
    summary = result.summary()
    record.update(test_success=summary["success_rate"], test_mqi=summary["mqi"], test_mqi_ci=summary["mqi_ci"])
    record["test_mqi_per_mission"] = [float(e["mqi"]) for e in result.episodes]
    return record


def transfer_name(args: argparse.Namespace) -> str:
    """The early-transfer variant in words: ``""`` for the default (>= 95 % over 20 episodes, no episode cap)."""
    parts = []
    if args.success_threshold != 0.95:
        parts.append(f"threshold{args.success_threshold:g}" if args.success_threshold else "no-early-transfer")
    if args.destination_episodes:
        parts.append(f"phase1-max{args.destination_episodes}")
    return "_".join(parts)


def run_path(args: argparse.Namespace, method: str, seed: int) -> str:
    """
    The record file of one run: ``<out>/<method>_<observation>[_<tag>][_<transfer>]_seed<k>.json``.

    :param args: the command's options
    :param method: ``"dtdpg"`` or ``"ddpg"``
    :param seed: the run's seed
    :return: the file's path
    """
    return os.path.join(args.out, f"{method}_{_variant(args, method != 'dtdpg')}_seed{seed}.json")


def _variant(args: argparse.Namespace, without_transfer: bool = False) -> str:
    """``<observation>[_<tag>][_<transfer>]``: the part of the file names that says the runs' variant (the transfer
    rule only for DT-DPG's runs and the summary)."""
    transfer = "" if without_transfer else transfer_name(args)
    return "_".join(part for part in (args.observation, args.tag, transfer) if part)


def run_settings(method: str, args: argparse.Namespace) -> dict[str, Any]:
    """
    The options that determine a run's result, stored in its record and compared when the command is repeated.

    :param method: ``"dtdpg"`` or ``"ddpg"`` (only DT-DPG's runs depend on the transfer rule)
    :param args: the command's options
    :return: per option (its ``argparse`` dest), its value
    """
    names = ["env", "env_kwargs", "observation", "hyperparams", "algo_kwargs", "episodes", "eval_episodes"]
    if method == "dtdpg":
        names += ["success_threshold", "destination_episodes"]
    return {name: getattr(args, name) for name in names}


def planner_mqi(args: argparse.Namespace) -> dict[str, Any]:
    """The comm-aware planner on the same test missions."""
    from noma_radiomap.planners import CommAwarePlanner
    from sb3_dtdpg.evaluation import evaluate

    test_env = _make_env(args.env, args.observation, channel="rayleigh", reward_phase="mqi", **args.env_kwargs)
    summary = evaluate(CommAwarePlanner(), test_env, n_episodes=args.eval_episodes, seed=10_000).summary()
    return {"test_success": summary["success_rate"], "test_mqi": summary["mqi"], "test_mqi_ci": summary["mqi_ci"]}


def _t_interval(values: list[float]) -> tuple[float, float]:
    from scipy import stats

    x = np.asarray(values, dtype=float)
    if len(x) < 2:
        return float(x.mean()), float("nan")
    return float(x.mean()), float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)))


def _half(half: float, spec: str) -> str:
    """A CI half-width in ``spec``'s format; ``n/a`` when it is undefined (one seed), as ``format_ci`` writes it."""
    return format(half, spec) if np.isfinite(half) else "n/a"


def summarize(records: list[dict[str, Any]], planner: dict[str, Any], args: argparse.Namespace) -> list[str]:
    """Markdown lines: one row per method and seed, the means, and the paired DT-DPG - DDPG differences."""
    from sb3_dtdpg.evaluation import format_ci

    rule = f" to {args.success_threshold:.0%}" if args.success_threshold else ""
    lines = [
        f"Test: {args.eval_episodes} Rayleigh missions; comm-aware planner {planner['test_mqi']:.1f} MQI, "
        f"{planner['test_success']:.0%} success; {args.episodes} training episodes per run; observation "
        f"{args.observation}; DT-DPG's transfer: {transfer_name(args) or 'early, at 95 % over 20 episodes'}"
        + (f"; both methods with {json.dumps(args.algo_kwargs)} ({args.tag})." if args.algo_kwargs else "."),
        "",
        f"| method | seed | phase-1 episodes{rule} | test success | test MQI | MQI / planner | train wall s |",
        "|---|---|---|---|---|---|---|",
    ]
    by_method: dict[str, dict[int, dict[str, Any]]] = {}
    for r in sorted(records, key=lambda r: (r["method"], r["seed"])):
        by_method.setdefault(r["method"], {})[r["seed"]] = r
        if r["method"] != "dtdpg":
            phase1 = "-"
        elif r["phase1_reached_95"]:
            phase1 = str(r["phase1_episodes"])
        else:
            # the DT-DPG rows of one summary share the invocation's transfer rule (it is in their file names)
            ended = "not reached" if args.success_threshold else "the cap, no early transfer"
            phase1 = f"{ended} ({r['phase1_episodes']} ep., last 20 at {r['phase1_rate_at_transfer']:.0%})"
        lines.append(
            f"| {r['method']} | {r['seed']} | {phase1} | {r['test_success']:.0%} "
            f"| {format_ci(r['test_mqi'], r['test_mqi_ci'])} | {r['test_mqi'] / planner['test_mqi']:.3f} "
            f"| {r['seconds']:.0f} |"
        )
    for method, runs in by_method.items():
        success, ci_s = _t_interval([r["test_success"] for r in runs.values()])
        mqi, ci_m = _t_interval([r["test_mqi"] for r in runs.values()])
        lines.append(
            f"| **{method} mean** | {len(runs)} seeds | | {success:.0%} ± {_half(ci_s, '.0%')} | {format_ci(mqi, ci_m)} "
            f"| {mqi / planner['test_mqi']:.3f} | |"
        )
    if "dtdpg" in by_method and "ddpg" in by_method:
        seeds = sorted(set(by_method["dtdpg"]) & set(by_method["ddpg"]))
        if seeds:
            d_success = [by_method["dtdpg"][s]["test_success"] - by_method["ddpg"][s]["test_success"] for s in seeds]
            d_mqi = [by_method["dtdpg"][s]["test_mqi"] - by_method["ddpg"][s]["test_mqi"] for s in seeds]
            (ms, cs), (mm, cm) = _t_interval(d_success), _t_interval(d_mqi)
            lines += [
                "",
                f"Paired DT-DPG - DDPG over {len(seeds)} seeds (mean ± 95 % t-interval): success {ms * 100:+.0f} ± "
                f"{_half(cs * 100, '.0f')} points, MQI {mm:+.1f} ± {_half(cm, '.1f')}.",
            ]
    return lines


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """
    The command's options, checked before anything runs: counts, JSON objects, the env id, and the runs already
    stored in ``--out`` (each must have this command's settings, :func:`~sb3_dtdpg.experiments.storage.reuse_error`).

    :param argv: the arguments (None: ``sys.argv``)
    :return: the options, ``--methods`` and ``--seeds`` without repeats
    :raises SystemExit: (code 2, one error line naming the option and its value) an option cannot be used
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--methods", nargs="+", default=["dtdpg", "ddpg"], choices=["dtdpg", "ddpg"])
    parser.add_argument("--seeds", type=seed_int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--episodes", type=positive_int, default=500, help="training episodes per run, both phases together")
    parser.add_argument("--eval-episodes", type=positive_int, default=20, help="test missions with Rayleigh fading")
    parser.add_argument("--observation", choices=["goal", "destinations"], default="goal")
    parser.add_argument(
        "--success-threshold",
        type=float,
        default=0.95,
        help="DT-DPG's early-transfer rule: phase 1 ends once this share of the last 20 episodes succeeded (0: off)",
    )
    parser.add_argument(
        "--destination-episodes",
        type=non_negative_int,
        default=0,
        help="DT-DPG's phase-1 episode cap (0: the whole budget, phase 1 then ends only by the early transfer)",
    )
    parser.add_argument("--hyperparams", choices=["tuned", "paper"], default="tuned", help="the shared settings")
    parser.add_argument("--env", default="NomaRadioMap-v0")
    parser.add_argument("--env-kwargs", type=json.loads, default={}, help='e.g. \'{"scenario": "small"}\'')
    parser.add_argument(
        "--algo-kwargs", type=json.loads, default={}, help="constructor arguments of both methods, e.g. '{\"tau\": 0.02}'"
    )
    parser.add_argument("--tag", default="", help="the name of an --algo-kwargs variant (in its file names)")
    parser.add_argument("--workers", type=positive_int, default=2)
    parser.add_argument("--out", default="results/targets")
    args = parser.parse_args(argv)
    if not 0 <= args.success_threshold <= 1:
        parser.error(f"--success-threshold {args.success_threshold}: must be in [0, 1] (0: no early transfer)")
    for option in ("env_kwargs", "algo_kwargs"):
        if not isinstance(getattr(args, option), dict):
            parser.error(f"--{option.replace('_', '-')}: expected a JSON object, got {getattr(args, option)!r}")
    if args.algo_kwargs and not args.tag:
        parser.error(f"--algo-kwargs {json.dumps(args.algo_kwargs)}: name the variant with --tag (its result files)")
    args.methods, args.seeds = list(dict.fromkeys(args.methods)), list(dict.fromkeys(args.seeds))
    import gymnasium as gym

    import noma_radiomap  # noqa: F401  (registers its env ids)

    try:
        gym.spec(args.env)
    except gym.error.Error as error:
        parser.error(f"--env {args.env}: {error}")
    error = reuse_error((run_path(args, m, s), run_settings(m, args)) for m in args.methods for s in args.seeds)
    if error is not None:
        parser.error(error)
    return args


def main(argv: list[str] | None = None) -> None:
    """
    Train and test the runs not yet stored in ``--out``, then print and write the summary.

    :param argv: the arguments (None: ``sys.argv``)
    """
    args = parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    todo = [(m, s) for m in args.methods for s in args.seeds if not os.path.exists(run_path(args, m, s))]
    print(f"{len(todo)} runs to do -> {args.out}", flush=True)
    from sb3_dtdpg.experiments.runs import worker_pool  # its workers end with this process

    with worker_pool(args.workers) as pool:
        planner_job = pool.submit(planner_mqi, args)
        jobs: dict[Future, tuple[str, int]] = {pool.submit(run, m, s, args): (m, s) for m, s in todo}
        while jobs:
            done, _ = wait(jobs, return_when=FIRST_COMPLETED)
            for future in done:
                method, seed = jobs.pop(future)
                record = future.result()
                write_json(run_path(args, method, seed), record)
                print(
                    f"{time.strftime('%H:%M:%S')} {method} seed {seed}: test success {record['test_success']:.0%}, "
                    f"MQI {record['test_mqi']:.1f} ({record['seconds']:.0f} s"
                    + (f", phase 1 {record['phase1_episodes']} ep." if method == "dtdpg" else "")
                    + ")",
                    flush=True,
                )
        planner = planner_job.result()
    records = []
    for m in args.methods:
        for s in args.seeds:
            if os.path.exists(run_path(args, m, s)):
                with open(run_path(args, m, s)) as f:
                    records.append(json.load(f))
    lines = summarize(records, planner, args)
    with open(os.path.join(args.out, f"summary_{_variant(args)}.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
