"""``python -m sb3_dtdpg.enjoy`` refuses a model on an env of other settings than it was trained with."""

import sys

import gymnasium as gym
import pytest
import yaml
from stable_baselines3 import DDPG

from sb3_dtdpg import DTDPG
from sb3_dtdpg.env_settings import record

pytest.importorskip("rl_zoo3")
ENV_ID = "NomaRadioMap-v0"


@pytest.fixture(scope="module")
def zoo_logs(tmp_path_factory):
    """A zoo log folder as ``python -m sb3_dtdpg.train --algo A --env NomaRadioMap-v0 --env-kwargs scenario:"'small'"``
    leaves it (run 1 of each algorithm; models untrained, their settings recorded as the zoo's runs record them)."""
    logs = tmp_path_factory.mktemp("logs")
    for algo, algo_class in (("dtdpg", DTDPG), ("ddpg", DDPG)):
        run = logs / algo / f"{ENV_ID}_1"
        (run / ENV_ID).mkdir(parents=True)
        model = algo_class("MlpPolicy", gym.make(ENV_ID, scenario="small"), buffer_size=1000, seed=0)
        record(model)
        model.save(run / f"{ENV_ID}.zip")
        (run / ENV_ID / "args.yml").write_text(yaml.safe_dump({"env_kwargs": {"scenario": "small"}}))
    return logs


def zoo_enjoy(monkeypatch, logs, algo, *env_kwargs):
    """Run ``python -m sb3_dtdpg.enjoy`` in this process on a few steps of run 1 of ``algo``."""
    import rl_zoo3.enjoy

    from sb3_dtdpg.enjoy import main

    argv = ["enjoy", "--algo", algo, "--env", ENV_ID, "-f", str(logs), "-n", "5", "--no-render", "--exp-id", "1"]
    monkeypatch.setattr(sys, "argv", [*argv, *(["--env-kwargs", *env_kwargs] if env_kwargs else [])])
    algos, create_test_env = rl_zoo3.enjoy.ALGOS, rl_zoo3.enjoy.create_test_env
    try:
        main()
    finally:  # the zoo's module is as it was
        assert (rl_zoo3.enjoy.ALGOS, rl_zoo3.enjoy.create_test_env) == (algos, create_test_env)


@pytest.mark.parametrize("algo", ["dtdpg", "ddpg"])
@pytest.mark.parametrize(
    ("env_kwargs", "named"),
    [
        (["multiple_access:'oma'"], "multiple_access='noma' (the env has 'oma')"),  # was: run on OMA, exit 0
        (["scenario:'mall'"], "scenario='small' (the env has 'mall')"),
        (["observation:'paper'"], "observation='goal' (the env has 'paper')"),
    ],
    ids=["multiple_access", "scenario", "observation"],
)
def test_zoo_enjoy_refuses_an_env_of_other_settings(zoo_logs, monkeypatch, capsys, algo, env_kwargs, named):
    with pytest.raises(SystemExit) as exit_info:
        zoo_enjoy(monkeypatch, zoo_logs, algo, *env_kwargs)
    printed = capsys.readouterr()
    assert exit_info.value.code == 2 and "Traceback" not in printed.err
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    model = zoo_logs / algo / f"{ENV_ID}_1" / f"{ENV_ID}.zip"
    assert len(errors) == 1 and errors[0].startswith(f"python -m sb3_dtdpg.enjoy: error: the model {model} was trained with")
    assert named in errors[0] and "Episode Reward" not in printed.out


@pytest.mark.parametrize("env_kwargs", [[], ["scenario:'small'", "multiple_access:'noma'"]], ids=["its_own", "the_same"])
def test_zoo_enjoy_runs_a_model_on_its_own_settings(zoo_logs, monkeypatch, capsys, env_kwargs):
    zoo_enjoy(monkeypatch, zoo_logs, "dtdpg", *env_kwargs)
    printed = capsys.readouterr()
    assert ": error: " not in printed.err and f"Loading {zoo_logs}" in printed.out


@pytest.mark.parametrize(
    ("env_kwargs", "named"),
    [
        (["scenario:'nosuch'"], "'nosuch'"),  # was: a ValueError traceback, exit 1
        (["observaton:'goal'"], "observaton"),  # was: a TypeError traceback (an unexpected keyword argument)
    ],
    ids=["unknown_value", "unknown_keyword"],
)
def test_zoo_enjoy_env_kwargs_the_env_cannot_take_are_one_error_line(zoo_logs, monkeypatch, capsys, env_kwargs, named):
    with pytest.raises(SystemExit) as exit_info:
        zoo_enjoy(monkeypatch, zoo_logs, "dtdpg", *env_kwargs)
    printed = capsys.readouterr()
    assert exit_info.value.code == 2 and "Traceback" not in printed.err
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith(f"python -m sb3_dtdpg.enjoy: error: env {ENV_ID} with env_kwargs {{")
    assert "(--env-kwargs or the run's args.yml)" in errors[0] and named in errors[0]
