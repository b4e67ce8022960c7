"""A saved model records its env settings; ``sb3-dtdpg evaluate`` and ``enjoy --record`` use them."""

import json
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from PIL import Image
from stable_baselines3 import DDPG

import noma_radiomap
from sb3_dtdpg import DTDPG
from sb3_dtdpg.cli import main
from sb3_dtdpg.env_settings import EnvSettingsMismatch, record, scenario_digest, settings_of
from sb3_dtdpg.vec_env import make_mission_vec_env


@pytest.fixture(autouse=True)
def _agg_backend(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


def small_env(**kwargs):
    return gym.make("NomaRadioMap-v0", scenario="small", **kwargs)


@pytest.fixture(scope="module")
def saved_dtdpg(tmp_path_factory):
    """A random-init DT-DPG on `small`, goal observation, NOMA, saved as it is."""
    path = tmp_path_factory.mktemp("model") / "dtdpg.zip"
    DTDPG("MlpPolicy", small_env(observation="goal"), seed=0).save(path)
    return path


def test_settings_of_the_envs():
    assert settings_of(small_env(observation="goal", multiple_access="oma")) == {
        "scenario": "small",
        "observation": "goal",
        "multiple_access": "oma",
        "channel": "radio_map",
        "task": "missions",
        "power_mapping": "paper",
        "scenario_digest": scenario_digest(noma_radiomap.load_scenario("small")),
        "scenario_file": None,  # a built-in scenario: no file of its own
    }
    assert settings_of(small_env(observation="paper"))["observation"] == "paper"
    assert settings_of(small_env(power_mapping="shares"))["power_mapping"] == "shares"
    vec = make_mission_vec_env("NomaRadioMap-v0", n_envs=2, seed=0, env_kwargs={"scenario": "small", "observation": "goal"})
    assert settings_of(vec)["observation"] == "goal" and settings_of(vec)["scenario"] == "small"
    assert settings_of(gym.make("Pendulum-v1")) is None


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"observation": "paper"}, "observation='goal'"),
        ({"observation": "goal", "multiple_access": "oma"}, "multiple_access='noma'"),
        ({"observation": "goal", "power_mapping": "shares"}, "power_mapping='paper'"),
    ],
)
def test_a_mismatched_env_is_refused_with_the_settings_to_use(saved_dtdpg, kwargs, named):
    with pytest.raises(EnvSettingsMismatch, match=named) as error:
        DTDPG.load(saved_dtdpg, env=small_env(**kwargs))
    assert "observation='goal', multiple_access='noma'" in str(error.value)  # the gym.make call that fits
    assert "(sb3-dtdpg: --scenario small --observation goal --multiple-access noma)" in str(
        error.value
    )  # was without --scenario
    model = DTDPG.load(saved_dtdpg)
    with pytest.raises(EnvSettingsMismatch, match=named):
        model.set_env(small_env(**kwargs))


def test_set_env_refuses_a_mismatched_env_for_a_model_never_saved():
    model = DTDPG("MlpPolicy", small_env(observation="goal"), buffer_size=100, seed=0)
    with pytest.raises(EnvSettingsMismatch, match="multiple_access='noma'"):
        model.set_env(small_env(observation="goal", multiple_access="oma"))
    assert model.get_env().get_attr("multiple_access") == ["noma"]  # kept
    model.set_env(small_env(observation="goal", channel="rayleigh"))  # the channel is not checked


def test_a_matching_env_loads_also_with_another_test_channel(saved_dtdpg):
    model = DTDPG.load(saved_dtdpg, env=small_env(observation="goal", channel="rayleigh"))
    assert model.env_settings["channel"] == "radio_map"  # recorded, not checked: test with fading


def test_record_works_for_any_sb3_model(tmp_path):
    model = DDPG("MlpPolicy", small_env(observation="goal", multiple_access="oma"), learning_starts=10)
    record(model)
    model.save(tmp_path / "ddpg.zip")
    assert DDPG.load(tmp_path / "ddpg.zip").env_settings["multiple_access"] == "oma"


