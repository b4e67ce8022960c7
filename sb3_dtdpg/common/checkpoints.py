"""
Checkpoints from which a training resumes exactly as it would have gone on uninterrupted, for the Python API:
:class:`ExactCheckpointCallback` saves them, :func:`load_checkpoint` loads one.

SB3's ``CheckpointCallback`` saves the model (and its replay buffer) in the middle of an iteration of the training
loop, and a model loaded from it starts on a freshly reset env with the random generators of the load: it trains on,
but not as it would have. These checkpoints also keep the training env as it was and the random generators
(:mod:`sb3_dtdpg.common.training_state`), and are taken between two iterations of the loop at the end of an episode
(SB3's ``learn`` resets the exploration noise when it starts, as the loop does at an episode's end), so that::

    model = load_checkpoint("checkpoints", env=make_env())  # the latest checkpoint in the folder
    model.learn(total_timesteps - model.num_timesteps, reset_num_timesteps=False)

gives the weights of the uninterrupted ``learn(total_timesteps)``, bit for bit on the same kind of CPU.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_dtdpg.common import training_state
from sb3_dtdpg.common.files import atomic_write

__all__ = ["ExactCheckpointCallback", "checkpoint_files", "checkpoint_steps", "load_checkpoint"]

#: The parts of a checkpoint: SB3's ``CheckpointCallback`` types (``<prefix>_<type><steps>_steps.<extension>``).
_REPLAY_BUFFER, _TRAINING_STATE = "replay_buffer_", "training_state_"
_MODEL_FILE = re.compile(r"(?P<prefix>.+)_(?P<steps>\d+)_steps\.zip")


class ExactCheckpointCallback(CheckpointCallback):
    """
    SB3's ``CheckpointCallback`` for an exact resume: after every ``save_freq`` calls it saves the model, its replay
    buffer and the training state (the env as it is and the random generators) at the end of the next episode, at the
    start of the rollout that follows it (after the gradient steps of the episode's last step), where a new ``learn``
    picks the training up exactly; a checkpoint due when ``learn`` ends at an episode's end is saved then. Each file
    is written whole or not at all, the model's last, so a kill while saving leaves the checkpoints before it usable.
    Resume with :func:`load_checkpoint`.

    The model must be off-policy (the replay buffer is saved) and train on a ``DummyVecEnv`` of one env (SB3's
    wrapping of a single env), whose env the training state keeps; SB3's own ``CheckpointCallback`` suits the others.

    :param save_freq: Save a checkpoint every ``save_freq`` calls of the callback (env steps of the vector env)
    :param save_path: Folder of the checkpoints
    :param name_prefix: Common prefix of the files
    :param keep_last: Keep only the latest ``keep_last`` checkpoints of this prefix in the folder, each removed once
        a newer one is saved whole (None: keep them all, as SB3's callback does); each holds a replay buffer
    :param verbose: 2: say where each checkpoint goes
    """

    def __init__(
        self, save_freq: int, save_path: str, name_prefix: str = "rl_model", keep_last: int | None = None, verbose: int = 0
    ):
        if isinstance(save_freq, bool) or not isinstance(save_freq, int) or save_freq < 1:
            raise ValueError(f"save_freq must be a positive number of calls, got {save_freq!r}")
        if keep_last is not None and (isinstance(keep_last, bool) or not isinstance(keep_last, int) or keep_last < 1):
            raise ValueError(f"keep_last must be a positive number of checkpoints or None, got {keep_last!r}")
        super().__init__(save_freq, save_path, name_prefix, save_replay_buffer=True, verbose=verbose)
        self.keep_last = keep_last
        self._due = False
        self._episode_ended = False

    def _init_callback(self) -> None:
        env = self.model.get_env()
        if not isinstance(env, DummyVecEnv) or env.num_envs != 1:
            kind = type(env).__name__ + (f" of {env.num_envs} envs" if isinstance(env, DummyVecEnv) else "")
            raise TypeError(
                f"ExactCheckpointCallback keeps the env of a DummyVecEnv of one env; the model trains on a {kind} "
                "(SB3's CheckpointCallback saves its model, to resume on a fresh env)"
            )
        if getattr(self.model, "replay_buffer", None) is None:
            raise TypeError(
                f"ExactCheckpointCallback saves an off-policy model's replay buffer; {type(self.model).__name__} has none "
                "(SB3's CheckpointCallback saves its model, to resume on a fresh env)"
            )
        super()._init_callback()

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            self._due = True
        self._episode_ended = bool(self.locals["dones"][0])
        return True

    def _on_rollout_start(self) -> None:
        if self._due and self._episode_ended:
            self._save()

    def _on_training_end(self) -> None:
        if self._due and self._episode_ended:
            self._save()

    def _save(self) -> None:
        self._due = False
        atomic_write(
            self._checkpoint_path(_TRAINING_STATE, extension="pkl"), lambda path: training_state.save(self.model, path)
        )
        atomic_write(self._checkpoint_path(_REPLAY_BUFFER, extension="pkl"), self.model.save_replay_buffer)  # type: ignore[attr-defined]
        model_path = atomic_write(self._checkpoint_path(extension="zip"), self.model.save)
        if self.verbose >= 2:
            print(f"Saving an exact checkpoint to {model_path}")
        if self.keep_last is not None:
            self._remove_older()

    def _remove_older(self) -> None:
        """Remove this prefix's checkpoints but the latest ``keep_last``, each model file first (it is then not loadable)."""
        saved = [model_file for model_file in _model_files(Path(self.save_path)) if _prefix(model_file) == self.name_prefix]
        saved.sort(key=checkpoint_steps)
        for model_file in saved[: -self.keep_last]:
            for file in _parts(model_file):
                file.unlink(missing_ok=True)


def checkpoint_files(path: str | Path) -> tuple[Path, Path, Path]:
    """
    :param path: a model file of :class:`ExactCheckpointCallback` (``<prefix>_<steps>_steps.zip``), or its folder: then
        the latest checkpoint there (the most steps) whose three files are there
    :return: the model file, its replay buffer and its training state
    :raises FileNotFoundError: no such checkpoint
    """
    path = Path(path)
    if path.is_dir():
        candidates = [_parts(model_file) for model_file in _model_files(path)]
        complete = [files for files in candidates if all(file.is_file() for file in files)]
        if not complete:
            raise FileNotFoundError(f"{path} holds no checkpoint of ExactCheckpointCallback (<prefix>_<steps>_steps.zip)")
        return max(complete, key=lambda files: (checkpoint_steps(files[0]), files[0].name))
    if _MODEL_FILE.fullmatch(path.name) is None:
        raise FileNotFoundError(f"{path} is not a checkpoint of ExactCheckpointCallback (<prefix>_<steps>_steps.zip)")
    files = _parts(path)
    for file in files:
        if not file.is_file():
            raise FileNotFoundError(f"the checkpoint {path} has no {file.name}")
    return files


def _model_files(folder: Path) -> list[Path]:
    """:return: the model files of :class:`ExactCheckpointCallback`'s checkpoints in ``folder`` (whole or not)"""
    return [model_file for model_file in folder.glob("*_steps.zip") if _MODEL_FILE.fullmatch(model_file.name)]


def _prefix(model_file: Path) -> str:
    match = _MODEL_FILE.fullmatch(model_file.name)
    assert match is not None
    return match["prefix"]


def checkpoint_steps(model_file: str | Path) -> int:
    """:return: the env steps trained before a checkpoint of :class:`ExactCheckpointCallback`, given its model file"""
    match = _MODEL_FILE.fullmatch(Path(model_file).name)
    assert match is not None
    return int(match["steps"])


def _parts(model_file: Path) -> tuple[Path, Path, Path]:
    """:return: a checkpoint's model file, replay buffer and training state, given its model file"""
    match = _MODEL_FILE.fullmatch(model_file.name)
    assert match is not None
    prefix, steps = match["prefix"], match["steps"]
    folder = model_file.parent
    return (
        model_file,
        folder / f"{prefix}_{_REPLAY_BUFFER}{steps}_steps.pkl",
        folder / f"{prefix}_{_TRAINING_STATE}{steps}_steps.pkl",
    )


def load_checkpoint(path: str | Path, env: GymEnv, algorithm: type[BaseAlgorithm] | None = None, **kwargs: Any) -> Any:
    """
    Load a checkpoint of :class:`ExactCheckpointCallback` to train on as the uninterrupted training would: the
    model, its replay buffer, the training env as it was and the random generators. Then call
    ``model.learn(total_timesteps - model.num_timesteps, reset_num_timesteps=False)`` with the uninterrupted run's
    ``total_timesteps``, so that the schedules (learning rate, noise) go on as they were.

    :param path: The checkpoint's model file, or its folder (the latest checkpoint there)
    :param env: An env built as the training env was (the same wrappers; the saved env takes their place, with its
        random generator and the episode in progress)
    :param algorithm: The model's class (default: :class:`~sb3_dtdpg.DTDPG`)
    :param kwargs: Passed to the class's ``load`` (e.g. ``device``, ``custom_objects``)
    :return: The model, ready to ``learn``
    """
    if algorithm is None:
        from sb3_dtdpg.dtdpg import DTDPG

        algorithm = DTDPG
    model_file, replay_buffer_file, state_file = checkpoint_files(path)
    state = training_state.load(state_file)
    model = algorithm.load(model_file, env=None, **kwargs)  # with the env, loading would seed it
    training_state.restore(model, env, state)
    model.load_replay_buffer(replay_buffer_file)  # type: ignore[attr-defined]
    return model
