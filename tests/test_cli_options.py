"""The ``sb3-dtdpg`` options: one-line user errors, help for every option, old spellings, any env id for train."""

import argparse
import importlib
import re
import sys
from importlib.metadata import version

import gymnasium as gym
import pytest
import torch as th

from sb3_dtdpg.cli import build_parser, main
from sb3_dtdpg.experiments.reproduce import DEFAULT_EXPERIMENTS, reproduce_specs
from sb3_dtdpg.experiments.runs import BUDGETS


def run_cli(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    return exit_info.value.code, capsys.readouterr()


def subcommands(parser):
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action.choices


def test_version_comes_from_the_package_metadata(capsys):
    import sb3_dtdpg

    code, printed = run_cli(["--version"], capsys)
    assert code == 0
    assert printed.out.strip() == f"sb3-dtdpg {version('sb3-dtdpg')}" == f"sb3-dtdpg {sb3_dtdpg.__version__}"


@pytest.fixture
def bad_yaml(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nroom: [1, 2\n")
    return str(path)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["map", "--scenario", "atlantis"], "scenario 'atlantis': unknown built-in name"),
        (["map", "--scenario", "BAD_YAML"], "broken.yaml"),
        (["train", "--algo", "ddpg", "--scenario", "atlantis"], "unknown built-in name"),
        (["compare", "--scenario", "BAD_YAML"], "broken.yaml"),
        (["train", "--algo", "ddpg", "--env", "NoSuchEnv-v0"], "'NoSuchEnv-v0' is not a registered env id"),
        (["train", "--algo", "ddpg", "--env", "Pendulum-v1", "--multiple-access", "oma"], "apply to the mission envs only"),
        (["train", "--algo", "td3", "--preset", "tuned"], "defined for 'dtdpg' and 'ddpg' only"),
        (["train", "--algo", "dtdpg", "--preset", "tuned", "--timesteps", "500"], "learning_starts=2000"),
        (["compare", "--env", "Pendulum-v1"], "compare runs on the NomaRadioMap envs"),
        (["compare", "--budget", "_micro", "--preset", "tuned"], "3 episodes of at most 60 steps"),
        (["compare", "--budget", "_micro"], "cannot train"),  # tuned is the default
        (["reproduce", "--budget", "_micro"], "cannot train: the first gradient step comes after learning_starts=2000"),
        (["compare", "--n-seeds", "two"], "expected a number of seeds from 1 to 1,000, got 'two'"),
        (["train", "--algo", "ddpg", "--tag", "../up"], "argument --tag: expected a name of letters, digits and ._+-"),
        (["train", "--algo", "ddpg", "--tag", "no curriculum"], "got 'no curriculum'"),
    ],
)
def test_user_errors_are_one_line_with_status_2(argv, message, bad_yaml, capsys):
    code, printed = run_cli([bad_yaml if a == "BAD_YAML" else a for a in argv], capsys)
    assert code == 2
    assert "Traceback" not in printed.err
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith(f"sb3-dtdpg {argv[0]}: error: ")
    assert message in errors[0]


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("seed:5", "seed (--hyperparams): set it with --seed, not as a hyperparameter"),
        ("verbose:2", "verbose (--hyperparams): set it with --verbose"),
        ("_init_setup_model:False", "unknown hyperparameter '_init_setup_model'"),
        ("policy_kwargs:'x'", "policy_kwargs (--hyperparams) must be a dict, e.g. dict(net_arch=[64, 64]), got 'x'"),
        ("device:'bogus'", "device (--hyperparams): torch knows no device 'bogus'"),
        ("learning_rate:'lin_0.001'", "learning_rate (--hyperparams) must be a positive finite number, got 'lin_0.001'"),
        ("gamma:5", "gamma must be a number in [0, 1], got 5"),
        ("phases:[]", "phases must hold at least one phase"),
        ("n_steps:100000000", "n_steps must be at most buffer_size (200000), got 100000000"),
        ("reinitialize_at_transfer:'no'", "reinitialize_at_transfer must be True or False, got 'no'"),
        ("batch_size:1", "batch_size must be at least 2 with batch normalisation (actor_norm or critic_norm 'batch'), got 1"),
        # the reward phases of the env are checked when the model is made (was: a traceback at the first learn())
        (
            "phases:[dict(name='dest', n_episodes=2), dict(name='mqi')]",
            "phase 'dest': reward_phase 'dest' is not a reward phase of the env ['destination', 'mqi', 'combined']",
        ),
    ],
)
def test_train_hyperparameters_the_model_refuses_are_one_line_and_create_nothing(override, message, tmp_path, capsys):
    # each was a traceback from inside the run (n_steps: a hang), after the output folder was made
    argv = ["train", "--algo", "dtdpg", "--scenario", "small", "--out", str(tmp_path / "out"), "--hyperparams", override]
    code, printed = run_cli(argv, capsys)
    assert code == 2 and "Traceback" not in printed.err
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and message in errors[0], printed.err
    assert not (tmp_path / "out").exists()


