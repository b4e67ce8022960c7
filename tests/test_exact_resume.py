"""A run interrupted in training and resumed from its checkpoint trains on as the uninterrupted run would, bit for
bit: ``sb3-dtdpg train``'s resume, and the runs of ``compare``/``reproduce``, which go on from their checkpoints."""

import dataclasses
import json

import pytest
from bitwise import same
from stable_baselines3.common.save_util import load_from_zip_file

from sb3_dtdpg.common.training_state import TRAINING_STATE
from sb3_dtdpg.experiments import runs
from sb3_dtdpg.experiments.runs import PeriodicCheckpoint, RunSpec, prepare_run, result_path, run_one

# 6 episodes of 60 steps at most; the paper's settings learn from step 100, DT-DPG's transfer comes after episode 4
DDPG = RunSpec("ddpg", "noma", 0, 6, scenario="small", eval_episodes=2, observation="paper")
DTDPG = dataclasses.replace(DDPG, algo="dtdpg")


def _trained(out, spec):
    """:return: the run's result and its model's weights and optimizer states"""
    run_dir = out / "runs" / spec.run_id
    _, params, _ = load_from_zip_file(run_dir / "model.zip", device="cpu")
    return json.loads((run_dir / "result.json").read_text()), params


def _interrupt_at(patch, episodes: int) -> None:
    """Make training raise ``KeyboardInterrupt`` right after its checkpoint at ``episodes`` or later."""
    original = runs.PeriodicCheckpoint._on_rollout_start

    def interrupt(self):
        due = self._due
        original(self)
        if due and self.counter.n_episodes >= episodes:
            raise KeyboardInterrupt

    patch.setattr(PeriodicCheckpoint, "_on_rollout_start", interrupt)


def _assert_same_training(resumed, uninterrupted, resumed_params, uninterrupted_params):
    assert same(resumed_params, uninterrupted_params)  # weights, target networks, Adam's moments and step counts
    assert resumed["train"]["timesteps"] == uninterrupted["train"]["timesteps"]
    assert json.dumps(resumed["eval"], sort_keys=True) == json.dumps(uninterrupted["eval"], sort_keys=True)
    assert resumed["curriculum_state"] == uninterrupted["curriculum_state"]


@pytest.mark.parametrize("spec", [DDPG, DTDPG], ids=["ddpg", "dtdpg"])
def test_a_run_resumed_twice_trains_the_uninterrupted_runs_weights(tmp_path, monkeypatch, spec):
    run_one(spec, tmp_path / "a")  # no checkpoints
    uninterrupted, uninterrupted_params = _trained(tmp_path / "a", spec)
    for stop in (2, 4):  # the second attempt resumes from the first's checkpoint, the third from the second's
        with monkeypatch.context() as patch:
            _interrupt_at(patch, stop)
            with pytest.raises(KeyboardInterrupt):
                run_one(spec, tmp_path / "b", resume=True, checkpoint_every=2)
        checkpoint = json.loads((tmp_path / "b" / "runs" / spec.run_id / "checkpoint.json").read_text())
        assert checkpoint["episodes"] == stop and checkpoint["same_as_uninterrupted"] is True
    run_one(spec, tmp_path / "b", resume=True, checkpoint_every=2)
    resumed, resumed_params = _trained(tmp_path / "b", spec)
    assert resumed["train"]["resumed_at_episode"] == 4 and resumed["train"]["same_as_uninterrupted"] is True
    if spec.algo == "dtdpg":  # the transfer came between two checkpoints
        assert [entry["phase"] for entry in resumed["curriculum_state"]["history"]] == ["destination", "mqi"]
        assert resumed["curriculum_state"]["history"][0]["episodes"] == 4
    _assert_same_training(resumed, uninterrupted, resumed_params, uninterrupted_params)