def test_a_relative_goal_wrapper_is_recorded_as_the_features_it_makes(tmp_path, capsys):
    from noma_radiomap.wrappers import RelativeGoalObservation

    # on "destinations" at the default 10 m the wrapper makes exactly the "goal" layout: recorded as it
    assert settings_of(RelativeGoalObservation(small_env(observation="destinations")))["observation"] == "goal"
    # at another scale (same length as "goal", other values) or on another layout it is recorded as the wrapper
    scaled = RelativeGoalObservation(small_env(observation="destinations"), distance_scale=4.0)
    recorded = "destinations+RelativeGoalObservation(distance_scale=4.0)"
    assert settings_of(scaled)["observation"] == recorded
    assert settings_of(RelativeGoalObservation(small_env(observation="paper")))["observation"] == (
        "paper+RelativeGoalObservation(distance_scale=10.0)"
    )
    DTDPG("MlpPolicy", scaled, seed=0).save(tmp_path / "scaled.zip")
    DTDPG.load(tmp_path / "scaled.zip", env=RelativeGoalObservation(small_env(observation="destinations"), 4.0))
    with pytest.raises(EnvSettingsMismatch, match=re.escape(f"observation='{recorded}' (the env has 'goal')")) as error:
        DTDPG.load(tmp_path / "scaled.zip", env=small_env(observation="goal"))  # was loaded: "goal" recorded
    assert "RelativeGoalObservation(distance_scale=4.0, env=gym.make(" in str(error.value)
    assert "observation='destinations'" in str(error.value)
    # a model saved before: "goal" recorded for any wrapped layout; refused on the wrapped env, with the way out
    old = DTDPG.load(tmp_path / "scaled.zip", custom_objects={"env_settings": {**settings_of(scaled), "observation": "goal"}})
    old.save(tmp_path / "old.zip")
    with pytest.raises(EnvSettingsMismatch, match=re.escape("custom_objects={'env_settings': None}")):
        DTDPG.load(tmp_path / "old.zip", env=scaled)
    DTDPG.load(tmp_path / "old.zip", env=scaled, custom_objects={"env_settings": None})
    code, output = run_cli(["evaluate", str(tmp_path / "scaled.zip"), "--n-episodes", "1"], capsys)
    assert code == 2 and "trained on observations of a wrapper" in output.err and recorded in output.err


