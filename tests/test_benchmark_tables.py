"""The tables of the benchmark scripts: options checked before any work, configurations kept apart, one seed's CI.

Tiny CSVs and result files in tmp_path instead of training: nothing here trains or runs a test mission.
"""

import json
import sys
from pathlib import Path

import pandas as pd
import pytest
from scripts import load_script


@pytest.fixture(scope="module")
def gap():
    return load_script("learner_gap")


@pytest.fixture(scope="module")
def merge():
    return load_script("paper_task_merge")


@pytest.fixture(scope="module")
def task_runs():
    return load_script("paper_task_runs")


@pytest.fixture(scope="module")
def shares():
    return load_script("power_shares")


def run_main(module, monkeypatch, capsys, *argv: str) -> tuple[int | None, str, str]:
    """:return: the exit code (None: returned), stdout and stderr of the script's ``main`` with these arguments"""
    monkeypatch.setattr(sys, "argv", [f"{module.__name__}.py", *map(str, argv)])
    code = None
    try:
        module.main()
    except SystemExit as exit_:
        code = exit_.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_option_error(code, err: str, *names: str) -> None:
    """An argparse error (status 2, usage then one ``error:`` line) naming each of ``names``, no traceback."""
    assert code == 2 and "Traceback" not in err
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1, err
    for name in names:
        assert name in lines[0], (name, lines[0])


# --- learner_gap.py -----------------------------------------------------------------------------------------------


def gap_missions(seeds: int = 1, mode: str = "noma") -> pd.DataFrame:
    """The missions of a ``learner_gap.py --csv``: DT-DPG over ``seeds`` runs and the two planners, two missions."""
    rows = []
    values = {"mqi_best_power": 0.0, "power_loss": 5.0, "outage_steps": 3.0, "outage_best_power": 1.0, "steps": 40.0}
    for seed in range(seeds):
        for episode in range(2):
            mqi = 820.0 + 10 * seed + episode
            rows.append({"policy": "DT-DPG", "mode": mode, "run": f"dtdpg_{mode}_s{seed}", "episode": episode, "mqi": mqi})
    for policy, mqi in (("best planner", 870.0), ("shortest-path planner", 850.0)):
        for episode in range(2):
            rows.append({"policy": policy, "mode": mode, "run": policy, "episode": episode, "mqi": mqi + episode})
    frame = pd.DataFrame([{**values, **row} for row in rows])
    frame["mqi_best_power"] = frame["mqi"] + frame["power_loss"]
    frame["power_used"], frame["outage_full_power"] = 0.9, 2.0
    return frame


@pytest.mark.parametrize("seeds", [1, 2])
def test_learner_gap_figure_of_one_seed_draws_the_bar_without_an_error_bar(gap, tmp_path, seeds):
    # compare's default is one seed: its CI is NaN, which made the axis limits NaN
    assert pd.isna(gap.summarise(gap_missions(1)).set_index("policy").loc["DT-DPG", "mqi_ci"])
    for frames in ({"one": gap_missions(seeds)}, {"one": gap_missions(seeds, "oma"), "other": gap_missions(1, "oma")}):
        path = tmp_path / f"gap_{len(frames)}.png"
        gap.plot(frames, path)
        assert path.stat().st_size > 1000


def test_learner_gap_from_csv_refuses_the_options_that_measure(gap, tmp_path, monkeypatch, capsys):
    source = tmp_path / "a.csv"
    gap_missions().to_csv(source, index=False)
    written = tmp_path / "b.csv"
    code, _, err = run_main(gap, monkeypatch, capsys, "--from-csv", source, "--csv", written)
    assert_option_error(code, err, "--csv", "--from-csv")
    assert not written.exists()
    for option, value in (("--episodes", "5"), ("--seed", "3"), ("--runs", "*_tuned_goal")):
        code, _, err = run_main(gap, monkeypatch, capsys, "--from-csv", source, option, value)
        assert_option_error(code, err, option)
    # An output folder and --from-csv: the folder was ignored and the input CSV copied to --csv
    code, _, err = run_main(gap, monkeypatch, capsys, tmp_path, "--from-csv", source)
    assert_option_error(code, err, str(tmp_path), "--from-csv")


