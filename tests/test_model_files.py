"""``sb3-dtdpg evaluate`` / ``enjoy`` on model files that are not what they seem: a policy alone, NaN weights, a
retired room, the RL Zoo's observation statistics, an output file that is the scenario file read."""

import json
import pickle
import shutil
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import noma_radiomap
from sb3_dtdpg import DTDPG
from sb3_dtdpg.cli import main
from sb3_dtdpg.env_settings import RETIRED_BUILTINS, scenario_digest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _agg_backend(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


@pytest.fixture(scope="module")
def small_model(tmp_path_factory):
    """A random-init DT-DPG on `small`, saved as it is."""
    path = tmp_path_factory.mktemp("model") / "dtdpg.zip"
    DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario="small"), seed=0).save(path)
    return path


def refused(argv):
    """:return: the exit status of the command, which must end with an error"""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    return exit_info.value.code


def one_error_line(code, printed, *parts):
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert code == 2 and "Traceback" not in printed.err and len(errors) == 1, printed.err
    for part in parts:
        assert part in errors[0], errors[0]
    return errors[0]


def test_a_policy_alone_or_a_zip_without_its_policy_is_no_model(small_model, tmp_path, capsys):
    policy_only = tmp_path / "policy.zip"
    DTDPG.load(small_model).policy.save(policy_only)
    for algo in ([], ["--algo", "dtdpg"]):  # the second was an AssertionError traceback
        code = refused(["evaluate", str(policy_only), *algo, "--n-episodes", "1"])
        one_error_line(code, capsys.readouterr(), str(policy_only), "not a Stable-Baselines3 model file", "no 'data'")
    repacked = tmp_path / "repacked.zip"
    with zipfile.ZipFile(small_model) as source, zipfile.ZipFile(repacked, "w") as target:
        for item in source.infolist():
            if item.filename != "policy.pth":
                target.writestr(item, source.read(item))
    code = refused(["evaluate", str(repacked), "--n-episodes", "1"])  # was a KeyError traceback
    one_error_line(code, capsys.readouterr(), "no 'policy.pth'")


@pytest.mark.parametrize("command", [["evaluate", "--n-episodes", "1"], ["enjoy"]])
def test_a_model_with_nan_weights_is_one_error_line_naming_them(small_model, tmp_path, capsys, command):
    model = DTDPG.load(small_model)
    with torch.no_grad():
        for parameter in model.actor.parameters():
            parameter.fill_(float("nan"))
    broken = tmp_path / "nan.zip"
    model.save(broken)
    code = refused([command[0], str(broken), *command[1:]])  # enjoy was a traceback about the env's actions
    more = f" and {len(list(model.actor.parameters())) - 3} more: "  # the first three named, then a count
    one_error_line(code, capsys.readouterr(), "holds non-finite weights (NaN or inf) in actor.", more, "training diverged")


def test_a_model_of_a_retired_room_without_its_file_is_told_the_kept_file(tmp_path, capsys):
    kept = "benchmarks/rooms/mall_2026-12-03.yaml"
    room = ROOT / kept
    assert RETIRED_BUILTINS[scenario_digest(noma_radiomap.load_scenario(str(room)))] == kept
    path = tmp_path / "model.zip"
    DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario=str(room)), seed=0).save(path)
    model = DTDPG.load(path)
    model.env_settings = {**model.env_settings, "scenario_file": None}  # as a model of the built-in recorded them
    model.save(path)
    code = refused(["evaluate", str(path), "--n-episodes", "1"])  # was "a scenario 'mall' of its own"
    one_error_line(code, capsys.readouterr(), "before its recalibration", f"give --scenario {kept}")


def test_the_scenario_file_of_the_test_env_is_no_output(tmp_path, capsys):
    # A scenario file may be JSON (YAML reads it): evaluate --json over it destroyed the room the model needs
    room = tmp_path / "room.json"
    room.write_text(json.dumps({**noma_radiomap.load_scenario("small").to_dict(), "name": "room"}))
    path = tmp_path / "model.zip"
    DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario=str(room)), seed=0).save(path)
    content = room.read_bytes()
    code = refused(["evaluate", str(path), "--n-episodes", "1", "--json", str(room)])
    one_error_line(code, capsys.readouterr(), f"--json {room}: that is the scenario file of the test env")
    assert room.read_bytes() == content


def test_a_zoo_model_trained_on_normalized_observations_is_tested_on_them(small_model, tmp_path, capsys):
    # The RL Zoo's layout: logs/<algo>/<env id>_<n>/<env id>.zip and <env id>/vecnormalize.pkl
    run = tmp_path / "dtdpg" / "NomaRadioMap-v0_1"
    (run / "NomaRadioMap-v0").mkdir(parents=True)
    shutil.copy(small_model, run / "NomaRadioMap-v0.zip")
    statistics = VecNormalize(DummyVecEnv([lambda: gym.make("NomaRadioMap-v0", scenario="small")]), norm_reward=False)
    statistics.obs_rms.mean = np.linspace(-1.0, 1.0, statistics.observation_space.shape[0])
    statistics.obs_rms.var = np.full(statistics.observation_space.shape[0], 0.01)
    statistics.save(run / "NomaRadioMap-v0" / "vecnormalize.pkl")

    from sb3_dtdpg.model_files import read_saved_model

    saved = read_saved_model(run / "NomaRadioMap-v0.zip")
    raw = gym.make("NomaRadioMap-v0", scenario="small")
    seen = saved.observations_as_trained(gym.make("NomaRadioMap-v0", scenario="small"))
    expected = statistics.normalize_obs(raw.reset(seed=3)[0])
    np.testing.assert_array_equal(seen.reset(seed=3)[0], expected)
    assert np.abs(expected - raw.reset(seed=3)[0]).max() > 1.0  # the statistics matter

    out = tmp_path / "result.json"
    assert main(["evaluate", str(run / "NomaRadioMap-v0.zip"), "--n-episodes", "1", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["settings"]["observation_statistics"] == str(
        run / "NomaRadioMap-v0" / "vecnormalize.pkl"
    )
    capsys.readouterr()
    (run / "NomaRadioMap-v0" / "vecnormalize.pkl").write_bytes(pickle.dumps([1, 2]))
    code = refused(["evaluate", str(run / "NomaRadioMap-v0.zip"), "--n-episodes", "1"])
    one_error_line(code, capsys.readouterr(), "not the RL Zoo's VecNormalize statistics of a flat observation")


def test_a_model_recording_no_settings_is_tested_on_the_defaults_with_a_warning(tmp_path, capsys):
    from stable_baselines3 import DDPG

    bare = tmp_path / "bare.zip"  # SB3's own save: nothing but the observation length tells what it trained on
    DDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario="small"), learning_starts=10).save(bare)
    assert main(["evaluate", str(bare), "--algo", "ddpg", "--n-episodes", "1"]) == 0
    err = capsys.readouterr().err
    assert "warning: the model" in err and "records no env settings" in err
    assert "give --scenario and --multiple-access if it was trained on others" in err
    given = ["--scenario", "small", "--multiple-access", "noma"]
    assert main(["evaluate", str(bare), "--algo", "ddpg", "--n-episodes", "1", *given]) == 0
    assert "warning" not in capsys.readouterr().err