def run_cli(argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    return exit_info.value.code, capsys.readouterr()


def test_evaluate_prints_the_compare_table_and_writes_json_and_csv(saved_dtdpg, tmp_path, capsys):
    out_json, out_csv = tmp_path / "eval.json", tmp_path / "eval.csv"
    assert main(["evaluate", str(saved_dtdpg), "--n-episodes", "3", "--json", str(out_json), "--csv", str(out_csv)]) == 0
    printed = capsys.readouterr().out
    assert "DT-DPG" in printed and "Success (%)" in printed and "3 episodes" in printed
    assert re.search(r"│\s+0\s+│", printed)  # the Train steps cell: this model never trained

    def no_nan(constant):  # strict JSON readers (jq, JavaScript) refuse NaN and Infinity
        raise AssertionError(f"{constant} in {out_json}")

    document = json.loads(out_json.read_text(), parse_constant=no_nan)
    assert document["settings"]["scenario"] == "small" and document["settings"]["observation"] == "goal"
    assert document["summary"]["n_episodes"] == 3 and len(document["episodes"]) == 3
    episodes = pd.read_csv(out_csv)
    assert list(episodes["seed"]) == [10_000, 10_001, 10_002]  # the test missions of compare
    assert np.isclose(episodes["mqi"].mean(), document["summary"]["mqi"])


def test_evaluate_refuses_a_mismatched_override(saved_dtdpg, capsys):
    code, printed = run_cli(["evaluate", str(saved_dtdpg), "--multiple-access", "oma"], capsys)
    assert code == 2 and "Traceback" not in printed.err
    assert "sb3-dtdpg evaluate: error: " in printed.err and "--multiple-access noma" in printed.err


def test_evaluate_a_missing_model_is_a_user_error(tmp_path, capsys):
    code, printed = run_cli(["evaluate", str(tmp_path / "nope.zip")], capsys)
    assert code == 2 and "no such model file" in printed.err


def test_enjoy_records_a_viewable_gif(saved_dtdpg, tmp_path, capsys):
    gif = tmp_path / "mission.gif"
    assert main(["enjoy", str(saved_dtdpg), "--record", str(gif), "--max-frames", "6"]) == 0
    assert "mission (seed 10000, small, NOMA, rayleigh)" in capsys.readouterr().out
    with Image.open(gif) as image:
        assert image.format == "GIF" and image.n_frames == 6
        image.seek(image.n_frames - 1)
        frame = np.asarray(image.convert("RGB"))
    assert frame.shape[0] > 200 and frame.shape[1] > 400
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 20  # a drawn map, not a blank canvas


def test_enjoy_refuses_another_suffix(saved_dtdpg, tmp_path, capsys):
    code, printed = run_cli(["enjoy", str(saved_dtdpg), "--record", str(tmp_path / "m.avi")], capsys)
    assert code == 2 and "expected a .gif or .mp4 file" in printed.err


@pytest.mark.parametrize(
    "options",
    [["--json", "{file}/eval.json"], ["--csv", "{file}/sub/eval.csv"], ["--env", "Pendulum-v1"]],
    ids=["json_under_a_file", "csv_under_a_file", "env_without_missions"],
)
@pytest.mark.parametrize("command", ["evaluate", "enjoy"])
def test_evaluate_and_enjoy_refuse_bad_outputs_and_envs_before_running(saved_dtdpg, tmp_path, capsys, command, options):
    if command == "enjoy" and options[0] != "--env":
        options = ["--record", options[1].replace(".json", ".gif").replace(".csv", ".gif")]
    file = tmp_path / "results"
    file.write_text("kept")
    code, printed = run_cli([command, str(saved_dtdpg), *(o.format(file=file) for o in options)], capsys)
    assert code == 2 and "Traceback" not in printed.err and printed.out == ""
    expected = "runs the NomaRadioMap test missions, got Pendulum-v1" if options[0] == "--env" else f"{str(file)!r} is a file"
    assert f"sb3-dtdpg {command}: error: " in printed.err and expected in printed.err
    assert file.read_text() == "kept"


def test_evaluate_of_a_model_of_another_env_says_it_records_no_mission_settings(tmp_path, capsys):
    from stable_baselines3 import DDPG

    DDPG("MlpPolicy", "Pendulum-v1").save(tmp_path / "pendulum.zip")
    code, printed = run_cli(["evaluate", str(tmp_path / "pendulum.zip")], capsys)
    assert code == 2 and "Traceback" not in printed.err
    assert "Observation spaces do not match" in printed.err and "records no NomaRadioMap settings" in printed.err


def test_settings_of_a_model_without_a_record_come_from_its_run_or_its_observation_length(tmp_path):
    from sb3_dtdpg.model_files import read_saved_model

    run = tmp_path / "runs" / "ddpg_oma_s0_goal"
    run.mkdir(parents=True)
    DDPG("MlpPolicy", small_env(observation="goal", multiple_access="oma"), learning_starts=10).save(run / "model.zip")
    spec = {"algo": "ddpg", "scenario": "small", "observation": "goal", "multiple_access": "oma", "env_id": "NomaRadioMap-v0"}
    (run / "result.json").write_text(json.dumps({"spec": spec}))
    saved = read_saved_model(run)  # a run folder: its model.zip and result.json
    assert saved.algo == "ddpg" and saved.source.endswith("result.json")
    assert (saved.settings["multiple_access"], saved.settings["observation"]) == ("oma", "goal")
    with pytest.raises(EnvSettingsMismatch, match="multiple_access='oma'"):
        saved.load(small_env(observation="goal"))

    bare = tmp_path / "bare.zip"
    DDPG("MlpPolicy", gym.make("NomaRadioMap-v0", observation="paper"), learning_starts=10).save(bare)
    saved = read_saved_model(bare, algo="ddpg")
    assert saved.settings == {"observation": "paper"} and saved.source == "the observation length"  # 3 x 2 robots


def test_the_test_env_of_a_saved_model_has_its_settings_and_the_overrides(saved_dtdpg):
    from sb3_dtdpg.model_files import read_saved_model

    saved = read_saved_model(saved_dtdpg)
    kwargs = saved.env_kwargs("rayleigh")
    assert kwargs == {
        "channel": "rayleigh",
        "scenario": "small",
        "observation": "goal",
        "multiple_access": "noma",
        "task": "missions",
        "power_mapping": "paper",
    }
    env = gym.make("NomaRadioMap-v0", **kwargs)
    assert saved.load(env).env_settings["scenario"] == "small"  # the recorded settings fit
    # An override replaces its setting, None keeps the recorded one
    assert saved.env_kwargs("radio_map", multiple_access="oma", scenario=None) == {
        **kwargs,
        "channel": "radio_map",
        "multiple_access": "oma",
    }


def test_evaluate_is_quiet_about_a_model_saved_with_verbose_on(tmp_path, capsys):
    path = tmp_path / "verbose.zip"
    DTDPG("MlpPolicy", small_env(observation="goal"), seed=0, verbose=1).save(path)  # as the RL Zoo saves its models
    capsys.readouterr()
    assert main(["evaluate", str(path), "--n-episodes", "1"]) == 0
    printed = capsys.readouterr().out
    assert "Wrapping the env" not in printed and "1 episode" in printed


@pytest.mark.parametrize(("algo", "label"), [("ddpg", "DDPG"), ("td3", "TD3")])
def test_sb3_models_load_as_their_algorithm_without_warnings(algo, label, tmp_path, capsys):
    import warnings

    from stable_baselines3 import TD3
    from stable_baselines3.common.buffers import NStepReplayBuffer

    from sb3_dtdpg.model_files import read_saved_model

    path = tmp_path / f"{algo}.zip"
    (DDPG if algo == "ddpg" else TD3)("MlpPolicy", small_env(observation="goal"), n_steps=3, seed=0).save(path)
    saved = read_saved_model(path)
    assert saved.algo == algo  # both have a TD3 policy; DDPG is TD3 without delay and target noise
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # SB3 warns "n_steps=3 is ignored" when its own n-step buffer comes back
        model = saved.load(small_env(observation="goal"))
    assert isinstance(model.replay_buffer, NStepReplayBuffer) and model.replay_buffer.n_steps == 3
    assert main(["evaluate", str(path), "--n-episodes", "1"]) == 0
    assert f"│ {label} " in capsys.readouterr().out


@pytest.fixture
def run_folder(saved_dtdpg, tmp_path):
    """A run folder as train/compare write it: ``<out>/runs/<run id>/`` with ``model.zip`` and ``result.json``."""
    import shutil

    run = tmp_path / "out" / "runs" / "dtdpg_noma_s0"
    run.mkdir(parents=True)
    shutil.copy(saved_dtdpg, run / "model.zip")
    spec = {
        "algo": "dtdpg",
        "scenario": "small",
        "observation": "goal",
        "multiple_access": "noma",
        "env_id": "NomaRadioMap-v0",
    }
    (run / "result.json").write_text(json.dumps({"identity": {"spec": spec}, "spec": spec}))
    return run


def assert_one_error_line(code, printed, command, *parts):
    assert code == 2 and "Traceback" not in printed.err and printed.out == ""  # refused before anything ran
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith(f"sb3-dtdpg {command}: error: "), printed.err
    for part in parts:
        assert part in errors[0], errors[0]


@pytest.mark.parametrize(
    ("option", "name"),
    [("--json", "result.json"), ("--json", "checkpoint.json"), ("--json", "failed.json"), ("--json", "progress.json")],
)
def test_evaluate_refuses_to_write_over_its_runs_records(run_folder, capsys, option, name):
    target = run_folder / name
    if not target.exists():
        target.write_text('{"kept": true}')
    stored = {path.name: path.read_bytes() for path in run_folder.iterdir()}
    code, printed = run_cli(["evaluate", str(run_folder / "model.zip"), option, str(target)], capsys)
    assert_one_error_line(code, printed, "evaluate", f"{option} {target}: {name} is a record of the run folder")
    assert {path.name: path.read_bytes() for path in run_folder.iterdir()} == stored


def test_evaluate_refuses_to_write_over_another_runs_record(run_folder, tmp_path, capsys):
    import shutil

    other = tmp_path / "copy" / "runs" / run_folder.name
    shutil.copytree(run_folder, other)
    stored = (other / "result.json").read_bytes()
    code, printed = run_cli(["evaluate", str(run_folder / "model.zip"), "--json", str(other / "result.json")], capsys)
    assert_one_error_line(code, printed, "evaluate", "result.json is a record of the run folder")  # was replaced
    assert (other / "result.json").read_bytes() == stored


def test_evaluate_and_enjoy_refuse_to_write_over_the_model_itself(saved_dtdpg, tmp_path, capsys):
    import shutil

    for command, option, name in [
        ("evaluate", "--csv", "model.csv"),
        ("evaluate", "--json", "m.json"),
        ("enjoy", "--record", "m.gif"),
    ]:
        model = tmp_path / name  # a model zip under another suffix: SB3 loads it all the same
        shutil.copy(saved_dtdpg, model)
        code, printed = run_cli([command, str(model), option, str(model)], capsys)
        assert_one_error_line(code, printed, command, f"{option} {model}: that is the model file itself")
        assert model.read_bytes() == saved_dtdpg.read_bytes()


def test_the_run_records_are_the_ones_storage_writes(tmp_path):
    from sb3_dtdpg.experiments import storage
    from sb3_dtdpg.experiments.specs import RunSpec
    from sb3_dtdpg.model_files import RUN_RECORDS

    spec = RunSpec("dtdpg", "noma", 0, 2, scenario="small")
    for path in (
        storage.result_path(tmp_path, spec),
        storage.progress_path(tmp_path, spec),
        storage.failure_path(tmp_path, spec),
    ):
        assert path.name in RUN_RECORDS
    assert {"checkpoint.json", "model.zip", "replay_buffer.pkl"} <= set(RUN_RECORDS)  # storage.save_checkpoint's


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac", "tqc"])
def test_an_algo_contradicting_the_model_is_refused(saved_dtdpg, run_folder, capsys, algo):
    code, printed = run_cli(["evaluate", str(saved_dtdpg), "--algo", algo], capsys)
    expected = f"--algo {algo}: the model {saved_dtdpg} is a dtdpg model (its policy class is DTDPGPolicy)"
    assert_one_error_line(code, printed, "evaluate", expected, "give --algo dtdpg")
    code, printed = run_cli(["enjoy", str(run_folder / "model.zip"), "--algo", algo], capsys)
    recorded = f"({run_folder / 'result.json'} records algo 'dtdpg')"
    assert_one_error_line(code, printed, "enjoy", f"--algo {algo}: the model", recorded)


def test_an_algo_of_the_policy_family_is_honoured(tmp_path):
    from sb3_dtdpg.model_files import read_saved_model

    path = tmp_path / "ddpg.zip"
    DDPG("MlpPolicy", small_env(observation="goal"), learning_starts=10).save(path)
    assert read_saved_model(path).algo == "ddpg"
    assert read_saved_model(path, algo="td3").algo == "td3"  # SB3's DDPG is a TD3: asked for, it loads as one
    with pytest.raises(ValueError, match=r"--algo dtdpg: the model .* is a ddpg model"):
        read_saved_model(path, algo="dtdpg")


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ('{"spec": {"algo": "dtdpg",\n', "is unreadable (JSONDecodeError: Expecting"),
        ("\n", "is unreadable (JSONDecodeError: Expecting value: line 2 column 1"),
        ("[1, 2]", "is a JSON list, not an object"),
        ('{"spec": "dtdpg"}', "has a spec that is a JSON str, not an object"),
        ('{"spec": {"scenario": 3}}', "has spec.scenario = 3, expected a string"),
        ('{"spec": {"algo": "ppo"}}', "has spec.algo = 'ppo', expected one of dtdpg"),
        ('{"spec": {"env_id": "Nope-v0"}}', "has spec.env_id = 'Nope-v0', not a registered env id"),
        ('{"spec": {"algo": "sac"}}', "records algo 'sac', but the model"),
        ('{"spec": {"power_mapping": "watts"}}', "has spec.power_mapping = 'watts', expected one of paper, shares"),
    ],
    ids=["truncated", "empty", "list", "spec_str", "scenario_int", "unknown_algo", "unknown_env", "other_algo", "mapping"],
)
@pytest.mark.parametrize("command", ["evaluate", "enjoy"])
def test_a_damaged_run_record_beside_the_model_is_one_error_line_naming_it(run_folder, capsys, content, problem, command):
    (run_folder / "result.json").write_text(content)
    code, printed = run_cli([command, str(run_folder / "model.zip")], capsys)
    assert_one_error_line(code, printed, command, f"{run_folder / 'result.json'}", problem)