def test_learner_gap_from_csv_keeps_one_frame_per_file(gap, tmp_path, monkeypatch, capsys):
    paths = []
    for folder, seeds in (("x4", 2), ("paper", 1)):
        (tmp_path / folder).mkdir()
        paths.append(tmp_path / folder / "learner_gap.csv")
        gap_missions(seeds).to_csv(paths[-1], index=False)
    code, _, err = run_main(gap, monkeypatch, capsys, "--from-csv", *paths, "--labels", "same", "same")
    assert_option_error(code, err, "--labels", "'same'")
    code, _, err = run_main(gap, monkeypatch, capsys, "--from-csv", paths[0], tmp_path / "x4" / ".." / "x4" / paths[0].name)
    assert_option_error(code, err, "--from-csv", "twice")
    # The same file name in two folders: the labels name the folders too, and both files are read
    assert gap.csv_labels(paths) == ["x4/learner_gap", "paper/learner_gap"]
    assert gap.csv_labels([paths[0], tmp_path / "other.csv"]) == ["learner_gap", "other"]
    code, out, err = run_main(gap, monkeypatch, capsys, "--from-csv", *paths, "--figure", tmp_path / "fig" / "gap.png")
    assert code is None, err
    assert "x4/learner_gap: radio-map channel" in out and "paper/learner_gap: radio-map channel" in out
    assert "| DT-DPG | NOMA | 2 |" in out and "| DT-DPG | NOMA | 1 |" in out
    assert (tmp_path / "fig" / "gap.png").is_file()


def test_learner_gap_from_csv_of_another_kind_is_one_line(gap, tmp_path, monkeypatch, capsys):
    other = tmp_path / "paper_task_runs.csv"
    pd.DataFrame({"group": ["g"], "seed": [0], "mqi": [1.0]}).to_csv(other, index=False)
    code, _, err = run_main(gap, monkeypatch, capsys, "--from-csv", other)
    assert_option_error(code, err, str(other), "policy", "mqi_best_power")


def test_learner_gap_makes_the_csv_folder_before_measuring(gap, tmp_path, monkeypatch, capsys):
    target = tmp_path / "new" / "folder" / "gap.csv"
    calls = []

    def measure(out, episodes, seed, runs):
        calls.append((episodes, seed, runs))
        assert target.parent.is_dir()  # the measurement takes minutes: a bad --csv fails before
        return gap_missions()

    monkeypatch.setattr(gap, "measure", measure)
    code, _, err = run_main(gap, monkeypatch, capsys, tmp_path / "compare", "--csv", target)
    assert code is None, err
    assert calls == [(20, 10_000, "*")]
    assert pd.read_csv(target).equals(gap_missions())
    blocked = tmp_path / "a_file"
    blocked.write_text("")
    code, _, err = run_main(gap, monkeypatch, capsys, tmp_path / "compare", "--csv", blocked / "gap.csv")
    assert_option_error(code, err, "--csv", str(blocked / "gap.csv"))
    assert len(calls) == 1
    code, _, err = run_main(gap, monkeypatch, capsys, tmp_path / "compare", "--episodes", "0")
    assert_option_error(code, err, "--episodes", "'0'")


# --- paper_task_merge.py ------------------------------------------------------------------------------------------


def task_records(episodes: int = 500, training: str = "radio_map") -> pd.DataFrame:
    """Per-run records as in ``paper_task_runs.csv``: DT-DPG and DDPG, NOMA, seeds 0 and 1."""
    rows = []
    for algo, label in (("dtdpg", "DT-DPG"), ("ddpg", "DDPG")):
        for seed in (0, 1):
            rows.append(
                {
                    "group": f"{algo}_noma_paper_task_{episodes}",
                    "preset": "paper",
                    "algorithm": label,
                    "algo": algo,
                    "multiple_access": "NOMA",
                    "training": training,
                    "episodes": episodes,
                    "seed": seed,
                    "success_rate": 0.5,
                    "mqi": 800.0 + seed,
                    "train_success": 0.1 * (seed + 1),
                    "train_success_first": 0.0,
                    "train_success_last": 0.2,
                    "train_episodes": episodes,
                }
            )
    return pd.DataFrame(rows)


def test_paper_task_merge_refuses_a_budget_of_other_episodes(merge, tmp_path, monkeypatch, capsys):
    runs = tmp_path / "job" / "paper_task_runs.csv"
    runs.parent.mkdir()
    task_records(500).to_csv(runs, index=False)
    code, _, err = run_main(merge, monkeypatch, capsys, runs, "--budget", "tiny", "--out", tmp_path / "merged")
    assert_option_error(code, err, "--budget tiny", "3 training episodes", "trained 500", "--budget paper")
    assert not (tmp_path / "merged").exists()
    # Rayleigh training: the budget's longer task_long_episodes (the paper: 700)
    merge.check_budget_episodes("paper", task_records(700, "rayleigh"), "rayleigh")
    with pytest.raises(ValueError, match=r"--budget paper: 500 training episodes per radio_map run, but the runs trained 700"):
        merge.check_budget_episodes("paper", task_records(700), "radio_map")
    with pytest.raises(ValueError, match=r"--budget tiny: 4 .* rayleigh .* trained 700 \(give --budget paper\)"):
        merge.check_budget_episodes("tiny", task_records(700, "rayleigh"), "rayleigh")
    both = pd.concat([task_records(200), task_records(500).assign(seed=[2, 3, 2, 3])])
    with pytest.raises(ValueError, match=r"trained 200, 500 \(no budget"):
        merge.check_budget_episodes("paper", both, "radio_map")


