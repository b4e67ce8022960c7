"""One training run (train, save, evaluate, write the result), and many of them in parallel processes.

A run is described by a :class:`RunSpec`; :func:`run_one` trains it with TensorBoard logging under
``<out>/tb/<run_id>``, saves the model and writes ``<out>/runs/<run_id>/result.json`` last, atomically:
a run whose result file exists is finished, which is what makes the experiments resumable and keeps
every finished run when a job is interrupted.

A result file records the run's identity (:func:`run_identity`): the spec, the scenario's full content, the
hyperparameters the algorithm is built with and :data:`RUN_FORMAT_VERSION`. A stored result is used only
when its identity is the one asked for; otherwise the run is refused loudly (:class:`RunMismatchError`)
instead of reporting another experiment's result under this one's name. :func:`output_lock` keeps two jobs
out of one folder, and the worker processes of :func:`run_many` end when their parent process ends.

The pieces live in modules of one job each: :mod:`.budgets` (budgets and their check), :mod:`.specs` (run
specs and identity), :mod:`.storage` (result, progress and checkpoint files, locks), :mod:`.run_callbacks`
(the episode counter and the callbacks that read it) and :mod:`.pool` (worker processes and progress bars);
their public names are importable from here too.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import time
import warnings
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_dtdpg import env_settings
from sb3_dtdpg.common import training_state
from sb3_dtdpg.common.files import atomic_write, json_default, remove_temp_files, write_json
from sb3_dtdpg.experiments.budgets import BUDGETS, CHECKPOINT_EVERY, PUBLIC_BUDGETS, Budget, check_budget, get_budget
from sb3_dtdpg.experiments.pool import RunReport, RunsFailedError, run_in_pool, worker_pool
from sb3_dtdpg.experiments.provenance import made_with, warn_other_versions
from sb3_dtdpg.experiments.run_callbacks import (
    EpisodeCounter,
    EpisodeReturnLogger,
    PeriodicCheckpoint,
    RunProgress,
    check_finite,
)
from sb3_dtdpg.experiments.specs import (
    RUN_FORMAT_VERSION,
    RunDivergedError,
    RunMismatchError,
    RunSpec,
    build_model,
    run_identity,
)
from sb3_dtdpg.experiments.storage import (
    TRAINED_RECORD,
    DamagedRecordError,
    OutputBusyError,
    clear_checkpoints,
    failure_path,
    load_result,
    load_results,
    output_lock,
    progress_path,
    read_checkpoint,
    read_progress,
    read_trained,
    result_path,
    run_folder,
    run_logger,
    save_checkpoint,
    tensorboard_claim,
    tensorboard_folder,
)

__all__ = [
    "BUDGETS",
    "CHECKPOINT_EVERY",
    "PUBLIC_BUDGETS",
    "RUN_FORMAT_VERSION",
    "Budget",
    "DamagedRecordError",
    "EpisodeCounter",
    "EpisodeReturnLogger",
    "OutputBusyError",
    "PeriodicCheckpoint",
    "RunDivergedError",
    "RunMismatchError",
    "RunProgress",
    "RunReport",
    "RunSpec",
    "RunsFailedError",
    "check_budget",
    "get_budget",
    "load_result",
    "load_results",
    "output_lock",
    "prepare_run",
    "read_checkpoint",
    "read_progress",
    "result_path",
    "run_identity",
    "run_many",
    "run_one",
    "save_checkpoint",
    "worker_pool",
]


def prepare_run(spec: RunSpec) -> dict[str, Any]:
    """
    The checks of a run before it starts, in one place: its budget can train (:func:`check_budget`), and its
    identity (:func:`run_identity`, which checks the hyperparameter set and loads the scenario).

    :param spec: the run
    :return: its identity
    :raises ValueError: the budget cannot train, or a setting is unknown
    """
    check_budget(spec)
    return run_identity(spec)


def _evaluation_record(result: Any, n_trajectories: int, reward_phase: str) -> dict[str, Any]:
    return {
        "reward_phase": reward_phase,
        "summary": result.summary(),
        "episodes": result.episodes,
        "trajectories": [np.round(t, 3).tolist() for t in result.trajectories[:n_trajectories]],
    }


#: The settings of a checkpoint's model that must be the run's (:func:`run_identity`'s ``hyperparameters``, where it
#: records them) to resume from it: the ones that tell the algorithms apart (the policy class; DDPG and TD3 share
#: one) and that training leaves as they are (not the action noise, which DT-DPG's curriculum re-arms).
_CHECKPOINT_SETTINGS: tuple[str, ...] = (
    "policy_class",
    "buffer_size",
    "batch_size",
    "gamma",
    "tau",
    "policy_delay",
    "target_policy_noise",
    "target_noise_clip",
    "policy.net_arch",
)


def _check_checkpoint_model(model: Any, checkpoint: dict[str, Any], identity: dict[str, Any], pointer: Path) -> None:
    """
    A checkpoint's model must be the one its record was written with: of the run's algorithm and settings
    (:data:`_CHECKPOINT_SETTINGS`) and at the step count the record names (``timesteps``). A model replaced from
    outside (another algorithm's, another run's) would otherwise be trained on and reported as this run's.

    :param model: the model loaded from the checkpoint
    :param checkpoint: the checkpoint record (:func:`read_checkpoint`)
    :param identity: the run's :func:`run_identity`
    :param pointer: the record's file, for the message
    :raises DamagedRecordError: naming the checkpoint, the differences and the record to delete
    """
    from sb3_dtdpg.presets import model_settings

    stored = json.loads(json.dumps(model_settings(model), default=json_default))
    expected = identity.get("hyperparameters", {})
    differences = [
        f"{name}: {stored[name]!r} in the model, {expected[name]!r} in the run"
        for name in _CHECKPOINT_SETTINGS
        if name in stored and name in expected and stored[name] != expected[name]
    ]
    if int(model.num_timesteps) != checkpoint["timesteps"]:
        differences.append(f"num_timesteps: {model.num_timesteps} in the model, {checkpoint['timesteps']} in {pointer}")
    if differences:
        raise DamagedRecordError(
            f"the checkpoint in {checkpoint['path']} is not this run's ({'; '.join(differences)[:400]}): its "
            f"model.zip was replaced from outside; delete {pointer} to start the run afresh"
        )


def _build_model(
    spec: RunSpec, run_dir: Path, checkpoint: dict[str, Any] | None, identity: dict[str, Any], verbose: int
) -> tuple[Any, Any, int]:
    """
    :return: the training env, the model (new, or loaded from the checkpoint) and the episodes already trained;
        a model resumed from a checkpoint with a training state (:mod:`.training_state`) trains on with the env
        and random generators as they were
    :raises DamagedRecordError: the checkpoint cannot be loaded, has no replay buffer, or its model is not the one
        its record was written with (:func:`_check_checkpoint_model`)
    """
    from sb3_dtdpg.baselines import make_env

    phase_files = {"curriculum_save_path": str(run_dir)} if spec.algo == "dtdpg" else {}
    if checkpoint is not None:
        return _resume_model(spec, run_dir, checkpoint, identity, verbose, phase_files)
    env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
    model = build_model(spec, env, verbose=verbose, **phase_files)
    return env, model, 0


def _resume_model(
    spec: RunSpec,
    run_dir: Path,
    checkpoint: dict[str, Any],
    identity: dict[str, Any],
    verbose: int,
    phase_files: dict[str, str],
) -> tuple[Any, Any, int]:
    """:func:`_build_model` from a checkpoint"""
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    from sb3_dtdpg.baselines import load_model, make_env

    pointer, folder = run_dir / "checkpoint.json", checkpoint["path"]
    buffer, state_file = folder / "replay_buffer.pkl", folder / training_state.TRAINING_STATE
    env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
    try:
        try:
            if state_file.exists():  # the env as it was (the model loads without one: loading would seed it)
                state = training_state.load(state_file)
                model = load_model(spec.algo, folder / "model.zip", device="cpu", verbose=verbose, **phase_files)
                training_state.restore(model, env, state)
            else:  # a checkpoint of an earlier version: a fresh env
                model = load_model(spec.algo, folder / "model.zip", env=env, device="cpu", verbose=verbose, **phase_files)
            if buffer.exists():
                model.load_replay_buffer(buffer)
        except Exception as error:  # written atomically: damaged from outside
            raise DamagedRecordError(
                f"the checkpoint in {folder} cannot be loaded ({type(error).__name__}: "
                f"{str(error)[:200]}); delete {pointer} to start the run afresh"
            ) from error
        if isinstance(model, OffPolicyAlgorithm) and not buffer.exists():  # saved with every off-policy model
            raise DamagedRecordError(
                f"the checkpoint in {folder} has no replay_buffer.pkl (removed from outside?); "
                f"delete {pointer} to start the run afresh"
            )
        _check_checkpoint_model(model, checkpoint, identity, pointer)
    except DamagedRecordError:
        env.close()
        raise
    return env, model, int(checkpoint["episodes"])


def _callbacks(
    spec: RunSpec,
    out: Path,
    model: Any,
    max_steps: int,
    done_episodes: int,
    identity: dict[str, Any],
    checkpoint_every: int | None,
    exact: bool,
    trained_s: float | None,
) -> tuple[EpisodeCounter, list[BaseCallback], int]:
    """
    :param exact: whether the training so far is the uninterrupted run's (recorded with the checkpoints)
    :param trained_s: wall-clock seconds trained before the checkpoint resumed from (None: not known)
    :return: the run's episode counter, its callbacks (the counter first) and the timesteps left to train
    """
    from sb3_dtdpg.baselines import mission_callbacks

    if spec.timesteps is None:
        counter = EpisodeReturnLogger(start=done_episodes, max_episodes=spec.episodes - done_episodes)
        # the uninterrupted run's step budget, so that a resumed run's schedules (learning rate) go on as they were
        total_timesteps = spec.episodes * max_steps - model.num_timesteps
        progress = RunProgress(progress_path(out, spec), spec.episodes, counter, "episodes")
    else:
        counter = EpisodeReturnLogger(start=done_episodes)
        total_timesteps = spec.timesteps - model.num_timesteps
        progress = RunProgress(progress_path(out, spec), spec.timesteps, counter, "timesteps")
    callbacks: list[BaseCallback] = [counter, *mission_callbacks(model), progress]
    if checkpoint_every:
        callbacks.append(PeriodicCheckpoint(run_folder(out, spec), checkpoint_every, identity, counter, exact, trained_s))
    return counter, callbacks, total_timesteps


def _train(model: Any, callbacks: list[BaseCallback], total_timesteps: int, resumed: bool, progress_bar: bool) -> float:
    """:return: the training's wall-clock seconds"""
    start = time.perf_counter()
    try:
        if total_timesteps > 0:
            model.learn(
                total_timesteps=total_timesteps,
                callback=callbacks,
                log_interval=1,
                reset_num_timesteps=not resumed,
                progress_bar=progress_bar,
            )
        check_finite(model)
    finally:
        model.logger.close()  # flush and close the CSV and TensorBoard files, also on an interruption
    return time.perf_counter() - start