def test_a_json_object_without_a_spec_beside_the_model_is_not_a_run_record(saved_dtdpg, tmp_path):
    import shutil

    from sb3_dtdpg.model_files import read_saved_model

    shutil.copy(saved_dtdpg, tmp_path / "model.zip")
    (tmp_path / "result.json").write_text('{"model": "model.zip", "summary": {}}')  # e.g. an evaluate --json
    saved = read_saved_model(tmp_path)
    assert saved.algo == "dtdpg" and saved.env_id is None and saved.source == "the model file"


@pytest.mark.parametrize(
    ("env_id", "named"),
    [("NomaRadioMapPaper-v0", "the env id has task='paper'"), ("NomaRadioMapOMA-v0", "the env id has multiple_access='oma'")],
)
@pytest.mark.parametrize("command", ["evaluate", "enjoy"])
def test_an_env_id_contradicting_the_models_settings_is_refused(saved_dtdpg, capsys, command, env_id, named):
    code, printed = run_cli([command, str(saved_dtdpg), "--env", env_id], capsys)
    assert_one_error_line(code, printed, command, f"--env {env_id}: {named}", "leave --env out")


def test_a_runs_env_id_records_its_task(tmp_path):
    from sb3_dtdpg.model_files import read_saved_model

    run = tmp_path / "runs" / "ddpg_noma_s0_paper"
    run.mkdir(parents=True)
    DDPG("MlpPolicy", small_env(observation="paper"), learning_starts=10).save(run / "model.zip")
    spec = {"algo": "ddpg", "scenario": "small", "observation": "paper", "multiple_access": "noma"}
    (run / "result.json").write_text(json.dumps({"spec": {**spec, "env_id": "NomaRadioMapPaper-v0"}}))
    assert read_saved_model(run).settings["task"] == "paper"
    (run / "result.json").write_text(json.dumps({"spec": {**spec, "env_id": "NomaRadioMap-v0"}}))
    assert read_saved_model(run).settings["task"] == "missions"


