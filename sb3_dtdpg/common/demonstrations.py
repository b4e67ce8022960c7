"""Replay seeded with a demonstrator's episodes (an extension of DT-DPG, in the spirit of DDPGfD)."""

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_dtdpg.evaluation import Planner

#: What :class:`DemonstrationCallback` needs of a demonstrator: the :class:`sb3_dtdpg.evaluation.Planner` protocol.
Demonstrator = Planner


class DemonstrationCallback(BaseCallback):
    """
    Seed the replay buffer with ``n_episodes`` episodes of a demonstrator before the first step of training,
    the replay half of DDPGfD (Vecerik et al., "Leveraging Demonstrations for Deep Reinforcement Learning on
    Robotics Problems with Sparse Rewards", 2017; no behaviour-cloning loss). It is not part of the paper's
    DT-DPG: an extension, off by default, reported in rows of its own (docs/BENCHMARKS.md).

    The episodes are played in the training env (its first sub-env, with the reward phase the curriculum set,
    so put this callback after the curriculum's; ``DTDPG.learn`` adds user callbacks after its own) and stored
    with their ``info``, so a replay buffer that keeps reward components can relabel them at a transfer. They do
    not count as timesteps or curriculum episodes. Afterwards the training env is reset. Seeding happens once, in
    the first ``learn()`` of a model (``num_timesteps == 0``).

    :param demonstrator: an object with ``reset(env)`` and ``act(env, observation)`` (e.g. one of the mission
        env's planners, docs/ARCHITECTURE.md), called with the unwrapped env
    :param n_episodes: number of demonstration episodes
    :param verbose: verbosity level
    """

    def __init__(self, demonstrator: Demonstrator, n_episodes: int, verbose: int = 0) -> None:
        super().__init__(verbose)
        if isinstance(n_episodes, bool) or not isinstance(n_episodes, int) or n_episodes < 1:
            raise ValueError(f"n_episodes must be a positive integer, got {n_episodes!r}")
        self.demonstrator = demonstrator
        self.n_episodes = n_episodes
        self.transitions = 0

    def _on_training_start(self) -> None:
        if self.model.num_timesteps > 0:
            return
        vec_env = self.training_env
        if vec_env.num_envs != 1 or not hasattr(vec_env, "envs"):
            raise ValueError(
                f"DemonstrationCallback needs a DummyVecEnv with one env, got {type(vec_env).__name__} "
                f"with {vec_env.num_envs} envs"
            )
        env = vec_env.envs[0]
        buffer = self.model.replay_buffer
        for _ in range(self.n_episodes):
            obs, _ = env.reset()
            self.demonstrator.reset(env.unwrapped)
            done = False
            while not done:
                action = np.asarray(self.demonstrator.act(env.unwrapped, obs), dtype=np.float32)
                next_obs, reward, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                info = {**info, "TimeLimit.truncated": truncated and not terminated}
                buffer_action = self.model.policy.scale_action(action) if hasattr(self.model, "policy") else action
                buffer.add(obs[None], next_obs[None], buffer_action[None], np.array([reward]), np.array([done]), [info])
                obs = next_obs
                self.transitions += 1
        self.model._last_obs = vec_env.reset()  # the algorithm's next step starts from a fresh episode
        if self.verbose:
            print(f"Replay buffer seeded with {self.n_episodes} demonstration episodes ({self.transitions} transitions)")

    def _on_step(self) -> bool:
        return True
