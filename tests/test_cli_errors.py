"""User errors of the command line: one ``error:`` line of the subcommand, exit status 2, nothing created."""

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sb3_dtdpg import cli, cli_parser
from sb3_dtdpg.cli import main

REPO = Path(__file__).resolve().parents[1]


def run_cli(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    return exit_info.value.code, capsys.readouterr()


def assert_one_error_line(code, printed, command, message):
    assert code == 2
    assert "Traceback" not in printed.err
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith(f"sb3-dtdpg {command}: error: "), printed.err
    assert message in errors[0]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--seed", "-1"], "expected a seed in 0..4294967295"),
        (["--seed", "99999999999999999999"], "expected a seed in 0..4294967295"),
        (["--eval-seed", "-5"], "expected a seed in 0..4294967295"),
        (["--learning-rate", "nan"], "expected a positive finite learning rate, got 'nan'"),
        (["--learning-rate", "-1"], "expected a positive finite learning rate, got '-1'"),
        (["--learning-rate", "inf"], "expected a positive finite learning rate, got 'inf'"),
        (["--threads", "-1"], "expected 0 (torch's default) or a positive number of threads"),
        (["--hyperparams", "learnin_rate:1e-3"], "unknown hyperparameter 'learnin_rate' for DTDPG"),
        (["--hyperparams", "learning_rate:0"], "learning_rate (--hyperparams) must be a positive finite number"),
        (["--hyperparams", "policy_kwargs:dict(net_arch=[100000, 100000])"], "more than the 20,000,000 allowed"),
        # were SB3's AssertionError tracebacks
        (["--hyperparams", "policy_kwargs:dict(net_arch=dict(pi=[64]))"], "keys exactly 'pi' and 'qf' (e.g."),
        (["--hyperparams", "policy_kwargs:dict(net_arch=dict(pi=[8], qf=[8], vf=[8]))"], "got the keys ['pi', 'qf', 'vf']"),
        (["--hyperparams", "policy_kwargs:dict(net_arch=(64, 64))"], "a list of layer sizes or a dict of them, got (64"),
        # was a TypeError traceback after every check, an empty run folder left
        (["--hyperparams", "curriculum_save_path:'phases'"], "curriculum_save_path (--hyperparams): set it with --out"),
        (["--hyperparams", "batch_size"], "expected key:value"),
        (["--hyperparams", "gamma:__import__('os')"], "is not a Python literal"),
        # were tracebacks after --out was made (the check built the model without its networks and buffer)
        (["--hyperparams", "policy_kwargs:dict(net_arc=[64, 64])"], "policy_kwargs key 'net_arc' for DTDPGPolicy"),
        (["--hyperparams", "policy_kwargs:dict(activation_fn='relu')"], "must be a class (e.g. nn.ReLU, unquoted), got"),
        (["--hyperparams", "replay_buffer_kwargs:dict(foo=1)"], "unexpected keyword argument 'foo'"),
        (["--hyperparams", "optimize_memory_usage:True"], "does not support optimize_memory_usage"),
        (["--hyperparams", "action_noise:0.1"], "action_noise must be an ActionNoise (e.g. NormalActionNoise(mean, sigma))"),
        (["--n-seed", "3"], "unrecognized arguments: --n-seed 3"),  # no abbreviations, the subcommand's error
        (["--bogus"], "unrecognized arguments: --bogus"),
    ],
)
def test_train_user_errors_create_nothing(extra, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # the default --out and --tb are relative: nothing may appear here
    code, printed = run_cli(["train", "--algo", "dtdpg", "--scenario", "small", "--episodes", "40", *extra], capsys)
    assert_one_error_line(code, printed, "train", message)
    assert list(tmp_path.iterdir()) == []


def test_an_env_whose_package_is_missing_is_a_user_error(tmp_path, monkeypatch, capsys):
    import gymnasium as gym

    def needs_a_missing_package(**kwargs):
        raise gym.error.DependencyNotInstalled('MuJoCo is not installed, run `pip install "gymnasium[mujoco]"`')

    gym.register("MissingPackage-v0", entry_point=needs_a_missing_package)
    monkeypatch.chdir(tmp_path)
    try:
        code, printed = run_cli(["train", "--algo", "ddpg", "--env", "MissingPackage-v0", "--timesteps", "200"], capsys)
    finally:
        del gym.registry["MissingPackage-v0"]
    message = "--env MissingPackage-v0 cannot be made here: DependencyNotInstalled: MuJoCo is not installed"
    assert_one_error_line(code, printed, "train", message)  # was a traceback
    assert list(tmp_path.iterdir()) == []


def test_an_env_with_discrete_actions_is_a_user_error(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, printed = run_cli(["train", "--algo", "dtdpg", "--env", "CartPole-v1", "--timesteps", "5000"], capsys)
    assert_one_error_line(code, printed, "train", "CartPole-v1: dtdpg needs a continuous (Box) action space")
    assert list(tmp_path.iterdir()) == []


def test_the_did_you_mean_names_the_right_key(capsys):
    code, printed = run_cli(["train", "--algo", "ddpg", "--hyperparams", "bach_size:64"], capsys)
    assert_one_error_line(code, printed, "train", "did you mean 'batch_size'")


@pytest.mark.parametrize("command", ["compare", "reproduce"])
def test_abbreviations_are_not_accepted(command, capsys):
    code, printed = run_cli([command, "--n-seed", "3"], capsys)
    assert_one_error_line(code, printed, command, "unrecognized arguments: --n-seed 3")


def test_a_folder_in_use_is_a_user_error(tmp_path, capsys):
    from sb3_dtdpg.experiments.runs import output_lock

    before = sorted(p.name for p in tmp_path.iterdir())
    with output_lock(tmp_path):
        code, printed = run_cli(["compare", "--budget", "tiny", "--out", str(tmp_path), "--no-progress"], capsys)
    assert_one_error_line(code, printed, "compare", "is in use by another job")
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != ".lock") == before


def test_a_folder_holding_another_run_of_the_same_id_is_a_user_error(tmp_path, capsys):
    train = ["train", "--algo", "ddpg", "--preset", "paper", "--scenario", "small", "--eval-episodes", "1"]
    train += ["--observation", "paper", "--out", str(tmp_path), "--no-progress"]
    assert main([*train, "--episodes", "2"]) == 0
    result = tmp_path / "runs" / "ddpg_noma_s0" / "result.json"
    stored = result.read_bytes()
    code, printed = run_cli([*train, "--episodes", "3"], capsys)  # same run id, other budget
    assert_one_error_line(code, printed, "train", "belongs to another run with the same id")
    assert result.read_bytes() == stored


def test_an_output_in_a_folder_that_is_not_writable_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    # (as root every folder is writable to os.access: the refusal is simulated)
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != locked and real_access(path, mode))
    code, printed = run_cli(["map", "--scenario", "small", "--out", str(locked / "maps")], capsys)
    assert_one_error_line(code, printed, "map", f"the folder {str(locked)!r} is not writable")
    assert not (locked / "maps").exists()


