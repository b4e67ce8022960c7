"""`benchmarks/targets.py` and `benchmarks/diagnosis.py`: options checked before anything runs, stored runs reused
only with the settings they were run with, a fresh log per run, and no ``nan`` for the CI of one seed."""

import json
from pathlib import Path

import pytest
from scripts import load_script

from sb3_dtdpg.experiments.storage import settings_mismatch


@pytest.fixture(scope="module")
def targets():
    return load_script("targets")


@pytest.fixture(scope="module")
def diagnosis():
    return load_script("diagnosis")


def refused(script, argv: list[str], capsys) -> str:
    """The error line of a command that must exit with code 2 (argparse's usage error)."""
    with pytest.raises(SystemExit) as exit_info:
        script.parse_args(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    return err.strip().splitlines()[-1]


TARGETS_SMALL = ["--episodes", "2", "--eval-episodes", "1", "--env-kwargs", '{"scenario": "small"}', "--workers", "1"]


def store_targets_run(targets, out: Path, argv: list[str], method: str = "dtdpg", seed: int = 0) -> Path:
    """A fake record of a finished run of ``argv`` (what run() stores, less the curves)."""
    args = targets.parse_args([*argv, "--out", str(out)])
    path = Path(targets.run_path(args, method, seed))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"method": method, "seed": seed, "settings": targets.run_settings(method, args)}))
    return path


@pytest.mark.parametrize(
    "argv, option",
    [
        (["--workers", "0"], "argument --workers: expected a positive integer, got '0'"),
        (["--episodes", "0"], "argument --episodes: expected a positive integer, got '0'"),
        (["--eval-episodes", "0"], "argument --eval-episodes: expected a positive integer, got '0'"),
        (["--seeds", "0", "-1"], "argument --seeds: expected a seed in 0.."),
        (["--destination-episodes", "-1"], "argument --destination-episodes: expected an integer >= 0, got '-1'"),
        (["--success-threshold", "1.5"], "--success-threshold 1.5"),
        (["--env-kwargs", '["small"]'], "--env-kwargs: expected a JSON object, got ['small']"),
        (["--env", "NoSuchEnv-v0"], "--env NoSuchEnv-v0"),
    ],
)
def test_targets_refuses_an_unusable_option_before_anything_runs(targets, tmp_path, capsys, argv, option):
    out = tmp_path / "out"
    line = refused(targets, [*argv, "--out", str(out)], capsys)
    assert f": error: {option}" in line
    assert not out.exists()


@pytest.mark.parametrize("option", ["--workers", "--episodes", "--eval-every", "--eval-missions"])
def test_diagnosis_refuses_a_count_below_one(diagnosis, tmp_path, capsys, option):
    out = tmp_path / "out"
    line = refused(diagnosis, [option, "0", "--out", str(out)], capsys)
    assert line.endswith(f": error: argument {option}: expected a positive integer, got '0'")
    assert not out.exists()


def test_repeated_seeds_methods_and_configs_run_once(targets, diagnosis, tmp_path):
    args = targets.parse_args(["--methods", "ddpg", "dtdpg", "ddpg", "--seeds", "3", "0", "3", "--out", str(tmp_path)])
    assert (args.methods, args.seeds) == (["ddpg", "dtdpg"], [3, 0])
    args = diagnosis.parse_args(["--configs", "sac", "base", "sac", "--seeds", "1", "1", "--out", str(tmp_path)])
    assert (args.configs, args.seeds) == (["sac", "base"], [1])


def test_targets_refuses_a_stored_run_of_other_settings(targets, tmp_path, capsys):
    path = store_targets_run(targets, tmp_path, TARGETS_SMALL)
    line = refused(targets, [*TARGETS_SMALL, "--episodes", "40", "--hyperparams", "paper", "--out", str(tmp_path)], capsys)
    assert str(path) in line
    assert "was run with --hyperparams tuned, --episodes 2; this command asks for --hyperparams paper, --episodes 40" in line
    assert "use another --out" in line
    line = refused(targets, [*TARGETS_SMALL, "--env-kwargs", '{"scenario": "mall"}', "--out", str(tmp_path)], capsys)
    assert """--env-kwargs '{"scenario": "small"}'; this command asks for --env-kwargs '{"scenario": "mall"}'""" in line
    assert "--eval-episodes 1;" in refused(targets, [*TARGETS_SMALL, "--eval-episodes", "3", "--out", str(tmp_path)], capsys)
    # the same settings: the stored run is reused
    assert targets.parse_args([*TARGETS_SMALL, "--out", str(tmp_path)]).episodes == 2


def test_targets_transfer_rule_is_a_setting_of_dtdpg_runs_only(targets, tmp_path, capsys):
    store_targets_run(targets, tmp_path, TARGETS_SMALL, method="ddpg")
    store_targets_run(targets, tmp_path, [*TARGETS_SMALL, "--success-threshold", "0.9"], method="dtdpg")
    args = targets.parse_args([*TARGETS_SMALL, "--methods", "ddpg", "--success-threshold", "0.9", "--out", str(tmp_path)])
    assert Path(targets.run_path(args, "ddpg", 0)).name == "ddpg_goal_seed0.json"
    assert Path(targets.run_path(args, "dtdpg", 0)).name == "dtdpg_goal_threshold0.9_seed0.json"
    line = refused(targets, [*TARGETS_SMALL, "--success-threshold", "0.9", "--episodes", "3", "--out", str(tmp_path)], capsys)
    assert "(2 stored runs cannot be reused)" in line