def test_paper_task_merge_refuses_runs_of_another_budget_with_the_same_episodes(merge, tmp_path, monkeypatch, capsys):
    # small-200 and mall-200 both train 200 episodes: --budget mall-200 drew mall's planners beside small's runs
    runs = tmp_path / "job" / "paper_task_runs.csv"
    runs.parent.mkdir()
    task_records(200).assign(scenario="small", eval_episodes=20).to_csv(runs, index=False)
    code, _, err = run_main(merge, monkeypatch, capsys, runs, "--budget", "mall-200", "--out", tmp_path / "merged")
    assert_option_error(code, err, "--budget mall-200: scenario 'mall'", "the runs have scenario 'small'", "small-200")
    assert not (tmp_path / "merged").exists()
    with pytest.raises(ValueError, match=r"eval_episodes 20, but the runs have eval_episodes 5 \(no budget has"):
        merge.check_budget_episodes("paper", task_records(500).assign(eval_episodes=5), "radio_map")
    # and two folders of the two budgets' runs, same ids: refused, not merged as one
    other = tmp_path / "other" / "paper_task_runs.csv"
    other.parent.mkdir()
    task_records(200).assign(scenario="mall", eval_episodes=20).to_csv(other, index=False)
    code, _, err = run_main(merge, monkeypatch, capsys, runs, other, "--budget", "mall-200", "--out", tmp_path / "merged")
    assert_option_error(code, err, "the runs are of several budgets (scenario: 'mall', 'small')")
    assert not (tmp_path / "merged").exists()


def test_paper_task_merge_refuses_a_csv_of_another_kind(merge, tmp_path, monkeypatch, capsys):
    other = tmp_path / "learner_gap.csv"
    gap_missions().to_csv(other, index=False)
    code, _, err = run_main(merge, monkeypatch, capsys, other, "--out", tmp_path / "merged")
    assert_option_error(code, err, str(other), "group", "train_success")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    code, _, err = run_main(merge, monkeypatch, capsys, empty, "--out", tmp_path / "merged")
    assert_option_error(code, err, str(empty), "not a CSV")


def test_paper_task_merge_refuses_to_write_into_an_input_s_folder(merge, tmp_path, monkeypatch, capsys):
    runs = tmp_path / "job" / "paper_task_runs.csv"
    runs.parent.mkdir()
    task_records().to_csv(runs, index=False)
    before = runs.read_bytes()
    code, _, err = run_main(merge, monkeypatch, capsys, runs, "--out", tmp_path / "job" / ".." / "job")
    assert_option_error(code, err, "--out", str(runs))
    assert runs.read_bytes() == before


# --- paper_task_runs.py -------------------------------------------------------------------------------------------


def write_result(out: Path, algo: str, seed: int, mqi: float, **spec_fields) -> None:
    """A ``result.json`` of ``sb3-dtdpg train`` (the spec as RunSpec stores it) under a unique run id."""
    spec = {
        "algo": algo,
        "multiple_access": "noma",
        "seed": seed,
        "episodes": 500,
        "channel": "radio_map",
        "learning_rate": None,
        "env_id": "NomaRadioMapPaper-v0",
        "scenario": None,
        "hyperparams": "paper",
        "observation": "paper",
        "overrides": [["gamma", "0.95"]],
        **spec_fields,
    }
    run_id = f"{algo}_noma_s{seed}_{len(list(out.glob('runs/*')))}"
    result = {"spec": spec, "eval": {"summary": {"success_rate": 1.0, "mqi": mqi}}, "train": {"wall_s": 2.0}}
    (out / "runs" / run_id).mkdir(parents=True)
    (out / "runs" / run_id / "result.json").write_text(json.dumps(result))


@pytest.fixture
def task_folder(task_runs, tmp_path, monkeypatch):
    """Runs of two seeds per algorithm, and seed 0 of each with a learning rate, with episodes or a channel changed."""
    monkeypatch.setattr(task_runs, "training_success", lambda log_dir: (0.5, 0.25, 0.75, 500))
    for seed in (0, 1):
        write_result(tmp_path, "dtdpg", seed, 850.0 + seed)
        write_result(tmp_path, "ddpg", seed, 800.0 + 3 * seed)
    write_result(tmp_path, "dtdpg", 0, 700.0, learning_rate=0.01)  # sb3-dtdpg train --hyperparams learning_rate:0.01
    write_result(tmp_path, "ddpg", 0, 600.0, learning_rate=0.01)
    write_result(tmp_path, "ddpg", 0, 500.0, episodes=1000)
    write_result(tmp_path, "ddpg", 0, 400.0, channel="rayleigh")
    return tmp_path