def test_a_compare_run_interrupted_in_training_goes_on_from_its_checkpoint(tmp_path, monkeypatch):
    monkeypatch.setattr(runs, "CHECKPOINT_EVERY", 2)
    with monkeypatch.context() as patch:
        _interrupt_at(patch, 2)
        with pytest.raises(KeyboardInterrupt):
            runs._worker(DTDPG, str(tmp_path / "b"), prepare_run(DTDPG))
    report = runs.run_many([DTDPG], tmp_path / "b", n_workers=1, progress=False)  # as compare runs it again
    assert not report.failed
    assert report.resumed == [DTDPG.run_id] and report.counts() == "1 run (1 resumed from its checkpoint), 0 already done"
    resumed, resumed_params = _trained(tmp_path / "b", DTDPG)
    assert resumed["train"]["resumed_at_episode"] == 2  # was: trained again from its start; the transfer came after
    run_one(DTDPG, tmp_path / "a")
    uninterrupted, uninterrupted_params = _trained(tmp_path / "a", DTDPG)
    _assert_same_training(resumed, uninterrupted, resumed_params, uninterrupted_params)
    assert json.dumps(resumed["before_transfer"], sort_keys=True) == json.dumps(
        uninterrupted["before_transfer"], sort_keys=True
    )


def _checkpoint_of_an_earlier_version(tmp_path, monkeypatch):
    """A run interrupted after its checkpoint at episode 2, made as the versions before the training state did."""
    with monkeypatch.context() as patch:
        _interrupt_at(patch, 2)
        with pytest.raises(KeyboardInterrupt):
            run_one(DDPG, tmp_path, resume=True, checkpoint_every=2)
    return _as_an_earlier_version(tmp_path / "runs" / DDPG.run_id)


def _as_an_earlier_version(run_dir):
    """Make the run's checkpoint one the versions before the training state wrote. :return: ``run_dir``"""
    pointer = json.loads((run_dir / "checkpoint.json").read_text())
    (run_dir / pointer["folder"] / TRAINING_STATE).unlink()
    del pointer["same_as_uninterrupted"]
    (run_dir / "checkpoint.json").write_text(json.dumps(pointer))
    return run_dir


def test_train_resumes_a_checkpoint_without_its_training_state_on_a_fresh_env_and_says_so(tmp_path, monkeypatch):
    run_dir = _checkpoint_of_an_earlier_version(tmp_path, monkeypatch)
    with monkeypatch.context() as patch:
        _interrupt_at(patch, 4)
        with pytest.raises(KeyboardInterrupt):
            run_one(DDPG, tmp_path, resume=True, checkpoint_every=2)
    # the checkpoints that follow are not the uninterrupted run's either
    assert json.loads((run_dir / "checkpoint.json").read_text())["same_as_uninterrupted"] is False
    result = run_one(DDPG, tmp_path, resume=True, checkpoint_every=2)
    assert result["train"]["resumed_at_episode"] == 4 and result["train"]["same_as_uninterrupted"] is False


def test_train_says_when_a_run_resumed_on_a_fresh_env(tmp_path, monkeypatch, capsys):
    from sb3_dtdpg.cli import main

    argv = ["train", "--algo", "ddpg", "--preset", "paper", "--observation", "paper", "--scenario", "small"]
    argv += ["--episodes", "6", "--checkpoint-every", "2", "--eval-episodes", "1", "--no-progress", "--out", str(tmp_path)]
    with monkeypatch.context() as patch:
        _interrupt_at(patch, 2)
        assert main(argv) == 130
    _as_an_earlier_version(tmp_path / "runs" / DDPG.run_id)
    assert main(argv) == 0
    assert "6 episodes (resumed after episode 2, on a fresh env), last reward phase" in capsys.readouterr().out


def test_a_compare_run_trains_afresh_over_a_checkpoint_without_its_training_state(tmp_path, monkeypatch):
    _checkpoint_of_an_earlier_version(tmp_path, monkeypatch)
    resumed = []

    def train(model, callbacks, total_timesteps, was_resumed, progress_bar):
        resumed.append(was_resumed)
        raise KeyboardInterrupt

    monkeypatch.setattr(runs, "_train", train)
    with pytest.raises(KeyboardInterrupt):
        runs._worker(DDPG, str(tmp_path), prepare_run(DDPG))
    assert resumed == [False]
    assert not (tmp_path / "runs" / DDPG.run_id / "checkpoint.json").exists()  # the leftovers were removed


