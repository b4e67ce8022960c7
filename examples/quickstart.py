"""
Quickstart: train DT-DPG on the NOMA indoor radio-map env, evaluate it, save it, load it and predict.

    python examples/quickstart.py                      # small budget: a minute or two on a laptop CPU
    python examples/quickstart.py --timesteps 35000 --tensorboard-log runs/   # learns the mission (README)

The ``tuned`` preset gives DTDPG the measured best settings on the mission (docs/BENCHMARKS.md; the paper's
Table I is the ``paper`` preset): batch-norm actor and critic, OU noise decaying per episode, and the two-phase
curriculum ("destination", then "mqi" once the robots reach their destinations in 95 % of the last 20 episodes, or
after 500 episodes). The env gets its id's observation by default: the goal-conditioned one on the missions of
``NomaRadioMap-v0`` (``--observation destinations``, positions, destinations and gains without the goal features,
learns them far more slowly: docs/BENCHMARKS.md "What limits learning"), the paper's state, Eq. (24), on the
paper's task, ``NomaRadioMapPaper-v0``. A small budget stays in the first phase.
"""

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th

import noma_radiomap  # noqa: F401  (registers NomaRadioMap-v0)
from sb3_dtdpg import DTDPG, MissionLoggerCallback, preset
from sb3_dtdpg.arguments import positive_int, seed_int
from sb3_dtdpg.evaluation import evaluate, format_ci


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=positive_int, default=5_000, help="training env steps")
    parser.add_argument("--env", default="NomaRadioMap-v0", help="a NomaRadioMap env id")
    parser.add_argument(
        "--observation",
        default=None,
        choices=["goal", "destinations", "paper"],
        help="goal-conditioned, destinations (positions, destinations, gains) or the paper's state, Eq. (24) "
        "(default: the env id's, goal on the missions, paper on the paper's task)",
    )
    parser.add_argument("--eval-episodes", type=positive_int, default=5, help="test episodes (Rayleigh fading)")
    parser.add_argument("--seed", type=seed_int, default=0, help="training seed")
    parser.add_argument("--save-path", default="dtdpg_noma.zip", help="the saved model file")
    parser.add_argument("--tensorboard-log", default=None, help="TensorBoard folder (runs appear as DTDPG_<n>)")
    parser.add_argument(
        "--threads", type=positive_int, default=1, help="torch threads (1 is fastest for these small networks)"
    )
    args = parser.parse_args(argv)
    th.set_num_threads(args.threads)

    env_kwargs = {} if args.observation is None else {"observation": args.observation}
    env = gym.make(args.env, **env_kwargs)
    model = DTDPG("MlpPolicy", env, seed=args.seed, tensorboard_log=args.tensorboard_log, **preset("tuned"))
    model.learn(args.timesteps, callback=MissionLoggerCallback(), progress_bar=True)
    phase = model.phases[model.curriculum_state["phase_index"]].name
    print(f"trained {model.num_timesteps} steps, {model._episode_num} episodes; curriculum phase: {phase!r}")
    model.save(args.save_path)
    save_path = Path(args.save_path) if Path(args.save_path).suffix else Path(args.save_path).with_suffix(".zip")

    # The paper's test protocol: Rayleigh fading, episode i reset with seed + i (the same missions for every policy)
    result = evaluate(model, args.env, n_episodes=args.eval_episodes, seed=10_000, env_kwargs=env_kwargs)
    summary = result.summary()
    print(
        f"evaluation ({args.eval_episodes} Rayleigh episodes): success {100 * summary['success_rate']:.0f} %, "
        f"MQI {format_ci(summary['mqi'], summary['mqi_ci'])}, mission time {summary['mission_time']:.0f} steps"
    )

    loaded = DTDPG.load(save_path, env=env)
    obs, _ = gym.make(args.env, **env_kwargs).reset(seed=10_000)
    action, _ = loaded.predict(obs, deterministic=True)
    assert np.array_equal(action, model.predict(obs, deterministic=True)[0])
    print(f"saved to {save_path}, loaded; first action of a mission: {np.round(action, 3)}")


if __name__ == "__main__":
    main()