def test_a_folder_where_the_map_figure_goes_is_refused_before_the_map(tmp_path, capsys):
    (tmp_path / "maps" / "maps_small.png").mkdir(parents=True)
    code, printed = run_cli(["map", "--scenario", "small", "--out", str(tmp_path / "maps")], capsys)
    assert_one_error_line(code, printed, "map", "maps_small.png' is a folder, where the figure of scenario 'small' goes")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_scenario_that_is_a_folder_or_a_fifo_says_so(tmp_path, capsys):
    code, printed = run_cli(["map", "--scenario", str(tmp_path)], capsys)
    assert_one_error_line(code, printed, "map", "is a folder: give a scenario YAML file or a built-in name")
    fifo = tmp_path / "scenario.yaml"
    os.mkfifo(fifo)
    code, printed = run_cli(["map", "--scenario", str(fifo)], capsys)
    assert_one_error_line(code, printed, "map", "is not a regular file (a FIFO, socket or device)")


@pytest.mark.parametrize(
    "command",
    [["compare", "--out"], ["reproduce", "--out"], ["map", "--out"], ["train", "--algo", "ddpg", "--out"], ["train", "--tb"]],
    ids=["compare", "reproduce", "map", "train", "train_tb"],
)
def test_an_output_folder_that_is_a_file_says_so(tmp_path, capsys, command):
    file = tmp_path / "results"
    file.write_text("kept")
    for out in (file, file / "compare"):  # the folder itself, or a folder above it
        code, printed = run_cli([*command, str(out)], capsys)
        assert_one_error_line(code, printed, command[0], f"{str(file)!r} is a file, expected a folder")
    assert file.read_text() == "kept"