def test_a_compare_run_whose_checkpoint_cannot_be_loaded_trains_afresh_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setattr(runs, "CHECKPOINT_EVERY", 2)
    with monkeypatch.context() as patch:
        _interrupt_at(patch, 2)
        with pytest.raises(KeyboardInterrupt):
            runs._worker(DDPG, str(tmp_path), prepare_run(DDPG))
    run_dir = tmp_path / "runs" / DDPG.run_id
    (run_dir / json.loads((run_dir / "checkpoint.json").read_text())["folder"] / TRAINING_STATE).write_bytes(b"damaged")
    with pytest.warns(
        UserWarning, match=r"ddpg_noma_s0: its checkpoint is not resumed, the run trains afresh: the checkpoint"
    ):
        runs._worker(DDPG, str(tmp_path), prepare_run(DDPG))
    assert json.loads(result_path(tmp_path, DDPG).read_text())["train"]["resumed_at_episode"] is None


def test_a_checkpoint_resumes_in_a_process_where_gymnasiums_time_limit_is_its_own(tmp_path, monkeypatch):
    """Importing the RL Zoo replaces Gymnasium's ``TimeLimit`` in its modules. A checkpoint written in such a process
    (the env's ``TimeLimit`` then cannot be found by its name) resumes in a job's worker, which has the original:
    pickled whole, the wrapper would travel by value and fail there (``TypeError: super(type, obj): ...``)."""
    import gymnasium.wrappers
    import gymnasium.wrappers.common

    class ReplacedTimeLimit(gymnasium.wrappers.common.TimeLimit):
        pass

    monkeypatch.setattr(runs, "CHECKPOINT_EVERY", 2)
    with monkeypatch.context() as patch:
        for module in (gymnasium.wrappers, gymnasium.wrappers.common):  # as rl_zoo3.gym_patches does
            patch.setattr(module, "TimeLimit", ReplacedTimeLimit)
        _interrupt_at(patch, 2)
        with pytest.raises(KeyboardInterrupt):
            runs._worker(DDPG, str(tmp_path), prepare_run(DDPG))
    report = runs.run_many([DDPG], tmp_path, n_workers=1, progress=False)
    assert report.failed == {} and report.resumed == [DDPG.run_id]


def test_a_checkpoint_of_a_model_on_another_vector_env_keeps_no_training_state_and_says_so(tmp_path):
    """The training state keeps a ``DummyVecEnv``'s envs; a model on another vector env (here ``VecNormalize``) gets
    its checkpoint all the same, recorded as not the uninterrupted run's."""
    import gymnasium as gym
    from stable_baselines3 import DDPG as SB3DDPG
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from sb3_dtdpg.experiments.storage import read_checkpoint, save_checkpoint

    model = SB3DDPG("MlpPolicy", VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")])), learning_starts=10)
    model.learn(20)
    folder = save_checkpoint(model, tmp_path, {}, 1)
    assert (folder / "model.zip").is_file() and not (folder / TRAINING_STATE).exists()
    assert read_checkpoint(tmp_path)["same_as_uninterrupted"] is False


def test_the_jobs_closing_lines_count_the_resumed_runs():
    from sb3_dtdpg.experiments.pool import RunReport
    from sb3_dtdpg.experiments.reproduce import _counts

    report = RunReport(finished=["a", "b"], resumed=["a", "b"], skipped=["c"])
    assert report.counts() == "2 runs (2 resumed from their checkpoints), 1 already done"  # compare's
    results = {"a": {}, "b": {}, "c": {}, "d": None}
    assert _counts({"a", "b", "c"}, results, report) == (
        "3 of 3 runs finished (of all experiments' 4 runs, 3); 2 resumed from their checkpoints"
    )
    assert RunReport(finished=["a"]).counts() == "1 run, 0 already done"