def test_enjoy_checks_the_mp4_writer_before_the_mission(saved_dtdpg, tmp_path, capsys, monkeypatch):
    from matplotlib import animation

    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    movie = tmp_path / "mission.mp4"
    code, printed = run_cli(["enjoy", str(saved_dtdpg), "--record", str(movie)], capsys)
    assert_one_error_line(code, printed, "enjoy", f"--record {movie}: writing .mp4 needs the ffmpeg program")
    assert not movie.exists()


def test_enjoy_writes_at_most_max_frames(saved_dtdpg, tmp_path, capsys):
    gif = tmp_path / "mission.gif"
    assert main(["enjoy", str(saved_dtdpg), "--record", str(gif), "--max-frames", "1"]) == 0
    assert "(1 frame)" in capsys.readouterr().out
    with Image.open(gif) as image:
        assert image.n_frames == 1
    from sb3_dtdpg.recording import frame_steps

    assert frame_steps(60, 1) == [60] and frame_steps(60, 2) == [0, 60] and frame_steps(0, 5) == [0]
    for max_frames in range(1, 70):
        frames = frame_steps(60, max_frames)
        assert len(frames) <= max_frames and frames[-1] == 60 and frames == sorted(set(frames))
    with pytest.raises(ValueError, match="max_frames must be >= 1"):
        frame_steps(60, 0)