def test_a_bare_builtin_name_is_the_builtin_and_a_path_is_the_file(tmp_path, monkeypatch, capsys):
    from noma_radiomap import load_scenario

    text = (REPO / "envs" / "noma_radiomap" / "scenarios" / "small.yaml").read_text()
    (tmp_path / "small").write_text(text.replace("name: small", "name: my_small", 1))
    monkeypatch.chdir(tmp_path)
    assert load_scenario("small").name == "small"
    assert load_scenario("./small").name == "my_small"
    args = cli.build_parser().parse_args(["map", "--scenario", "small"])
    assert args.scenario == "small"
    assert "for the file 'small' here write ./small" in capsys.readouterr().err


def test_presets_have_their_own_flag_and_the_old_spelling_warns(capsys):
    parser = cli.build_parser()
    args = parser.parse_args(["compare", "--preset", "paper"])
    cli._split_hyperparams(args)
    assert (args.preset, args.overrides) == ("paper", {})
    args = parser.parse_args(["train", "--algo", "dtdpg", "--hyperparams", "batch_size:256", "gamma:0.9"])
    cli._split_hyperparams(args)
    assert args.preset is None and args.overrides == {"batch_size": 256, "gamma": 0.9}
    args = parser.parse_args(["train", "--algo", "dtdpg", "--hyperparams", "tuned"])
    cli._split_hyperparams(args)
    assert args.preset == "tuned" and "--hyperparams tuned is deprecated, use --preset tuned" in capsys.readouterr().err
    args = parser.parse_args(["compare", "--hyperparams", "paper"])  # compare and reproduce take whole presets
    assert args.preset == "paper" and "--hyperparams is deprecated, use --preset" in capsys.readouterr().err


def test_old_budget_names_are_aliases_of_names_that_say_what_they_run(capsys):
    from sb3_dtdpg.experiments.budgets import BUDGETS

    assert cli.build_parser().parse_args(["compare", "--budget", "reduced"]).budget == "small-200"
    assert "--budget reduced is deprecated, use --budget small-200" in capsys.readouterr().err
    assert BUDGETS["small-200"].scenario == "small" and BUDGETS["mall-200"].scenario is None  # None: mall


def test_overrides_reach_the_model(tmp_path, capsys):
    from sb3_dtdpg import DTDPG

    args = ["train", "--algo", "dtdpg", "--preset", "paper", "--env", "Pendulum-v1", "--timesteps", "120"]
    args += ["--hyperparams", "learning_starts:50", "batch_size:16", "policy_kwargs:dict(net_arch=[8, 8])"]
    args += ["--eval-episodes", "1", "--no-progress", "--tb", str(tmp_path / "tb"), "--out", str(tmp_path)]
    assert main(args) == 0
    model = DTDPG.load(tmp_path / "dtdpg_Pendulum-v1_s0.zip")
    assert (model.learning_starts, model.batch_size) == (50, 16)
    assert model.policy.actor.mu[0].out_features == 8