def _record_divergence(out: Path, spec: RunSpec, identity: dict[str, Any], model: Any, error: Exception) -> RunDivergedError:
    """
    A run whose training failed with non-finite weights has diverged: its checkpoints are removed (resuming
    would diverge again, and they would hold the folder against other settings) and ``failed.json`` records
    the failure. :return: the error to raise
    """
    try:
        check_finite(model)
    except RunDivergedError as diverged:
        clear_checkpoints(run_folder(out, spec))
        write_json(failure_path(out, spec), {"identity": identity, "error": f"{type(error).__name__}: {error}"}, indent=1)
        return RunDivergedError(
            f"{spec.run_id}: {diverged}; its checkpoints were removed and the failure recorded in "
            f"{failure_path(out, spec)}: run it again with other settings (the next run starts afresh)"
        )
    raise error


def _before_transfer_models(run_dir: Path) -> list[Path]:
    """:return: DT-DPG's networks saved at the end of its destination phase (the "before transfer" evaluation's)"""
    return sorted(run_dir.glob("phase_*_destination.zip"))


def _evaluations(
    spec: RunSpec, model: Any, run_dir: Path, trained_on: list[str], final_reward_phase: str, n_trajectories: int
) -> dict[str, Any]:
    """:return: the evaluation records of the trained model and, for DT-DPG, of its network before the transfer"""
    from sb3_dtdpg.baselines import load_model, make_env
    from sb3_dtdpg.evaluation import evaluate

    def _evaluate(policy: Any, reward_phase: str) -> Any:
        return evaluate(
            policy,
            spec.env_id,
            n_episodes=spec.eval_episodes,
            seed=spec.eval_seed,
            channel=spec.eval_channel,
            multiple_access=spec.multiple_access,
            env_kwargs={**spec.env_kwargs, "reward_phase": reward_phase},
            return_trajectories=True,
        )

    records = {"eval": _evaluation_record(_evaluate(model, final_reward_phase), n_trajectories, final_reward_phase)}
    before = _before_transfer_models(run_dir)
    if before and spec.eval_before_transfer:
        load_env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
        try:
            phase_1 = load_model(spec.algo, before[0], env=load_env, device="cpu")
        except Exception as error:  # written atomically: damaged from outside
            load_env.close()
            raise DamagedRecordError(
                f"the network saved before the transfer, {before[0]}, cannot be loaded ({type(error).__name__}: "
                f"{str(error)[:200]}); delete {run_dir / TRAINED_RECORD} to train the run again"
            ) from error
        phase_1_reward = trained_on[0]
        records["before_transfer"] = _evaluation_record(_evaluate(phase_1, phase_1_reward), n_trajectories, phase_1_reward)
        load_env.close()
    return records