def test_targets_refuses_a_stored_run_without_settings(targets, tmp_path, capsys):
    (tmp_path / "dtdpg_goal_seed0.json").write_text(json.dumps({"method": "dtdpg", "seed": 0, "test_mqi": 1.0}))
    line = refused(targets, [*TARGETS_SMALL, "--methods", "dtdpg", "--out", str(tmp_path)], capsys)
    assert "dtdpg_goal_seed0.json was stored by an older version" in line
    assert "cannot be checked" in line and "another --out" in line


def test_targets_record_stores_the_settings_it_is_checked_against(targets, tmp_path):
    from sb3_dtdpg.common.files import write_json

    argv = [*TARGETS_SMALL, "--methods", "ddpg", "--out", str(tmp_path)]
    args = targets.parse_args(argv)
    record = targets.run("ddpg", 0, args)
    write_json(targets.run_path(args, "ddpg", 0), record)
    assert settings_mismatch(targets.run_path(args, "ddpg", 0), targets.run_settings("ddpg", args)) is None
    assert targets.parse_args(argv).episodes == 2


def test_targets_summary_of_one_seed_has_no_nan(targets, tmp_path):
    args = targets.parse_args([*TARGETS_SMALL, "--out", str(tmp_path)])
    records = [
        {"method": "ddpg", "seed": 0, "test_success": 1.0, "test_mqi": 50.0, "test_mqi_ci": float("nan"), "seconds": 3},
        {
            "method": "dtdpg",
            "seed": 0,
            "test_success": 0.5,
            "test_mqi": 60.0,
            "test_mqi_ci": 2.0,
            "seconds": 3,
            "phase1_reached_95": True,
            "phase1_episodes": 1,
        },
    ]
    text = "\n".join(targets.summarize(records, {"test_mqi": 100.0, "test_success": 1.0}, args))
    assert "nan" not in text
    assert "| 50.0 ± n/a |" in text and "| 60.0 ± 2.0 |" in text
    assert "| **ddpg mean** | 1 seeds | | 100% ± n/a | 50.0 ± n/a |" in text
    assert "success -50 ± n/a points, MQI +10.0 ± n/a." in text
    records += [{**r, "seed": 1, "test_mqi": r["test_mqi"] + 2} for r in records]
    text = "\n".join(targets.summarize(records, {"test_mqi": 100.0, "test_success": 1.0}, args))
    assert "| **ddpg mean** | 2 seeds | | 100% ± 0% | 51.0 ± 12.7 |" in text


DIAGNOSIS_TINY = ["--episodes", "2", "--eval-every", "1", "--eval-missions", "1", "--workers", "1"]


def store_diagnosis_run(diagnosis, out: Path, argv: list[str], name: str = "base", seed: int = 0) -> Path:
    args = diagnosis.parse_args([*argv, "--out", str(out)])
    path = Path(diagnosis.run_path(str(out), name, seed))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"config": name, "seed": seed, "settings": diagnosis.run_settings(args)}))
    return path


def test_diagnosis_refuses_a_stored_run_of_other_settings(diagnosis, tmp_path, capsys):
    path = store_diagnosis_run(diagnosis, tmp_path, DIAGNOSIS_TINY)
    line = refused(diagnosis, [*DIAGNOSIS_TINY, "--eval-every", "5", "--base", "defaults", "--out", str(tmp_path)], capsys)
    assert f"{path} was run with --base tuned, --eval-every 1; this command asks for --base defaults, --eval-every 5" in line
    assert "use another --out" in line
    assert "--stop-at 0.95;" in refused(diagnosis, [*DIAGNOSIS_TINY, "--stop-at", "0.8", "--out", str(tmp_path)], capsys)
    assert diagnosis.parse_args([*DIAGNOSIS_TINY, "--out", str(tmp_path)]).episodes == 2


def test_diagnosis_checks_the_runs_of_sooner_than_and_old_records(diagnosis, tmp_path, capsys):
    store_diagnosis_run(diagnosis, tmp_path, [*DIAGNOSIS_TINY, "--episodes", "9"], name="sac")
    line = refused(diagnosis, [*DIAGNOSIS_TINY, "--sooner-than", "sac", "--out", str(tmp_path)], capsys)
    assert "sac_seed0.json was run with --episodes 9" in line
    (tmp_path / "sac_seed0.json").write_text(json.dumps({"config": "sac", "seed": 0, "evals": []}))
    line = refused(diagnosis, [*DIAGNOSIS_TINY, "--configs", "sac", "--out", str(tmp_path)], capsys)
    assert "sac_seed0.json was stored by an older version" in line and "cannot be checked" in line


def test_diagnosis_run_starts_a_fresh_log(diagnosis, tmp_path):
    args = diagnosis.parse_args([*DIAGNOSIS_TINY, "--out", str(tmp_path)])
    log = tmp_path / "base_seed0.log"
    log.write_text('{"episode": 1, "success": 1.0}\n{"episode": 2, "success": 1.0}\n{"episode": 3, "success": 1.0}\n')
    record = diagnosis.run("base", 0, args)  # an interrupted run's lines before it
    assert [json.loads(line)["episode"] for line in log.read_text().splitlines()] == [1, 2]
    assert record["settings"] == diagnosis.run_settings(args)