def test_an_interrupted_train_on_another_env_keeps_its_models_and_says_it_starts_afresh(tmp_path, monkeypatch, capsys):
    from stable_baselines3 import DDPG

    from sb3_dtdpg.baselines import load_model

    def interrupted(self, *args, **kwargs):
        self.num_timesteps = 70
        raise KeyboardInterrupt

    def interrupted_later(self, *args, **kwargs):
        self.num_timesteps = 90
        raise KeyboardInterrupt

    monkeypatch.setattr(DDPG, "learn", interrupted)
    args = ["train", "--algo", "ddpg", "--env", "Pendulum-v1", "--timesteps", "3000", "--no-progress"]
    assert main([*args, "--tb", str(tmp_path / "tb"), "--out", str(tmp_path)]) == 130
    message = capsys.readouterr().err
    assert "interrupted after 70 steps: the model so far is in" in message and "starts afresh" in message
    assert "resume" not in message  # there is nothing to resume from (was: "run the same command again to resume")
    assert load_model("ddpg", tmp_path / "ddpg_Pendulum-v1_s0_interrupted.zip").num_timesteps == 70
    monkeypatch.setattr(DDPG, "learn", interrupted_later)
    assert main([*args, "--tb", str(tmp_path / "tb"), "--out", str(tmp_path)]) == 130  # interrupted again
    second = tmp_path / "ddpg_Pendulum-v1_s0_interrupted_2.zip"
    assert f"the model so far is in {second};" in capsys.readouterr().err
    assert load_model("ddpg", second).num_timesteps == 90
    monkeypatch.undo()
    args[args.index("3000")] = "200"
    args += ["--preset", "paper", "--eval-episodes", "1", "--tb", str(tmp_path / "tb"), "--out", str(tmp_path)]
    assert main(args) == 0  # afresh, beside the interrupted model
    assert (tmp_path / "ddpg_Pendulum-v1_s0.zip").exists()
    assert load_model("ddpg", tmp_path / "ddpg_Pendulum-v1_s0_interrupted.zip").num_timesteps == 70  # kept


def test_train_on_another_env_interrupted_in_its_test_episodes_says_the_model_is_saved(tmp_path, monkeypatch, capsys):
    from sb3_dtdpg import cli as cli_module

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("stable_baselines3.common.evaluation.evaluate_policy", interrupted)
    args = ["train", "--algo", "ddpg", "--preset", "paper", "--env", "Pendulum-v1", "--timesteps", "200", "--no-progress"]
    args += ["--out", str(tmp_path)]
    assert cli_module.main(args) == 130
    message = capsys.readouterr().err  # was "finished runs are saved; run the same command again to resume"
    assert (
        message.strip() == f"interrupted in the test episodes: the trained model is in {tmp_path / 'ddpg_Pendulum-v1_s0.zip'}"
    )


def test_a_buffer_too_large_for_memory_is_one_error_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, printed = run_cli(
        ["train", "--algo", "dtdpg", "--scenario", "small", "--hyperparams", "buffer_size:2000000000"], capsys
    )
    assert_one_error_line(code, printed, "train", "not enough memory for this run")  # was a numpy traceback
    assert list(tmp_path.iterdir()) == []


def test_the_option_choices_are_the_libraries(monkeypatch):
    from noma_radiomap.registration import OBSERVATIONS
    from sb3_dtdpg.baselines import ALGORITHMS, DEFAULT_ENV_ID, HYPERPARAMS
    from sb3_dtdpg.experiments.reproduce import EXPERIMENTS

    assert cli_parser.ALGORITHMS == ALGORITHMS and cli_parser.OBSERVATIONS == OBSERVATIONS
    assert set(cli_parser.PRESETS) == set(HYPERPARAMS) and cli_parser.DEFAULT_ENV_ID == DEFAULT_ENV_ID
    assert cli_parser.EXPERIMENTS == EXPERIMENTS