def test_paper_task_runs_keeps_a_changed_learning_rate_a_configuration_of_its_own(task_runs, task_folder):
    rows = task_runs.run_rows(task_folder)
    assert set(rows["learning_rate"].dropna()) == {0.01}
    assert sorted(rows["budget_episodes"]) == [500] * 7 + [1000]
    summary = task_runs.summary_rows(rows)
    assert len(summary) == 6
    default = summary[
        summary["learning_rate"].isna() & (summary["budget_episodes"] == 500) & (summary["channel"] == "radio_map")
    ]
    assert list(default["algo"]) == ["dtdpg", "ddpg"] and list(default["n"]) == [2, 2]
    assert list(default["test_mqi"].str[:5]) == ["850.5", "801.5"]
    lone = summary[summary["n"] == 1]
    assert len(lone) == 4 and lone["test_mqi"].str.endswith("± n/a").all()  # one seed: no CI, never "± nan"
    # Each learning rate pairs with its own: two pairs at the default, one at 0.01; no pair across episodes/channels
    paired = task_runs.paired_rows(rows)
    assert sorted(paired["n"]) == [1, 2]
    assert set(paired.loc[paired["n"] == 2, "test_mqi"].str[:4]) == {"49.0"}
    assert list(paired.loc[paired["n"] == 1, "test_mqi"]) == ["100.0 ± n/a"]


def test_paper_task_runs_prints_the_configurations_that_differ(task_runs, task_folder, monkeypatch, capsys):
    code, out, err = run_main(task_runs, monkeypatch, capsys, task_folder, "--csv", task_folder / "table" / "runs.csv")
    assert code is None, err
    assert "nan" not in out.lower() and "± n/a" in out
    header = out.splitlines()[0]
    assert header.startswith("every run:") and "env_id NomaRadioMapPaper-v0" in header and "learning_rate" not in header
    tables = "\n".join(out.splitlines()[1:])
    assert all(column in tables for column in ("learning_rate", "budget_episodes", "channel", "0.01", "rayleigh"))
    assert len(pd.read_csv(task_folder / "table" / "runs.csv")) == 8


# --- power_shares.py ----------------------------------------------------------------------------------------------


def test_power_shares_refuses_a_bad_budget_and_seed_count_in_one_line(shares, tmp_path, monkeypatch, capsys):
    out = tmp_path / "power_shares"
    code, _, err = run_main(shares, monkeypatch, capsys, "--budget", "bogus", "--out", out)
    assert_option_error(code, err, "--budget", "'bogus'")
    for seeds in ("0", "-2", "two"):
        code, _, err = run_main(shares, monkeypatch, capsys, "--seeds", seeds, "--out", out)
        assert_option_error(code, err, "--seeds", seeds)
    assert not out.exists()
    code, out_text, _ = run_main(shares, monkeypatch, capsys, "--help")
    assert code == 0 and "count" in out_text


def test_power_shares_reports_runs_of_another_setting_in_out_in_one_line(shares, tmp_path, monkeypatch, capsys):
    from sb3_dtdpg.experiments.runs import RunMismatchError

    target = tmp_path / "tables" / "rows.csv"
    message = "results/runs/dtdpg_noma_s0_tuned_goal/result.json belongs to another run with the same id (spec.channel)"

    def run_many(runs, out, n_workers):
        assert target.parent.is_dir()  # a bad --csv fails before the training
        assert {spec.channel for spec in runs} == {"rayleigh"} and len(runs) == 2
        raise RunMismatchError(message)

    monkeypatch.setattr(shares, "run_many", run_many)
    argv = ("--budget", "tiny", "--seeds", "1", "--modes", "noma", "--channel", "rayleigh", "--csv", target)
    code, _, err = run_main(shares, monkeypatch, capsys, *argv, "--out", tmp_path / "out")
    assert_option_error(code, err, message)


def test_power_shares_table_of_one_seed_says_n_a(shares):
    from sb3_dtdpg.experiments.compare import BEST_PLANNER, SHORTEST_PATH_PLANNER

    rows = pd.DataFrame(
        [
            {"algo": "dtdpg", "multiple_access": "noma", "power_mapping": mapping, "seed": 0, "mqi": mqi, "success_rate": 1.0}
            for mapping, mqi in (("paper", 800.0), ("shares", 820.0))
        ]
    )
    planners = {(BEST_PLANNER, "NOMA"): 900.0, (SHORTEST_PATH_PLANNER, "NOMA"): 850.0}
    text = "\n".join(shares.summary_lines(rows, planners, 20))
    assert "nan" not in text
    assert "| paper | 1 | 800.0 ± n/a |" in text and "| shares | 1 | 820.0 ± n/a |" in text
    assert "| 1 | +20.0 ± n/a (shares ahead on 1 of 1 seeds)" in text