def test_a_replay_buffer_of_another_observation_layout_is_refused_and_the_models_kept(tmp_path):
    # it loaded, and learn() then died in a bare broadcast error at the next stored transition
    tiny = dict(learning_starts=10, batch_size=8, policy_kwargs=dict(net_arch=[8]), seed=0)
    source = DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario="small", observation="goal"), **tiny)
    source.learn(20)
    source.save_replay_buffer(tmp_path / "buffer.pkl")
    model = DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario="small", observation="paper"), **tiny)
    own = model.replay_buffer
    with pytest.raises(ValueError, match=r"does not fit this model: observation space Box\(.*\(18,\).* \(the model's: Box"):
        model.load_replay_buffer(tmp_path / "buffer.pkl")
    assert model.replay_buffer is own
    twin = DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario="small", observation="goal"), **tiny)
    twin.load_replay_buffer(tmp_path / "buffer.pkl")
    assert twin.replay_buffer.pos == 20


# ------------------------------------------------------------------------------------ models of scenario files


def scenario_file(folder, name="small", ap_dbm=5.0, interferer_dbm=40.0):
    """The built-in `small` room with a weaker AP and a louder interferer, under ``name``, as a YAML file."""
    import yaml

    data = noma_radiomap.load_scenario("small").to_dict()
    data["name"], data["ap"]["max_power_dbm"], data["interferers"][0]["power_dbm"] = name, ap_dbm, interferer_dbm
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}_{ap_dbm:g}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("name", ["small", "mysmall"])
def test_a_model_of_a_scenario_file_is_tested_on_that_file_and_refused_on_another_room(tmp_path, capsys, name):
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.model_files import read_saved_model

    room = scenario_file(tmp_path, name)
    path = tmp_path / "model.zip"
    DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario=str(room), observation="goal"), seed=0).save(path)
    recorded = DTDPG.load(path).env_settings
    assert (recorded["scenario"], recorded["scenario_file"]) == (name, str(room))
    assert recorded["scenario_digest"] == scenario_digest(noma_radiomap.load_scenario(str(room)))
    assert read_saved_model(path).env_kwargs("rayleigh")["scenario"] == str(room)  # the file, not the built-in
    # the built-in `small` is another room: refused, naming both (the room's file and digest where the names agree)
    with pytest.raises(EnvSettingsMismatch) as error:
        evaluate(DTDPG.load(path), small_env(observation="goal"), n_episodes=1)
    if name == "small":
        assert f"scenario='small' (from {room}, content sha256 {recorded['scenario_digest'][:12]})" in str(error.value)
        assert "(the env has 'small', the built-in scenario, content sha256" in str(error.value)
        assert "another room of the same name" in str(error.value)
    else:
        assert "scenario='mysmall' (the env has 'small')" in str(error.value)
    assert f"scenario={str(room)!r}" in str(error.value) and f"--scenario {room}" in str(error.value)
    # evaluate tests it on its file
    out = tmp_path / "eval.json"
    assert main(["evaluate", str(path), "--n-episodes", "1", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["settings"]["scenario"] == str(room)
    capsys.readouterr()
    code, printed = run_cli(["evaluate", str(path), "--n-episodes", "1", "--scenario", "small"], capsys)
    assert_one_error_line(code, printed, "evaluate", f"scenario='{name}' ", "(the env has 'small'", f"--scenario {room}")


def test_a_model_of_the_mall_before_its_recalibration_is_refused_on_mall_and_taken_with_its_kept_file(tmp_path):
    # docs/SCENARIOS.md ("mall calibration"): the room of 2026-12-03 is kept as a file of the same name and content
    from sb3_dtdpg.env_settings import RETIRED_BUILTINS

    kept = "benchmarks/rooms/mall_2026-12-03.yaml"
    room = Path(__file__).resolve().parents[1] / kept
    # the file's content is the retired built-in's that names it (recorded from commit a77ba69), not today's mall
    assert RETIRED_BUILTINS.get(scenario_digest(noma_radiomap.load_scenario(str(room)))) == kept
    assert scenario_digest(noma_radiomap.load_scenario("mall")) not in RETIRED_BUILTINS
    path = tmp_path / "model.zip"
    DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario=str(room)), seed=0).save(path)
    model = DTDPG.load(path)  # without an env, saving keeps the recorded settings
    model.env_settings = {**model.env_settings, "scenario_file": None}  # as a model of the built-in recorded them
    model.save(path)
    with pytest.raises(EnvSettingsMismatch, match="another room of the same name") as error:
        DTDPG.load(path, env=gym.make("NomaRadioMap-v0"))
    assert f"before its recalibration, kept as {kept}" in str(error.value)  # the message names the kept file
    assert f"scenario='{kept}'" in str(error.value) and f"--scenario {kept} " in str(error.value)
    DTDPG.load(path, env=gym.make("NomaRadioMap-v0", scenario=str(room)))