def test_every_subcommand_of_the_parser_has_its_command():
    subcommands = next(a for a in cli_parser.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(cli._commands()) == set(subcommands.choices)  # else: a KeyError traceback for the one left out


def test_help_imports_neither_torch_nor_sb3():
    code = (
        "import sys, contextlib, io\n"
        "from sb3_dtdpg.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    main(['--help'])\n"
        "print(sorted(m for m in ('torch', 'stable_baselines3', 'noma_radiomap') if m in sys.modules))\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "envs"), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.strip() == "[]"


def test_subcommand_help_lists_the_budgets_when_shown(capsys):
    code, printed = run_cli(["compare", "--help"], capsys)
    assert code == 0
    assert "tiny:" in printed.out and "episodes on small" in " ".join(printed.out.split())


def test_overrides_reach_a_mission_run_and_name_it(tmp_path, capsys):
    from stable_baselines3 import DDPG

    from sb3_dtdpg.experiments.specs import RunSpec, run_identity

    args = ["train", "--algo", "ddpg", "--preset", "paper", "--scenario", "small", "--episodes", "2"]
    args += ["--hyperparams", "batch_size:16", "policy_kwargs:dict(net_arch=[8, 8])", "--eval-episodes", "1"]
    args += ["--no-progress", "--tb", str(tmp_path / "tb"), "--out", str(tmp_path)]
    assert main(args) == 0
    (run,) = (tmp_path / "runs").iterdir()
    assert run.name.startswith("ddpg_noma_s0_goal_hp")  # another run than the one without overrides
    model = DDPG.load(run / "model.zip")
    assert model.batch_size == 16 and model.policy.actor.mu[0].out_features == 8
    # Without overrides the identity is what it was before overrides existed: earlier results stay valid
    assert "overrides" not in run_identity(RunSpec("ddpg", "noma", 0, 2, scenario="small"))["spec"]


@pytest.mark.parametrize("folder", ["missing", "empty"])
def test_reproduce_report_only_without_finished_runs_creates_nothing(folder, tmp_path, capsys):
    from sb3_dtdpg.experiments.reproduce import reproduce_specs
    from sb3_dtdpg.experiments.runs import BUDGETS
    from sb3_dtdpg.experiments.storage import result_path

    out = tmp_path / "reproduce"
    if folder == "empty":
        out.mkdir()
    argv = ["reproduce", "--report-only", "--out", str(out), "--no-progress"]
    code, printed = run_cli(argv, capsys)
    assert_one_error_line(code, printed, "reproduce", f"--out: {out} holds no finished runs of this job")
    assert printed.out == "" and sorted(tmp_path.rglob("*")) == ([out] if folder == "empty" else [])
    # One finished run of the job is enough to draw the report from
    specs = [
        spec for group in reproduce_specs(BUDGETS["tiny"], BUDGETS["tiny"].seeds, "tuned", "goal").values() for spec in group
    ]
    result_path(out, specs[0]).parent.mkdir(parents=True)
    result_path(out, specs[0]).write_text("{}")
    args = cli.build_parser().parse_args(argv)
    args.hyperparams = "tuned"
    cli._check_finished_runs(args, specs)


def test_ctrl_c_of_a_command_without_runs_does_not_promise_a_resume(tmp_path, monkeypatch, capsys):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_cmd_map", interrupted)
    assert main(["map", "--scenario", "small", "--out", str(tmp_path)]) == 130
    message = capsys.readouterr().err  # was "finished runs are saved; run the same command again to resume"
    assert message.strip() == "interrupted: map stopped before its end (nothing to resume: run it again)"


def test_reproduces_hint_at_the_papers_scale_keeps_the_users_choices(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli, "_failed_runs_status", lambda args, job: 0)  # the hint alone, no runs
    base = ["reproduce", "--budget", "tiny", "--out", str(tmp_path), "--no-progress"]
    assert main([*base, "--preset", "paper", "--observation", "destinations"]) == 0
    assert "sb3-dtdpg reproduce --budget paper --preset paper --observation destinations --out <folder>" in (
        capsys.readouterr().out  # was without them: the tuned preset and goal observation at the paper's scale
    )
    assert main(base) == 0
    assert "sb3-dtdpg reproduce --budget paper --out <folder>" in capsys.readouterr().out
    assert main([*base, "--preset", "tuned"]) == 0  # the default set, but given: it picks the paper task's runs
    assert "sb3-dtdpg reproduce --budget paper --preset tuned --out <folder>" in capsys.readouterr().out


def test_train_on_another_env_keeps_an_earlier_model_and_tests_on_its_eval_seed(tmp_path, capsys):
    def train(out, eval_seed):
        argv = ["train", "--algo", "ddpg", "--preset", "paper", "--env", "Pendulum-v1", "--timesteps", "200"]
        argv += ["--eval-episodes", "2", "--eval-seed", str(eval_seed), "--no-progress", "--out", str(tmp_path / out)]
        code = main(argv)
        printed = capsys.readouterr()
        return code, printed, re.search(r"reward (\S+ ± \S+)", printed.out)

    first = train("a", 1)
    model = tmp_path / "a" / "ddpg_Pendulum-v1_s0.zip"
    saved = model.read_bytes()
    with pytest.raises(SystemExit):
        train("a", 1)  # was trained again, replacing the first model
    assert "--out " in capsys.readouterr().err and model.read_bytes() == saved
    same, other = train("b", 1), train("c", 999)
    assert first[0] == same[0] == other[0] == 0
    assert first[2].group(1) == same[2].group(1) != other[2].group(1)  # --eval-seed was ignored: one test either way