def run_one(
    spec: RunSpec,
    out: str | Path,
    n_trajectories: int = 3,
    *,
    tensorboard_dir: str | Path | None = None,
    checkpoint_every: int | None = None,
    resume: bool = False,
    retest: bool = False,
    threads: int | None = 1,
    progress_bar: bool = False,
    verbose: int = 0,
    identity: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """
    Train, save and evaluate one run; the result is written to :func:`result_path` last.

    The run is evaluated on the reward phase it finished training on (DT-DPG: its last phase's, ``mqi``; the
    baselines: ``combined``), the network saved before the transfer on the first phase's; the result records
    them (``reward_phases``, and ``reward_phase`` in each evaluation record).

    The model trains for ``spec.episodes`` episodes (counted and stopped by the run's
    :class:`~sb3_dtdpg.experiments.run_callbacks.EpisodeReturnLogger`; or ``spec.timesteps`` timesteps), logging
    to TensorBoard in ``<tensorboard_dir>/<run_id>`` (SB3's scalars and the ``mission/*`` ones). DT-DPG also
    saves its network at the end of the destination phase (the paper's theta_X), which is evaluated too ("before transfer").

    Without ``resume``, leftovers of an interrupted attempt are removed and the run starts afresh (so that a
    run's result depends on its seed only). With ``resume``, a finished run's result is returned as is, one
    interrupted in its evaluations is evaluated again (its trained ``model.zip``, :data:`TRAINED_RECORD`), and one
    interrupted in training continues from its last checkpoint: model, replay buffer, action noise, curriculum
    state and the training state (:mod:`.training_state`: the env as it was and the random generators), so that
    it trains on bit for bit as the uninterrupted run (a checkpoint of an earlier version, without the training
    state, resumes on a fresh env). With ``retest`` alone, a run is taken up only where the result stays the
    uninterrupted run's: one interrupted in its evaluations is evaluated again, one interrupted in training goes on
    from a checkpoint of a training that was the uninterrupted run's so far (``same_as_uninterrupted`` in
    ``checkpoint.json``); any other leftover is removed as without ``resume``.

    :param spec: the run
    :param out: output folder
    :param n_trajectories: how many test episodes' trajectories to keep in the result
    :param tensorboard_dir: TensorBoard root folder (None: ``<out>/tb``, under the output folder's lock); a run
        claims its folder there (:func:`sb3_dtdpg.experiments.storage.tensorboard_claim`): it never deletes or
        writes into another run's logs
    :param checkpoint_every: save a checkpoint every this many episodes (None: none)
    :param resume: reuse a finished result or the last checkpoint (both checked against :func:`run_identity`)
    :param retest: take up a run interrupted in its evaluations, or in training with a checkpoint, where its
        result stays the uninterrupted run's (what ``compare`` and ``reproduce`` do; implied by ``resume``)
    :param threads: torch threads (None: torch's default; 1 in parallel workers)
    :param progress_bar: show SB3's progress bar
    :param verbose: SB3 verbosity
    :param identity: the run's :func:`prepare_run` (None: prepared here)
    :return: the result (as written)
    :raises RunMismatchError: with ``resume``, a stored result or checkpoint is another run's; the TensorBoard
        folder holds another run's logs
    :raises OutputBusyError: another process trains into the run's TensorBoard folder
    :raises RunDivergedError: training diverged (``failed.json`` records it; the checkpoints are removed)
    :raises DamagedRecordError: with ``resume``, the result or checkpoint record is damaged, or the checkpoint it
        names is missing, cannot be loaded or is not this run's (another algorithm's or run's model): changed from
        outside; the message names what to delete, and nothing is removed
    :raises ValueError: when the budget cannot train (:func:`prepare_run`)
    """
    import torch as th

    import noma_radiomap  # noqa: F401  (registers the env ids in a spawned worker)

    identity = prepare_run(spec) if identity is None else identity
    if threads is not None:
        th.set_num_threads(threads)  # one core per run: runs are parallel across processes
    out = Path(out)
    run_dir = run_folder(out, spec)
    checkpoint, trained = None, None
    if resume:
        finished = load_result(out, spec, identity)
        if finished is not None:
            warn_other_versions({spec.run_id: finished}, out)
            return finished
        record = read_trained(run_dir, identity)
        if record is not None:
            warn_other_versions({spec.run_id: record}, out, reused="evaluated")
            trained = _load_trained(spec, run_dir, verbose), record
        else:
            checkpoint = read_checkpoint(run_dir, identity)
            warn_other_versions({spec.run_id: checkpoint}, out, reused="resumed")
    elif retest:
        trained = _uninterrupted_training(run_dir, identity, spec, verbose)
        if trained is None:
            checkpoint = _uninterrupted_checkpoint(run_dir, identity)
            if checkpoint is not None:
                warn_other_versions({spec.run_id: checkpoint}, out, reused="resumed")
    if trained is not None:  # interrupted in its evaluations: the trained model is evaluated, not trained again
        remove_temp_files(run_dir)  # e.g. of a result.json whose writer was killed
        return _record_result(spec, out, *trained, n_trajectories)
    built = None
    if checkpoint is not None and not resume:  # retest: a checkpoint that cannot be loaded is a leftover
        try:
            built = _build_model(spec, run_dir, checkpoint, identity, verbose)
        except DamagedRecordError as error:
            warnings.warn(f"{spec.run_id}: its checkpoint is not resumed, the run trains afresh: {error}", stacklevel=2)
            checkpoint = None
    tb_dir = tensorboard_folder(out, spec, tensorboard_dir)
    with tensorboard_claim(tb_dir, out, spec.run_id, fresh=checkpoint is None):
        if checkpoint is None:  # leftovers of an interrupted attempt: start afresh
            if run_dir.is_dir():
                clear_checkpoints(run_dir)  # the checkpoint record first: a kill here leaves none naming a removed folder
            shutil.rmtree(run_dir, ignore_errors=True)
        remove_temp_files(run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        return _train_and_record(
            spec, out, tb_dir, identity, checkpoint, n_trajectories, checkpoint_every, progress_bar, verbose, built
        )


def _train_and_record(
    spec: RunSpec,
    out: Path,
    tb_dir: Path,
    identity: dict[str, Any],
    checkpoint: dict[str, Any] | None,
    n_trajectories: int,
    checkpoint_every: int | None,
    progress_bar: bool,
    verbose: int,
    built: tuple[Any, Any, int] | None = None,
) -> dict[str, Any]:
    """
    The steps of :func:`run_one` once its folders are ready: build, train, save, evaluate, write the result.

    :param built: :func:`_build_model`'s env, model and episodes trained, when already built (None: built here)
    """
    run_dir = run_folder(out, spec)
    env, model, done_episodes = _build_model(spec, run_dir, checkpoint, identity, verbose) if built is None else built
    # every algorithm's zip, its checkpoints' too, says what it was trained on (DTDPG's save does it too)
    env_settings.record(model)
    start_timesteps = int(model.num_timesteps) if checkpoint is not None else 0  # learn() resets a new model's count
    model.set_logger(run_logger(tb_dir, verbose, start_timesteps if checkpoint is not None else None))
    max_steps = int(env.unwrapped.scenario.mission.max_steps)
    exact = checkpoint is None or _resumes_exactly(checkpoint)
    trained_s = 0.0 if checkpoint is None else checkpoint["train_s"]
    counter, callbacks, total_timesteps = _callbacks(
        spec, out, model, max_steps, done_episodes, identity, checkpoint_every, exact, trained_s
    )
    try:
        train_s = _train(model, callbacks, total_timesteps, checkpoint is not None, progress_bar)
    except Exception as error:  # not KeyboardInterrupt: an interrupted run keeps its checkpoint
        raise _record_divergence(out, spec, identity, model, error) from error
    atomic_write(run_dir / "model.zip", model.save)
    curriculum = getattr(model, "curriculum_state", None)
    if curriculum is not None:
        trained_on = list(dict.fromkeys(entry.get("reward_phase") for entry in curriculum["history"]))
    else:
        trained_on = [env.unwrapped.reward_phase]
    final_reward_phase = env.unwrapped.reward_phase
    env.close()
    trained = {
        "identity": identity,
        "train": {
            "timesteps": int(model.num_timesteps),
            "episodes": int(counter.n_episodes),
            "resumed_at_episode": done_episodes if checkpoint is not None else None,
            "same_as_uninterrupted": exact,  # started afresh, or resumed from checkpoints that kept everything
            # the training's: up to the checkpoint it resumed from, then in this process (a checkpoint of an
            # earlier version records no time: then this process's only, as wall_s_complete says)
            "wall_s": train_s + (trained_s or 0.0),
            "wall_s_complete": trained_s is not None,
            # the steps trained in this process over its training time (a resumed run: not those before its checkpoint)
            "steps_per_s": (model.num_timesteps - start_timesteps) / max(train_s, 1e-9),
        },
        "reward_phases": {"trained": trained_on, "evaluated": final_reward_phase},
        "curriculum_state": curriculum,
        "before_transfer_models": [path.name for path in _before_transfer_models(run_dir)],
        "made_with": made_with(),
    }
    # What the result keeps of the training, so that a run interrupted in its evaluations resumes with them
    write_json(run_dir / TRAINED_RECORD, trained, indent=1)
    return _record_result(spec, out, model, trained, n_trajectories)


def _uninterrupted_training(
    run_dir: Path, identity: dict[str, Any], spec: RunSpec, verbose: int
) -> tuple[Any, dict[str, Any]] | None:
    """
    :return: the trained model and its record of a run that trained from its start in one go and was interrupted
        in its evaluations (None: none, or leftovers that are not such a run's, to be removed as without ``resume``:
        another run's, damaged, of a training resumed from a checkpoint, or without the networks saved before the
        transfer that its training left, which the uninterrupted run evaluates too)
    """
    try:
        trained = read_trained(run_dir, identity)
        train = None if trained is None else trained.get("train")
        if not isinstance(train, dict):
            return None
        if train.get("resumed_at_episode") is not None and train.get("same_as_uninterrupted") is not True:
            return None
        before = trained.get("before_transfer_models")  # recorded when the training ended
        if before != [path.name for path in _before_transfer_models(run_dir)]:
            return None
        if not all(zipfile.is_zipfile(run_dir / name) for name in before):
            return None
        return _load_trained(spec, run_dir, verbose), trained
    except (RunMismatchError, DamagedRecordError):
        return None


def _uninterrupted_checkpoint(run_dir: Path, identity: dict[str, Any]) -> dict[str, Any] | None:
    """
    :return: the run's last checkpoint when resuming from it gives the uninterrupted run's training bit for bit
        (None: none, or leftovers that are not such a checkpoint, to be removed: another run's, damaged, without a
        training state, or of a training resumed from a checkpoint that had none)
    """
    try:
        checkpoint = read_checkpoint(run_dir, identity)
    except (RunMismatchError, DamagedRecordError):
        return None
    return checkpoint if checkpoint is not None and _resumes_exactly(checkpoint) else None


def _resumes_exactly(checkpoint: dict[str, Any]) -> bool:
    """:return: whether resuming from the checkpoint (:func:`read_checkpoint`) gives the uninterrupted run's training:
    it was recorded so and keeps its training state"""
    return checkpoint.get("same_as_uninterrupted") is True and (checkpoint["path"] / training_state.TRAINING_STATE).is_file()


def _load_trained(spec: RunSpec, run_dir: Path, verbose: int) -> Any:
    """:return: the run's trained model (``model.zip``, beside its :data:`TRAINED_RECORD`)
    :raises DamagedRecordError: it cannot be loaded"""
    from sb3_dtdpg.baselines import load_model

    path = run_dir / "model.zip"
    try:
        return load_model(spec.algo, path, device="cpu", verbose=verbose)
    except Exception as error:  # written atomically: damaged from outside
        raise DamagedRecordError(
            f"the trained model {path} cannot be loaded ({type(error).__name__}: {str(error)[:200]}); delete "
            f"{run_dir / TRAINED_RECORD} to train the run again"
        ) from error


def _record_result(spec: RunSpec, out: Path, model: Any, trained: dict[str, Any], n_trajectories: int) -> dict[str, Any]:
    """Evaluate the trained model and write the run's result (:func:`result_path`); :return: the result"""
    run_dir = run_folder(out, spec)
    reward_phases = trained["reward_phases"]
    result: dict[str, Any] = {
        "identity": trained["identity"],
        "spec": dataclasses.asdict(spec),
        "run_id": spec.run_id,
        "group": spec.group,
        "train": trained["train"],
        "reward_phases": reward_phases,
        **_evaluations(spec, model, run_dir, reward_phases["trained"], reward_phases["evaluated"], n_trajectories),
        "curriculum_state": trained["curriculum_state"],
        "made_with": trained.get("made_with"),  # the training's (a record of an older version has none)
    }
    write_json(result_path(out, spec), result, indent=1)
    clear_checkpoints(run_dir)  # the result supersedes them (and the record of the training)
    return result


def _worker(spec: RunSpec, out: str, identity: dict[str, Any]) -> tuple[str, float, bool]:
    """:return: the run id, its seconds and whether it went on from a checkpoint (:func:`run_in_pool`'s ``work``)"""
    start = time.perf_counter()
    result = run_one(spec, out, identity=identity, retest=True, checkpoint_every=CHECKPOINT_EVERY)
    return spec.run_id, time.perf_counter() - start, result["train"]["resumed_at_episode"] is not None


def run_many(
    specs: Sequence[RunSpec],
    out: str | Path,
    n_workers: int | None = None,
    progress: bool = True,
    on_finish: Callable[[str], None] | None = None,
) -> RunReport:
    """
    Run the unfinished runs of ``specs`` in parallel worker processes (spawned, one torch thread each).

    Runs whose result file exists are skipped (resumable), after checking that the stored result is this run's
    (:func:`run_identity`). Each run writes its files as soon as it ends and a checkpoint every
    :data:`CHECKPOINT_EVERY` episodes, so an interruption loses only the episodes since the runs' last checkpoints:
    the next job goes on from them, bit for bit as the uninterrupted runs, and evaluates a run interrupted in its
    evaluations again (``run_one``'s ``retest``). Hold :func:`output_lock` around a job that calls this.

    :param specs: the runs
    :param out: output folder
    :param n_workers: number of processes (default: the number of CPUs)
    :param progress: show a progress bar
    :param on_finish: called with each run id as it finishes
    :return: the report
    :raises RunMismatchError: stored results are other runs' (checked for every run before any starts, all named)
    :raises ValueError: a run's budget cannot train (:func:`prepare_run`, for every run before any starts), or two
        runs share an id with other settings
    """
    unique: dict[str, RunSpec] = {}
    for spec in specs:  # a run given twice runs once: two workers must never write one run's folder
        if unique.setdefault(spec.run_id, spec) != spec:
            raise ValueError(f"two runs share the id {spec.run_id!r} with other settings: {unique[spec.run_id]} and {spec}")
    specs = list(unique.values())
    identities = [prepare_run(spec) for spec in specs]  # every run's checks before any run starts
    stored = load_results(out, specs, identities)
    report = RunReport()
    todo: list[tuple[RunSpec, str, dict[str, Any]]] = []
    for spec, identity in zip(specs, identities, strict=True):
        if stored[spec.run_id] is not None:
            report.skipped.append(spec.run_id)
        else:
            todo.append((spec, str(out), identity))
    # Longest runs first (the budget is the proxy for their length), so that no long run starts last and runs alone
    todo.sort(key=lambda job: job[0].timesteps or job[0].episodes, reverse=True)
    n_workers = max(1, min(n_workers or os.cpu_count() or 1, len(todo) or 1))
    start = time.perf_counter()
    run_in_pool(_worker, todo, out, n_workers, report, progress=progress, on_finish=on_finish)
    report.wall_s = time.perf_counter() - start
    return report