def test_a_model_of_a_scenario_file_changed_or_gone_since_says_so(tmp_path, capsys):
    import shutil

    from sb3_dtdpg.model_files import read_saved_model

    room = scenario_file(tmp_path)
    path = tmp_path / "model.zip"
    DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario=str(room), observation="goal"), seed=0).save(path)
    shutil.copy(room, tmp_path / "kept.yaml")
    room.write_text(scenario_file(tmp_path / "other", ap_dbm=7.0).read_text())  # edited since: another room
    with pytest.raises(ValueError, match=f"from {re.escape(str(room))} .*but that file holds another scenario now"):
        read_saved_model(path).env_kwargs("rayleigh")
    room.unlink()
    code, printed = run_cli(["enjoy", str(path)], capsys)
    assert_one_error_line(
        code, printed, "enjoy", f"{room} (content sha256", "but that file cannot be loaded now", "--scenario"
    )
    # a copy of the room it trained in is that room
    kwargs = read_saved_model(path).env_kwargs("rayleigh", scenario=str(tmp_path / "kept.yaml"))
    read_saved_model(path).load(gym.make("NomaRadioMap-v0", **kwargs))


def test_a_model_saved_before_the_scenario_digest_is_read_and_checked_by_name_as_before(tmp_path):
    from sb3_dtdpg.model_files import read_saved_model

    room = scenario_file(tmp_path)
    model = DDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario=str(room), observation="goal"), learning_starts=10)
    record(model)
    for key in ("scenario_digest", "scenario_file"):
        del model.env_settings[key]  # as saved before they were recorded
    model.save(tmp_path / "old.zip")
    saved = read_saved_model(tmp_path / "old.zip")
    assert saved.env_kwargs("rayleigh")["scenario"] == "small"  # the name: as before
    saved.load(small_env(observation="goal"))
    saved.load(gym.make("NomaRadioMap-v0", scenario=str(room), observation="goal"))
    # beside its run record, the record's scenario content tells the room of that name it trained in
    run = tmp_path / "runs" / "ddpg_noma_s0_goal"
    run.mkdir(parents=True)
    (tmp_path / "old.zip").rename(run / "model.zip")
    spec = {"algo": "ddpg", "scenario": str(room), "observation": "goal", "multiple_access": "noma"}
    identity = {"spec": spec, "scenario": noma_radiomap.load_scenario(str(room)).to_dict()}
    (run / "result.json").write_text(json.dumps({"identity": identity, "spec": spec}))
    saved = read_saved_model(run)
    assert saved.env_kwargs("rayleigh")["scenario"] == str(room) and "result.json" in saved.source
    with pytest.raises(EnvSettingsMismatch, match="another room of the same name"):
        saved.load(small_env(observation="goal"))


def test_a_runs_record_gives_its_power_mapping_and_its_scenario_file(tmp_path):
    from sb3_dtdpg.model_files import read_saved_model

    room = scenario_file(tmp_path)
    run = tmp_path / "runs" / "ddpg_noma_s0_goal_shares"
    run.mkdir(parents=True)
    trained_env = gym.make("NomaRadioMap-v0", scenario=str(room), observation="goal", power_mapping="shares")
    DDPG("MlpPolicy", trained_env, learning_starts=10).save(run / "model.zip")  # no settings in the zip
    spec = {"algo": "ddpg", "scenario": str(room), "observation": "goal", "multiple_access": "noma"}
    spec["power_mapping"] = "shares"
    (run / "result.json").write_text(json.dumps({"spec": spec}))  # no scenario content: read from the file
    saved = read_saved_model(run)
    assert saved.settings["power_mapping"] == "shares" and saved.settings["scenario"] == "small"
    kwargs = saved.env_kwargs("rayleigh")
    assert (kwargs["power_mapping"], kwargs["scenario"]) == ("shares", str(room))
    saved.load(gym.make("NomaRadioMap-v0", **kwargs))  # its own settings, compared like for like
    with pytest.raises(EnvSettingsMismatch, match="power_mapping='shares'"):
        saved.load(gym.make("NomaRadioMap-v0", **{**kwargs, "power_mapping": "paper"}))
    with pytest.raises(EnvSettingsMismatch, match="another room of the same name"):
        saved.load(gym.make("NomaRadioMap-v0", **{**kwargs, "scenario": "small"}))
    # the content the record stores is the room it trained in, whatever became of the file since
    identity = {"spec": spec, "scenario": noma_radiomap.load_scenario(str(room)).to_dict()}
    (run / "result.json").write_text(json.dumps({"identity": identity, "spec": spec}))
    room.write_text(scenario_file(tmp_path / "other", ap_dbm=7.0).read_text())
    with pytest.raises(ValueError, match="holds another scenario now"):
        read_saved_model(run).env_kwargs("rayleigh")
    # a record from before power mappings were recorded: not checked, the default env
    del spec["power_mapping"]
    (run / "result.json").write_text(json.dumps({"spec": {**spec, "scenario": "small"}}))
    assert "power_mapping" not in read_saved_model(run).env_kwargs("rayleigh")


