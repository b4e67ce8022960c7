"""The curriculum transfer of DT-DPG between reward phases (any env with ``set_reward_phase``)."""

import os
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from sb3_dtdpg.common.checks import check_folder, check_switches
from sb3_dtdpg.common.files import atomic_write, remove_temp_files, safe_name
from sb3_dtdpg.common.noise import advance_noise, decaying_noise, noise_sigma, rearm_noise
from sb3_dtdpg.common.phases import Phase, check_env_phases, parse_phases


class CurriculumTransferCallback(BaseCallback):
    """
    Curriculum transfer of DT-DPG (Algorithm 1 of Zhong et al., "Path Design and Resource Management for NOMA
    enhanced Indoor Intelligent Robots"): train through several phases in order, each with its own env reward
    phase, budget and exploration-noise schedule, carrying the networks from one phase to the next.

    A phase ends when its budget (episodes or env steps) is spent, or early when its success rate
    (``info["is_success"]`` at episode end) over its last ``success_window`` episodes reaches
    ``success_threshold``. At the transfer:

    1. the finished phase's model (theta_X of Algorithm 1) is saved atomically to
       ``<save_path>/phase_<k>_<name>.zip`` (a temporary file in the same folder, then ``os.replace``);
    2. the networks carry over unchanged, or, with ``reinitialize_at_transfer=True`` (ablation), are re-created
       from scratch with fresh optimizers by the model's ``reinitialize()`` (:meth:`sb3_dtdpg.DTDPG.reinitialize`);
    3. the env switches reward phase (``env_method("set_reward_phase", name)``), from the next step on;
    4. the action noise re-arms with the new phase's schedule (:func:`sb3_dtdpg.common.noise.rearm_noise`);
       the episode that just ended does not count in the new schedule;
    5. the replay buffer is kept, cleared, or relabelled for the new phase (``Phase.replay_handling``).
       Relabelling waits until SB3 has stored the transfer step's transitions and happens before the next
       gradient step (at the end of the rollout, or at the next step if the rollout goes on). Clearing happens
       at once, so the transfer step's transitions (one per env) are the first of the cleared buffer: the
       gradient step after the rollout needs data; a buffer that stores reward components relabels them.

    Episodes are counted from ``dones`` (terminations and truncations) over all envs of a vectorized env, so
    with several envs a phase may end with a few more episodes than its budget. When the last phase has a
    budget, training stops once it is spent; otherwise the last phase lasts until ``learn()`` ends, and its
    model is saved (``phase_<k>_<name>.zip``) at the end of every ``learn()`` call.

    The curriculum state lives in ``model.curriculum_state`` (a plain dict: phase index, episodes and steps done
    in the phase, recent successes, the history of phases), so ``model.save`` saves it with the action noise and
    its schedule: ``Model.load(path, env)`` then ``learn(..., callback=CurriculumTransferCallback(same phases))``
    resumes in the same phase (a :class:`sb3_dtdpg.DTDPG` runs its own: ``DTDPG.load(path, env).learn(...)``), and
    repeated ``learn()`` calls continue the curriculum. A model saved at a transfer step, before the replay is
    relabelled (e.g. by SB3's ``CheckpointCallback``), relabels the replay buffer loaded with it when it resumes. Loading a
    ``phase_<k>_<name>.zip`` checkpoint and training goes on with phase k + 1.

    Evaluation follows the curriculum: the eval envs of ``eval_callbacks`` (SB3 ``EvalCallback`` objects) switch
    reward phase with the training env, so each evaluation measures the reward being trained, and at each
    transfer their best mean reward is reset, so ``best_model.zip`` is the best model on the last phase's reward.
    ``DTDPG.learn`` passes the ``EvalCallback`` objects among its callbacks, also those inside other callbacks
    (``CallbackList``, ``EveryNTimesteps``, an ``EvalCallback``'s ``callback_on_new_best``).

    Logged: ``curriculum/phase`` (index), ``curriculum/noise_sigma``, ``curriculum/episodes_in_phase`` at every
    step (written at SB3's log dumps); a line per transfer with ``verbose >= 1``.

    Works with any SB3 off-policy algorithm (DDPG, TD3, ...). When a phase has a noise ``sigma`` and the model has
    no action noise, a :class:`sb3_dtdpg.common.noise.LinearDecayOUNoise` is created for it.

    :param phases: The phases in training order (:class:`sb3_dtdpg.common.phases.Phase` or dicts of their fields).
    :param save_path: Folder for the per-phase checkpoints (None: no checkpoints); an existing file is refused, and
        so is a new curriculum (a model without ``curriculum_state``) where the folder holds its phase files already
        (another run's: each run saves into its own folder).
    :param reinitialize_at_transfer: Ablation: re-initialise the networks at each transfer instead of carrying them
        over (needs a model with ``reinitialize()``, e.g. :class:`sb3_dtdpg.DTDPG`).
    :param eval_callbacks: ``EvalCallback`` objects whose eval envs follow the curriculum's reward phase.
    :param verbose: Verbosity level: 0 no output, 1 a line per transfer.
    """

    def __init__(
        self,
        phases: Sequence[Phase | Mapping[str, Any]],
        save_path: str | os.PathLike[str] | None = None,
        reinitialize_at_transfer: bool = False,
        verbose: int = 0,
        eval_callbacks: Sequence[EvalCallback] = (),
    ):
        super().__init__(verbose=verbose)
        check_folder("CurriculumTransferCallback", "save_path", save_path)
        check_switches("CurriculumTransferCallback", {"reinitialize_at_transfer": reinitialize_at_transfer})
        self.phases = parse_phases(phases)
        self.eval_callbacks = list(eval_callbacks)
        self._ended_training = False  # set when the last phase's budget ends training
        self.save_path = None if save_path is None else os.fspath(save_path)
        self.reinitialize_at_transfer = reinitialize_at_transfer
        self._pending_replay: Phase | None = None
        self._stop = False

    # ------------------------------------------------------------------ state
    @property
    def state(self) -> dict[str, Any]:
        """The curriculum state, ``model.curriculum_state``."""
        return self.model.curriculum_state  # type: ignore[attr-defined]

    @property
    def phase_index(self) -> int:
        """Index of the current phase."""
        return self.state["phase_index"]

    @property
    def phase(self) -> Phase:
        """The current phase."""
        return self.phases[self.phase_index]

    def checkpoint_path(self, index: int) -> str | None:
        """
        :param index: Phase index
        :return: Where the model at the end of that phase is saved (None without ``save_path``).
        """
        if self.save_path is None:
            return None
        return os.path.join(self.save_path, f"phase_{index}_{safe_name(self.phases[index].name)}.zip")

    def _new_history_entry(self, index: int) -> dict[str, Any]:
        return {
            "phase": self.phases[index].name,
            "reward_phase": self.phases[index].reward_phase,
            "start_timestep": int(self.num_timesteps),
            "end_timestep": None,
            "episodes": None,
            "timesteps": None,
            "reason": None,
        }

    # ------------------------------------------------------------------ SB3 hooks
    def _on_training_start(self) -> None:
        self._check_setup()
        if self.save_path is not None:
            # left by a process killed while saving this curriculum's checkpoints (the folder may hold other files)
            names = [os.path.basename(self.checkpoint_path(i)) for i in range(len(self.phases))]  # type: ignore[arg-type]
            remove_temp_files(self.save_path, names)
        self._pending_replay = None
        self._stop = False
        state = getattr(self.model, "curriculum_state", None)
        if not state:
            self._check_no_earlier_run()
            self.model.curriculum_state = {  # type: ignore[attr-defined]
                "phase_names": [phase.name for phase in self.phases],
                "phase_index": 0,
                "episodes_in_phase": 0,
                "timesteps_in_phase": 0,
                "recent_successes": [],
                "finished": False,
                "history": [self._new_history_entry(0)],
            }
            self._set_env_phase(self.phases[0])
            self._arm_noise(self.phases[0])
        else:
            saved = list(state.get("phase_names", []))
            if saved != [phase.name for phase in self.phases]:
                raise ValueError(
                    f"model.curriculum_state was saved with the phases {saved}, but the callback has "
                    f"{[phase.name for phase in self.phases]}: resume with the same phases"
                )
            if not state["finished"]:
                # Resume mid-phase: the noise (saved with the model) keeps its schedule position
                self._set_env_phase(self.phase)
                if self.model.action_noise is None:  # e.g. load(..., action_noise=None): the phase's noise of now
                    self._arm_noise(self.phase)
                    advance_noise(self.model.action_noise, state["episodes_in_phase"])
                if state.get("pending_replay"):  # saved at the transfer step, before the relabelling
                    self._pending_replay = self.phase
                    self._apply_pending_replay()
            elif self.phase_index + 1 < len(self.phases):
                # Trained from a phase checkpoint: the transfer it marks has not been applied yet
                self._enter_phase(self.phase_index + 1, defer_replay=False)
            else:
                warnings.warn(f"The curriculum is over (its last phase {self.phase.name!r} is finished): training stops")
                self._stop = True
        self._record()

    def _on_step(self) -> bool:
        self._apply_pending_replay()
        if self._stop:
            return False
        state = self.state
        phase = self.phase
        state["timesteps_in_phase"] += self.training_env.num_envs
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if not done:
                continue
            state["episodes_in_phase"] += 1
            if "is_success" in info:
                state["recent_successes"] = [*state["recent_successes"], bool(info["is_success"])][-phase.success_window :]
            elif phase.success_threshold is not None:
                raise ValueError(
                    f"phase {phase.name!r} has success_threshold={phase.success_threshold}, which needs "
                    "info['is_success'] at the end of every episode; the env gave none"
                )
        reason = self._end_reason(phase, state)
        continue_training = True
        if reason is not None:
            continue_training = self._transfer(reason)
        self._record()
        self._ended_training = not continue_training
        return continue_training

    def _on_rollout_end(self) -> None:
        self._apply_pending_replay()

    def _on_training_end(self) -> None:
        self._apply_pending_replay()
        if self.phase_index == len(self.phases) - 1 and not self.state["finished"]:
            self._save_checkpoint(self.phase_index)
        if self._ended_training and self.logger.name_to_value:
            # The last phase's budget ended training inside SB3's rollout, which then dumps no logs: the figures of
            # the episodes that ended at that step are written here
            self.logger.dump(self.num_timesteps)

    # ------------------------------------------------------------------ transfer
    def _end_reason(self, phase: Phase, state: dict[str, Any]) -> str | None:
        if phase.n_episodes is not None and state["episodes_in_phase"] >= phase.n_episodes:
            return "episode budget"
        if phase.n_timesteps is not None and state["timesteps_in_phase"] >= phase.n_timesteps:
            return "timestep budget"
        successes = state["recent_successes"]
        if (
            phase.success_threshold is not None
            and len(successes) >= phase.success_window
            and np.mean(successes) >= phase.success_threshold
        ):
            return "success rate"
        return None

    def _transfer(self, reason: str) -> bool:
        state, index = self.state, self.phase_index
        state["finished"] = True
        state["history"][-1].update(
            end_timestep=int(self.num_timesteps),
            episodes=state["episodes_in_phase"],
            timesteps=state["timesteps_in_phase"],
            reason=reason,
        )
        path = self._save_checkpoint(index)
        if self.verbose >= 1:
            print(
                f"Curriculum: phase {index} {self.phase.name!r} finished ({reason}) after {state['episodes_in_phase']} "
                f"episodes, {state['timesteps_in_phase']} steps, at step {self.num_timesteps}"
                + (f"; saved to {path}" if path else "")
            )
        if index + 1 == len(self.phases):
            return False
        self._enter_phase(index + 1, defer_replay=True)
        return True

    def _enter_phase(self, index: int, defer_replay: bool) -> None:
        phase = self.phases[index]
        self.state.update(phase_index=index, episodes_in_phase=0, timesteps_in_phase=0, recent_successes=[], finished=False)
        self.state["history"].append(self._new_history_entry(index))
        if self.reinitialize_at_transfer:
            self.model.reinitialize()  # type: ignore[attr-defined]
        self._set_env_phase(phase)
        for callback in self.eval_callbacks:
            callback.best_mean_reward = -np.inf  # the earlier phases' best was measured on another reward
        self._arm_noise(phase)
        if phase.replay_handling == "clear":
            # Cleared now, not after SB3 stores this step's transitions: the gradient step that follows the
            # rollout needs a non-empty buffer. Those transitions (one per env) are relabelled below if possible.
            self.model.replay_buffer.reset()  # type: ignore[attr-defined]
        if phase.replay_handling != "keep":
            self._pending_replay = phase
            # in the saved state too: a model saved before it is applied (a CheckpointCallback at the transfer step)
            # applies it when it resumes
            self.state["pending_replay"] = True
            if not defer_replay:
                self._apply_pending_replay()
        if self.verbose >= 1:
            print(
                f"Curriculum: entering phase {index} {phase.name!r} (reward phase {phase.reward_phase!r}, "
                f"noise sigma {phase.sigma}, replay buffer: {phase.replay_handling}"
                + (", networks re-initialised)" if self.reinitialize_at_transfer else ", networks carried over)")
            )

    def _apply_pending_replay(self) -> None:
        phase, self._pending_replay = self._pending_replay, None
        if phase is None:
            return
        self.state.pop("pending_replay", None)
        buffer = self.model.replay_buffer  # type: ignore[attr-defined]
        if hasattr(buffer, "relabel") and phase.reward_phase is not None and self.training_env.has_attr("reward_weights"):
            weights = self.training_env.env_method("reward_weights", phase.reward_phase, indices=[0])[0]
            buffer.relabel(weights)

    def _set_env_phase(self, phase: Phase) -> None:
        if phase.reward_phase is not None:
            self.training_env.env_method("set_reward_phase", phase.reward_phase)
            for callback in self.eval_callbacks:
                callback.eval_env.env_method("set_reward_phase", phase.reward_phase)

    def _arm_noise(self, phase: Phase) -> None:
        schedule = phase.noise_schedule()
        if schedule is None:
            return
        sigma, final_sigma, decay_episodes = schedule
        if self.model.action_noise is None:
            self.model.action_noise = decaying_noise(
                self.model.action_space.shape, sigma, final_sigma, decay_episodes, n_envs=self.training_env.num_envs
            )
        else:
            rearm_noise(self.model.action_noise, sigma, final_sigma, decay_episodes)

    def _save_checkpoint(self, index: int) -> str | None:
        path = self.checkpoint_path(index)
        if path is None:
            return None
        atomic_write(path, self.model.save)  # a reader never sees a partial file
        return path

    def _record(self) -> None:
        self.logger.record("curriculum/phase", self.phase_index)
        self.logger.record("curriculum/episodes_in_phase", self.state["episodes_in_phase"])
        sigma = noise_sigma(self.model.action_noise) if self.model.action_noise is not None else float("nan")
        if not np.isnan(sigma):  # SB3's own noises keep their scale private: nothing to log
            self.logger.record("curriculum/noise_sigma", sigma)

    # ------------------------------------------------------------------ checks
    def _check_no_earlier_run(self) -> None:
        """
        A new curriculum (no ``curriculum_state`` yet) would overwrite the phase files another run left in
        ``save_path``: refused before the first step. A model that trained before, or one loaded from a phase file
        or a checkpoint, carries its curriculum state and continues writing its own phase files there.
        """
        if self.save_path is None:
            return
        paths = [self.checkpoint_path(i) for i in range(len(self.phases))]
        found = [os.path.basename(path) for path in paths if path is not None and os.path.lexists(path)]
        if found:
            raise ValueError(
                f"save_path (DTDPG: curriculum_save_path) {self.save_path!r} already holds {', '.join(found)} of an "
                "earlier curriculum run, which this new run would overwrite: give each run its own folder, or move "
                "those files elsewhere"
            )

    def _check_setup(self) -> None:
        env = self.training_env
        if self.reinitialize_at_transfer and not callable(getattr(self.model, "reinitialize", None)):
            raise ValueError(
                "reinitialize_at_transfer=True needs a model with reinitialize() (e.g. DTDPG), "
                f"got {type(self.model).__name__}"
            )
        check_env_phases(self.phases, env)
        reward_phases = sorted({phase.reward_phase for phase in self.phases if phase.reward_phase is not None})
        if reward_phases:
            for callback in self.eval_callbacks:
                if not callback.eval_env.has_attr("set_reward_phase"):
                    raise ValueError(
                        f"the phases use the env reward phases {reward_phases}, but the eval env of "
                        f"{type(callback).__name__} has no set_reward_phase() to follow them"
                    )
        for phase in self.phases[1:]:
            if phase.replay_handling != "relabel":
                continue
            if phase.reward_phase is None:
                raise ValueError(f"phase {phase.name!r}: replay_handling='relabel' needs a reward_phase, got None")
            if not hasattr(self.model.replay_buffer, "relabel"):  # type: ignore[attr-defined]
                raise ValueError(
                    f"phase {phase.name!r} has replay_handling='relabel', which needs a replay buffer that stores reward "
                    f"components (replay_buffer_class=RewardComponentsReplayBuffer), got "
                    f"{type(self.model.replay_buffer).__name__}"  # type: ignore[attr-defined]
                )
            if not env.has_attr("reward_weights"):
                raise ValueError(f"phase {phase.name!r} has replay_handling='relabel', which needs env.reward_weights()")