def test_the_seed_count_limit_is_the_jobs(capsys):
    from sb3_dtdpg.arguments import seed_count
    from sb3_dtdpg.experiments.budgets import MAX_SEEDS

    assert seed_count(str(MAX_SEEDS)) == MAX_SEEDS  # the CLI's bound is the job's
    code, printed = run_cli(["compare", "--n-seeds", str(10**11)], capsys)  # was 2 GB of run specs, then a hang
    assert code == 2 and f"expected a number of seeds from 1 to {MAX_SEEDS:,}, got '{10**11}'" in printed.err


def test_every_option_has_help():
    parser = build_parser()
    missing = []
    for name, sub in {"": parser, **subcommands(parser)}.items():
        for action in sub._actions:
            if action.help is None or (action.help == argparse.SUPPRESS and "deprecated" not in type(action).__name__.lower()):
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
    assert not missing


@pytest.mark.parametrize(
    ("old", "new", "dest", "value"),
    [
        (["compare", "--seeds", "2"], ["compare", "--n-seeds", "2"], "n_seeds", 2),
        (["reproduce", "--seeds", "2"], ["reproduce", "--n-seeds", "2"], "n_seeds", 2),
        (["compare", "--modes", "oma"], ["compare", "--multiple-access", "oma"], "multiple_access", ["oma"]),
    ],
)
def test_old_spellings_still_work_and_say_so(old, new, dest, value, capsys):
    assert getattr(build_parser().parse_args(new), dest) == value
    assert capsys.readouterr().err == ""
    assert getattr(build_parser().parse_args(old), dest) == value
    assert f"{old[1]} is deprecated, use {new[1]}" in capsys.readouterr().err


def test_out_is_a_folder_everywhere():
    for name, sub in subcommands(build_parser()).items():
        outs = [a for a in sub._actions if "--out" in a.option_strings]
        assert len(outs) == (0 if name in ("evaluate", "enjoy") else 1), name  # those two name their files
        assert all("folder" in out.help for out in outs), name
        if outs:  # an empty --out would write into the current folder
            with pytest.raises(SystemExit):
                sub.parse_args(["--out", ""])


def test_reproduce_defaults_to_a_budget_of_minutes():
    budget = BUDGETS[build_parser().parse_args(["reproduce"]).budget]
    experiments = reproduce_specs(budget, budget.seeds)
    specs = {s.run_id: s for name in DEFAULT_EXPERIMENTS for s in experiments[name]}
    # `small`: at most 60 steps an episode; the paper's task: 1000
    steps = sum(spec.episodes * (1000 if spec.env_id == "NomaRadioMapPaper-v0" else 60) for spec in specs.values())
    assert budget.scenario == "small" and steps <= 100_000, "at a few hundred steps/s per core, minutes"
    help_text = " ".join(subcommands(build_parser())["reproduce"].format_help().split())  # argparse wraps lines
    assert "--budget paper" in help_text


def test_train_works_with_any_registered_env(tmp_path, capsys):
    args = ["train", "--algo", "dtdpg", "--preset", "paper", "--env", "Pendulum-v1", "--timesteps", "300"]
    args += ["--eval-episodes", "1", "--no-progress"]
    assert main([*args, "--tb", str(tmp_path / "tb"), "--out", str(tmp_path / "models")]) == 0
    assert (tmp_path / "models" / "dtdpg_Pendulum-v1_s0.zip").exists()
    assert "dtdpg_Pendulum-v1_s0: 300 steps; test (1 episodes): reward" in capsys.readouterr().out


def test_train_on_a_mission_env_evaluates_on_its_last_reward_phase(tmp_path, capsys):
    args = ["train", "--algo", "ddpg", "--preset", "paper", "--env", "NomaRadioMapOMA-v0", "--scenario", "small"]
    args += ["--episodes", "2", "--eval-episodes", "1", "--no-progress", "--tb", str(tmp_path / "tb"), "--out", str(tmp_path)]
    assert main(args) == 0
    # the env id's own mode (OMA) when --multiple-access is not given, the goal-conditioned observation by default
    assert (tmp_path / "runs" / "ddpg_oma_s0_goal" / "model.zip").exists()
    assert "last reward phase 'combined'; test (1 Rayleigh episodes, 'combined' reward)" in capsys.readouterr().out


@pytest.mark.parametrize(("env_id", "observation"), [("NomaRadioMapPaperOMA-v0", "paper"), ("NomaRadioMapOMA-v0", "goal")])
def test_train_and_compare_default_to_the_env_ids_observation(env_id, observation, monkeypatch):
    from sb3_dtdpg import cli

    seen = {}
    monkeypatch.setattr(cli, "_train_mission", lambda args, *_: seen.setdefault("train", args.observation) and 0)
    monkeypatch.setattr(cli, "_run_compare", lambda args: seen.setdefault("compare", args.observation))
    assert main(["train", "--algo", "dtdpg", "--env", env_id, "--scenario", "small", "--episodes", "40"]) == 0
    assert main(["compare", "--env", env_id, "--budget", "smoke"]) == 0
    assert seen == {"train": observation, "compare": observation}  # what gymnasium.make(env_id) gives
    assert gym.make(env_id, scenario="small").unwrapped.observation == observation