def test_the_scenario_digest_is_the_same_from_a_scenario_and_from_its_run_record():
    from sb3_dtdpg.experiments.specs import RunSpec, run_identity

    scenario = noma_radiomap.load_scenario("small")
    assert scenario_digest(scenario) == scenario_digest(
        run_identity(RunSpec("dtdpg", "noma", 0, 2, scenario="small"))["scenario"]
    )
    assert scenario_digest(scenario) == scenario_digest(scenario.with_resolution(scenario.room.resolution))
    assert scenario_digest(scenario) != scenario_digest(noma_radiomap.load_scenario("mall"))


@pytest.mark.parametrize("scenario", ["small", "file"])
def test_a_paper_task_model_is_tested_on_its_room(tmp_path, scenario):
    # The paper's task runs its scenario with another mission length: the recorded digest is of the room as loaded
    from sb3_dtdpg.model_files import read_saved_model

    if scenario == "file":
        scenario = tmp_path / "room.yaml"
        builtin = Path(noma_radiomap.__file__).parent / "scenarios" / "small.yaml"
        scenario.write_text(builtin.read_text().replace("max_power_dbm: 20.0", "max_power_dbm: 15.0"))
    env = gym.make("NomaRadioMapPaper-v0", scenario=str(scenario))
    DTDPG("MlpPolicy", env, learning_starts=10, batch_size=8, policy_kwargs={"net_arch": [8]}).save(tmp_path / "model")
    kwargs = read_saved_model(tmp_path / "model.zip").env_kwargs("rayleigh")
    assert kwargs["scenario"] == str(scenario) and kwargs["task"] == "paper"
    test_env = gym.make("NomaRadioMap-v0", **kwargs)  # the env evaluate builds
    assert (
        read_saved_model(tmp_path / "model.zip").load(test_env).env_settings["scenario_digest"]
        == settings_of(env)["scenario_digest"]
    )


def test_a_saved_n_step_ddpg_loads_without_sb3s_spurious_buffer_warning(tmp_path):
    # SB3 2.9.2 warns that n_steps is ignored when reloading its own n-step DDPG, then restores the buffer all the same
    # (SB3 2.9.0 does not warn).
    import warnings

    import stable_baselines3
    from packaging.version import Version

    from sb3_dtdpg.baselines import load_model

    DDPG("MlpPolicy", small_env(), n_steps=3, learning_starts=10).save(tmp_path / "model.zip")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = load_model("ddpg", tmp_path / "model.zip", env=small_env())
    assert (type(model.replay_buffer).__name__, model.replay_buffer.n_steps) == ("NStepReplayBuffer", 3)
    # A canary: once SB3 stops warning, this fails and load_model's filter can go.
    if Version(stable_baselines3.__version__) >= Version("2.9.2"):
        with pytest.warns(UserWarning, match="is ignored because a custom"):
            DDPG.load(tmp_path / "model.zip", env=small_env())
    else:  # ... and SB3 2.9.0 gives no such warning to filter
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            DDPG.load(tmp_path / "model.zip", env=small_env())


def test_evaluate_scores_the_returns_on_the_reward_the_model_trained_on_last(tmp_path, capsys):
    # DDPG trains on the "combined" reward: evaluate's returns are on it (were on the env id's "destination" reward).
    from sb3_dtdpg.evaluation import evaluate

    path = tmp_path / "ddpg.zip"
    model = DDPG("MlpPolicy", small_env(observation="goal", reward_phase="combined"), learning_starts=10, seed=0)
    record(model)  # as the CLI's runs do: tested on small
    model.save(path)
    out_json, out_csv = tmp_path / "eval.json", tmp_path / "eval.csv"
    assert main(["evaluate", str(path), "--n-episodes", "2", "--json", str(out_json), "--csv", str(out_csv)]) == 0
    assert json.loads(out_json.read_text())["settings"]["reward_phase"] == "combined"
    expected = evaluate(
        DDPG.load(path), "NomaRadioMap-v0", n_episodes=2, seed=10_000,
        env_kwargs={"scenario": "small", "observation": "goal", "reward_phase": "combined"},
    )  # fmt: skip
    returns = pd.read_csv(out_csv)["episode_return"]
    assert list(returns) == pytest.approx([e["episode_return"] for e in expected.episodes])
    destination = evaluate(
        DDPG.load(path), "NomaRadioMap-v0", n_episodes=2, seed=10_000, env_kwargs={"scenario": "small", "observation": "goal"}
    )
    assert list(returns) != pytest.approx([e["episode_return"] for e in destination.episodes])
