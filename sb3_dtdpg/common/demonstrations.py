"""Replay seeded with a demonstrator's episodes (an extension of DT-DPG, in the spirit of DDPGfD)."""

from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback

from sb3_dtdpg.common.checks import _is_int
from sb3_dtdpg.evaluation import Planner

#: What :class:`DemonstrationCallback` needs of a demonstrator: the :class:`sb3_dtdpg.evaluation.Planner` protocol.
Demonstrator = Planner

#: The model attribute that records that the model's replay buffer was seeded (saved with the model by ``save``).
SEEDED_ATTRIBUTE = "_demonstrations_seeded"


class DemonstrationCallback(BaseCallback):
    """
    Seed the replay buffer with ``n_episodes`` episodes of a demonstrator before the first step of training,
    the replay half of DDPGfD (Vecerik et al., "Leveraging Demonstrations for Deep Reinforcement Learning on
    Robotics Problems with Sparse Rewards", 2017; no behaviour-cloning loss). It is not part of the paper's
    DT-DPG: an extension, off by default, reported in rows of its own (docs/BENCHMARKS.md).

    The episodes are played in the training env (its first sub-env, with the reward phase the curriculum set,
    so put this callback after the curriculum's; ``DTDPG.learn`` adds user callbacks after its own) and stored
    with their ``info``, so a replay buffer that keeps reward components can relabel them at a transfer. They do
    not count as timesteps or curriculum episodes. The demonstrator's actions are clipped to the action space,
    as the model's own actions are: the buffer holds the action the env executed, scaled to [-1, 1] as SB3
    stores it for a ``Box`` space. Afterwards the training env is reset (under ``VecNormalize`` the model's
    original observation follows it).

    Seeding happens once per model, in its first ``learn()`` with this callback: the model records it (an
    attribute that ``save`` keeps), and later ``learn()`` calls, with ``reset_num_timesteps`` or without, and
    those of the model loaded from its file, do not seed again. A ``learn()`` that goes on from earlier
    training (``reset_num_timesteps=False`` on a model that has trained steps) does not seed either.

    :param demonstrator: an object with ``reset(env)`` and ``act(env, observation)`` (e.g. one of the mission
        env's planners, docs/ARCHITECTURE.md), called with the unwrapped env
    :param n_episodes: number of demonstration episodes
    :param verbose: verbosity level
    :raises ValueError: for a demonstrator without those methods or an ``n_episodes`` that is not an integer >= 1
    """

    def __init__(self, demonstrator: Demonstrator, n_episodes: int, verbose: int = 0) -> None:
        super().__init__(verbose)
        missing = [name for name in ("reset", "act") if not callable(getattr(demonstrator, name, None))]
        if missing:
            raise ValueError(
                f"demonstrator must have the methods reset(env) and act(env, observation) (e.g. a planner), "
                f"got {demonstrator!r}, which lacks {' and '.join(missing)}"
            )
        if not _is_int(n_episodes) or n_episodes < 1:
            raise ValueError(f"n_episodes must be a positive integer, got {n_episodes!r}")
        self.demonstrator = demonstrator
        self.n_episodes = int(n_episodes)
        self.transitions = 0

    def _on_training_start(self) -> None:
        if self.model.num_timesteps > 0 or getattr(self.model, SEEDED_ATTRIBUTE, False):
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
                action, buffer_action = self._actions(self.demonstrator.act(env.unwrapped, obs))
                next_obs, reward, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                info = {**info, "TimeLimit.truncated": truncated and not terminated}
                buffer.add(obs[None], next_obs[None], buffer_action[None], np.array([reward]), np.array([done]), [info])
                obs = next_obs
                self.transitions += 1
        setattr(self.model, SEEDED_ATTRIBUTE, True)
        # The algorithm's next step starts from a fresh episode, from the observations SB3's own reset sets
        self.model._last_obs = vec_env.reset()
        normalization = self.model.get_vec_normalize_env()
        if normalization is not None:
            self.model._last_original_obs = normalization.get_original_obs()
        if self.verbose:
            print(f"Replay buffer seeded with {self.n_episodes} demonstration episodes ({self.transitions} transitions)")

    def _actions(self, demonstrated: Any) -> tuple[np.ndarray, np.ndarray]:
        """
        The action to execute and the action to store for a demonstrator's action: for a ``Box`` space, the action
        clipped to the space and its scaled form in [-1, 1] (what SB3's ``_sample_action`` stores), else the action.
        """
        action_space = self.model.action_space
        if not isinstance(action_space, spaces.Box):
            action = np.asarray(demonstrated)
            return action, action
        action = np.asarray(demonstrated, dtype=action_space.dtype)
        if action.shape != action_space.shape:  # np.clip would broadcast it to the space's shape
            raise ValueError(f"the demonstrator's action has shape {action.shape}, the action space {action_space.shape}")
        action = np.clip(action, action_space.low, action_space.high)
        return action, self.model.policy.scale_action(action)

    def _on_step(self) -> bool:
        return True
