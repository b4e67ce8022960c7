"""``sb3-dtdpg train`` on an env without missions (``Pendulum-v1``): its checkpoints, from which the same command
resumes the run as the uninterrupted one goes on, bit for bit; a command with other options is refused."""

import pandas as pd
import pytest
from bitwise import same, saved_weights
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from sb3_dtdpg.cli import main
from sb3_dtdpg.experiments.run_callbacks import EpisodeReturnLogger

# Pendulum-v1's episodes are 200 steps: a checkpoint every 2 episodes, at steps 400, 800, ...
ARGS = ["train", "--env", "Pendulum-v1", "--preset", "paper", "--checkpoint-every", "2", "--eval-episodes", "1"]
ARGS += ["--no-progress", "--hyperparams", "learning_starts:50", "batch_size:16", "policy_kwargs:dict(net_arch=[16, 16])"]


def _interrupt_at(monkeypatch, step):
    """Ctrl-C when the training reaches ``step`` env steps."""
    on_step = EpisodeReturnLogger._on_step

    def interrupted(self):
        if self.num_timesteps == step:
            raise KeyboardInterrupt
        return on_step(self)

    monkeypatch.setattr(EpisodeReturnLogger, "_on_step", interrupted)


@pytest.mark.parametrize(("algo", "budget"), [("ddpg", ["--timesteps", "1200"]), ("dtdpg", ["--episodes", "6"])])
def test_a_train_interrupted_twice_resumes_to_the_uninterrupted_weights(algo, budget, tmp_path, monkeypatch, capsys):
    args = [*ARGS, "--algo", algo, *budget]
    name = f"{algo}_Pendulum-v1_s0"
    assert main([*args, "--out", str(tmp_path / "whole")]) == 0
    out = tmp_path / "interrupted"
    folder = out / f"{name}_checkpoints"
    capsys.readouterr()

    _interrupt_at(monkeypatch, 700)
    assert main([*args, "--out", str(out)]) == 130
    assert "the same command resumes from the checkpoint after 400 steps" in capsys.readouterr().err
    monkeypatch.undo()
    _interrupt_at(monkeypatch, 1100)
    assert main([*args, "--out", str(out)]) == 130
    printed = capsys.readouterr()
    assert f"resuming after 400 steps (2 episodes) from {folder}" in printed.out
    assert "the same command resumes from the checkpoint after 800 steps" in printed.err
    assert sorted(path.name for path in folder.glob("*.zip")) == [f"{name}_800_steps.zip"]  # the latest only
    monkeypatch.undo()
    assert main([*args, "--out", str(out)]) == 0
    assert f"{name}: 1200 steps (resumed after step 800)" in capsys.readouterr().out

    assert same(saved_weights(out / f"{name}.zip"), saved_weights(tmp_path / "whole" / f"{name}.zip"))
    board = EventAccumulator(str(out / "tb" / f"{name}_1"))  # what TensorBoard shows: each episode once
    board.Reload()
    assert [event.step for event in board.Scalars("episode/number")] == [200, 400, 600, 800, 1000, 1200]
    logged = pd.read_csv(out / "tb" / f"{name}_1" / "progress.csv")
    whole = pd.read_csv(tmp_path / "whole" / "tb" / f"{name}_1" / "progress.csv")
    assert list(logged["episode/number"].dropna()) == [1, 2, 3, 4, 5, 6]  # one row per episode, counted on
    pd.testing.assert_series_equal(logged["episode/return"], whole["episode/return"])  # the uninterrupted run's
    assert not folder.exists()  # removed once the model is saved
    assert len(list(out.glob(f"{name}_interrupted*.zip"))) == 2  # the models at each Ctrl-C, as before


def test_a_train_with_other_options_does_not_resume_a_checkpoint(tmp_path, monkeypatch, capsys):
    args = [*ARGS, "--algo", "ddpg", "--timesteps", "1200", "--out", str(tmp_path)]
    _interrupt_at(monkeypatch, 500)
    assert main(args) == 130
    capsys.readouterr()
    with pytest.raises(SystemExit) as exited:
        main([*args, "--learning-rate", "0.0005"])
    assert exited.value.code == 2
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert "was run with --learning-rate (unset); this command asks for --learning-rate 0.0005" in message
    assert (tmp_path / "ddpg_Pendulum-v1_s0_checkpoints" / "ddpg_Pendulum-v1_s0_400_steps.zip").is_file()  # kept


def test_a_damaged_checkpoint_is_a_named_error_and_is_kept(tmp_path, monkeypatch, capsys):
    args = [*ARGS, "--algo", "ddpg", "--timesteps", "1200", "--out", str(tmp_path)]
    _interrupt_at(monkeypatch, 500)
    assert main(args) == 130
    model_file = tmp_path / "ddpg_Pendulum-v1_s0_checkpoints" / "ddpg_Pendulum-v1_s0_400_steps.zip"
    model_file.write_bytes(model_file.read_bytes()[:1000])  # cut, as by a full disk outside the package
    capsys.readouterr()
    with pytest.raises(SystemExit) as exited:
        main(args)
    assert exited.value.code == 2
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"{model_file}: the checkpoint cannot be loaded" in message and "delete" in message
    assert model_file.is_file()


def test_a_run_interrupted_before_its_first_checkpoint_starts_afresh_with_any_options(tmp_path, monkeypatch, capsys):
    args = [*ARGS, "--algo", "ddpg", "--timesteps", "1200", "--out", str(tmp_path)]
    _interrupt_at(monkeypatch, 300)
    assert main(args) == 130
    assert "no checkpoint yet (one every 2 episodes): the same command starts afresh" in capsys.readouterr().err
    monkeypatch.undo()
    args[args.index("1200")] = "400"
    assert main([*args, "--learning-rate", "0.0005"]) == 0
    assert "resumed" not in capsys.readouterr().out