def test_hyperparams_default_to_the_tuned_set_where_every_algorithm_has_it(capsys):
    train = ["train", "--episodes", "1", "--scenario", "small"]  # 60 steps: the budget check stops it before training
    code, printed = run_cli([*train, "--algo", "ddpg"], capsys)
    assert code == 2 and "learning_starts=2000" in printed.err  # tuned
    code, printed = run_cli([*train, "--algo", "td3"], capsys)
    assert code == 2 and "learning_starts=100" in printed.err  # TD3 has no tuned set: SB3's defaults, no error about it


@pytest.mark.parametrize("script", ["train", "enjoy"])
def test_zoo_scripts_without_the_zoo_extra_say_what_to_install(script, monkeypatch):
    monkeypatch.setitem(sys.modules, "rl_zoo3", None)  # as if rl_zoo3 were not installed
    monkeypatch.delitem(sys.modules, "sb3_dtdpg.zoo", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        importlib.import_module(f"sb3_dtdpg.{script}").main()
    message = str(exit_info.value.code)
    assert message.startswith(f"python -m sb3_dtdpg.{script}: error: ") and "\n" not in message
    # the package is installed from a clone, not from an index it is not on
    assert "'zoo' extra (rl_zoo3 is not installed)" in message and 'pip install -e ".[zoo]"' in message


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("nn.Tanh", th.nn.Tanh),
        ("th.nn.ReLU", th.nn.ReLU),
        ("torch.optim.RMSprop", th.optim.RMSprop),
        ("dict(net_arch=[64, 64], activation_fn=nn.Tanh)", {"net_arch": [64, 64], "activation_fn": th.nn.Tanh}),
        ("{'optimizer_class': th.optim.Adam, 'x': (1,)}", {"optimizer_class": th.optim.Adam, "x": (1,)}),
    ],
)
def test_hyperparameter_values_name_torch_classes_as_the_zoo_writes_them(text, expected):
    from sb3_dtdpg.overrides import override_text, parse_value

    value = parse_value(text)
    assert value == expected
    assert parse_value(override_text(value)) == value  # the text a run's spec stores reads back to the value


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("nn.Tanhh", "torch.nn has no Module class 'Tanhh'; did you mean 'Tanh'"),
        ("nn.functional", "torch.nn has no Module class 'functional'"),
        ("os.system", "'os.system' is not a literal; the names a value may hold are torch's"),
        ("dict(activation_fn=nn.ReLU())", "is not a Python literal"),
    ],
)
def test_a_name_that_is_not_a_torch_class_is_refused(text, message):
    from sb3_dtdpg.overrides import HyperparameterError, parse_value

    with pytest.raises(HyperparameterError, match=re.escape(message)):
        parse_value(text)


@pytest.mark.parametrize(
    "value", [3e-4, [64, 64], {"net_arch": [64, 64]}, {"pi": [8], "qf": [8]}, (1,), (), "relabel", None, True, {}]
)
def test_the_text_of_a_value_without_classes_is_its_repr(value):
    """Run ids hash the overrides' text: runs stored before classes were allowed keep their ids."""
    from sb3_dtdpg.overrides import override_text

    assert override_text(value) == repr(value)


@pytest.mark.parametrize("algo", ["dtdpg", "ddpg", "td3", "sac", "tqc"])
def test_a_net_arch_dict_of_tuples_is_taken_as_sb3_takes_it(algo):
    from sb3_dtdpg.baselines import algorithm_class, make_model
    from sb3_dtdpg.overrides import HyperparameterError, check_constructor_kwargs

    policy_kwargs = {"net_arch": {"pi": (8, 8), "qf": (16,)}}
    check_constructor_kwargs(algorithm_class(algo), {"policy_kwargs": policy_kwargs}, "")
    model = make_model(algo, gym.make("Pendulum-v1"), policy_kwargs=policy_kwargs, learning_starts=10)
    assert model.policy.actor is not None  # built: SB3's create_mlp takes tuples inside a dict
    with pytest.raises(HyperparameterError, match=r"a list of layer sizes or a dict of them, got \(8, 8\)"):
        check_constructor_kwargs(algorithm_class(algo), {"policy_kwargs": {"net_arch": (8, 8)}}, "")  # SB3 asserts


def test_curriculum_save_path_is_a_hyperparameter_of_train_on_other_envs_only(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, printed = run_cli(["train", "--algo", "dtdpg", "--hyperparams", "curriculum_save_path:'P'"], capsys)
    assert code == 2 and "curriculum_save_path (--hyperparams): set it with --out" in printed.err  # a mission run's
    argv = ["train", "--algo", "dtdpg", "--env", "Pendulum-v1", "--timesteps", "200", "--out", "O", "--no-progress"]
    assert main([*argv, "--eval-episodes", "1", "--hyperparams", "curriculum_save_path:'P'", "learning_starts:100"]) == 0
    assert sorted(p.name for p in (tmp_path / "P").iterdir()) == ["phase_0_train.zip"]  # the phase saved where asked
