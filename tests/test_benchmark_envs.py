"""Benchmark scripts: `targets.py` trains on the observation layout it names, `paper_task_runs.py` tabulates runs."""

import json

import gymnasium as gym
import pytest
from scripts import load_script

import noma_radiomap  # noqa: F401


@pytest.mark.parametrize("observation", ["goal", "destinations"])
def test_targets_trains_on_the_env_layout_it_names(observation):
    targets = load_script("targets")
    env = targets._make_env("NomaRadioMap-v0", observation, scenario="small")
    reference = gym.make("NomaRadioMap-v0", observation=observation, scenario="small")
    assert env.observation_space == reference.observation_space  # no second set of goal features
    obs, _ = env.reset(seed=3)
    expected, _ = reference.reset(seed=3)
    assert (obs == expected).all()


def test_targets_env_kwargs_may_name_another_layout():
    targets = load_script("targets")
    env = targets._make_env("NomaRadioMap-v0", "goal", scenario="small", observation="destinations")
    assert env.unwrapped.observation == "destinations"


def test_paper_task_runs_reads_training_success_and_tests_per_run(tmp_path):
    paper_task_runs = load_script("paper_task_runs")
    for algo, successes, mqi in (("ddpg", [0, 0, 1, 1], 800.0), ("dtdpg", [1, 1, 1, 0], 850.0)):
        _fake_paper_task_run(tmp_path, algo, "noma", 0, successes, mqi)
    rows = paper_task_runs.run_rows(tmp_path)
    assert list(rows["algo"]) == ["dtdpg", "ddpg"] and set(rows["overrides"]) == {"gamma:0.95"}
    assert list(rows["train_success"]) == [0.75, 0.5] and list(rows["episodes"]) == [4, 4]
    assert list(rows["test_mqi"]) == [850.0, 800.0]
    paired = paper_task_runs.paired_rows(rows)
    assert list(paired["contrast"]) == ["dtdpg - ddpg"] and list(paired["n"]) == [1]
    assert paired["train_success"].iloc[0].startswith("25.0 ± ") and paired["test_mqi"].iloc[0].startswith("50.0 ± ")
    summary = paper_task_runs.summary_rows(rows)
    assert list(summary["algo"]) == ["dtdpg", "ddpg"] and list(summary["train_success"].str[:4]) == ["75.0", "50.0"]
    figure = paper_task_runs.plot_success(rows, tmp_path, tmp_path / "success.png")
    curves = {line.get_label(): line.get_ydata() for line in figure.axes[0].get_lines() if "seed" in line.get_label()}
    assert set(curves) == {"DT-DPG paper gamma:0.95 NOMA (1 seed)", "DDPG paper gamma:0.95 NOMA (1 seed)"}
    assert curves["DT-DPG paper gamma:0.95 NOMA (1 seed)"][-1] == pytest.approx(0.75)  # all 4 episodes in the window
    assert (tmp_path / "success.png").stat().st_size > 0


def _fake_paper_task_run(out, algo, access, seed, successes, mqi, overrides=(("gamma", "0.95"),), tag=""):
    """A finished ``sb3-dtdpg train`` run of the paper's task in ``out``: its result and its success per episode."""
    from stable_baselines3.common.logger import configure

    run_id = f"{algo}_{access}_s{seed}{'_' + tag if tag else ''}_hp{len(overrides)}"
    logger = configure(str(out / "tb" / run_id), ["tensorboard"])
    for episode, success in enumerate(successes, start=1):
        logger.record("mission/success", float(success))
        logger.record("episode/number", episode)
        logger.dump(episode)
    logger.close()
    (out / "runs" / run_id).mkdir(parents=True)
    spec = {"algo": algo, "hyperparams": "paper", "overrides": [list(item) for item in overrides], "multiple_access": access}
    spec.update(seed=seed, episodes=len(successes), env_id="NomaRadioMapPaper-v0", observation="paper", tag=tag)
    result = {"spec": spec, "eval": {"summary": {"success_rate": 1.0, "mqi": mqi}}, "train": {"wall_s": 2.0}}
    (out / "runs" / run_id / "result.json").write_text(json.dumps(result))


def test_paper_task_runs_joins_earlier_tables_and_pairs_noma_with_oma(tmp_path, monkeypatch, capsys):
    paper_task_runs = load_script("paper_task_runs")
    noma, oma = tmp_path / "noma", tmp_path / "oma"
    for seed in (0, 1):
        _fake_paper_task_run(noma, "dtdpg", "noma", seed, [1, 1, 1, 0], 850.0 + seed)
        _fake_paper_task_run(noma, "ddpg", "noma", seed, [0, 0, 1, 1], 800.0)
        _fake_paper_task_run(oma, "dtdpg", "oma", seed, [1, 0, 0, 0], 840.0)
    _fake_paper_task_run(oma, "dtdpg", "noma", 0, [1, 1, 1, 0], 852.0)  # in both sources: the folder's counts, once
    table = tmp_path / "noma.csv"
    paper_task_runs.run_rows(noma).to_csv(table, index=False)
    rows = paper_task_runs.with_tables(paper_task_runs.run_rows(oma), [table])
    assert len(rows) == 6 and rows["run_id"].is_unique
    assert sorted(zip(rows["algo"], rows["multiple_access"], strict=True)) == sorted(
        [("dtdpg", "noma")] * 2 + [("ddpg", "noma")] * 2 + [("dtdpg", "oma")] * 2
    )
    assert list(paper_task_runs.summary_rows(rows)["n"]) == [2, 2, 2]  # one configuration per downlink and algorithm
    access = paper_task_runs.access_rows(rows)
    assert list(access["algo"]) == ["dtdpg"] and list(access["n"]) == [2]
    assert access["train_success"].iloc[0].startswith("50.0 ± ") and access["test_mqi"].iloc[0].startswith("11.5 ± ")
    command = ["paper_task_runs.py", str(oma), "--with-csv", str(table), "--csv", str(tmp_path / "all.csv")]
    monkeypatch.setattr("sys.argv", command)
    paper_task_runs.main()
    assert "NOMA - OMA" in capsys.readouterr().out and len(paper_task_runs.pd.read_csv(tmp_path / "all.csv")) == 6
    (tmp_path / "other.csv").write_text("run_id,algo\nx,dtdpg\n")
    monkeypatch.setattr("sys.argv", ["paper_task_runs.py", str(oma), "--with-csv", str(tmp_path / "other.csv")])
    with pytest.raises(SystemExit) as exit_info:
        paper_task_runs.main()
    assert exit_info.value.code == 2 and "not a table of this script (no columns preset, " in capsys.readouterr().err


def test_paper_task_runs_pairs_an_ablation_s_runs_with_each_algorithm_of_its_set_up(tmp_path):
    paper_task_runs = load_script("paper_task_runs")
    phases = "[{'name': 'a', 'reward_phase': 'combined', 'n_episodes': 2}, {'name': 'b', 'reward_phase': 'combined'}]"
    for seed in (0, 1):
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [1, 1, 1, 0], 850.0)
        _fake_paper_task_run(tmp_path, "ddpg", "noma", seed, [0, 0, 0, 0], 800.0)
        ablation = (("gamma", "0.95"), ("phases", phases))
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [0, 1, 0, seed], 820.0 + seed, overrides=ablation)
    rows = paper_task_runs.run_rows(tmp_path)
    assert list(paper_task_runs.paired_rows(rows)["n"]) == [2]  # DT-DPG - DDPG in the set-up without an ablation's
    ablation = paper_task_runs.override_rows(rows)
    assert list(ablation["contrast"]) == [
        "dtdpg gamma:0.95 phases:combined/combined - dtdpg gamma:0.95",
        "dtdpg gamma:0.95 phases:combined/combined - ddpg gamma:0.95",
    ]
    assert list(ablation["n"]) == [2, 2] and list(ablation["multiple_access"]) == ["noma", "noma"]
    assert [text.split(" ± ")[0] for text in ablation["train_success"]] == ["-37.5", "37.5"]
    assert [text.split(" ± ")[0] for text in ablation["test_mqi"]] == ["-29.5", "20.5"]
    figure = paper_task_runs.plot_success(rows, tmp_path, tmp_path / "success.png")
    labels = {line.get_label().replace("\n", " ") for line in figure.axes[0].get_lines() if "seed" in line.get_label()}
    assert "DT-DPG paper gamma:0.95 phases:combined/combined NOMA (2 seeds)" in labels  # on two lines


def test_paper_task_runs_names_a_tagged_ablation_by_its_tag_and_pairs_it_with_its_set_up(tmp_path):
    paper_task_runs = load_script("paper_task_runs")
    phases = "[{'name': 'a', 'reward_phase': 'combined', 'n_episodes': 2}, {'name': 'b', 'reward_phase': 'combined'}]"
    for seed in (0, 1):
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [1, 1, 1, 0], 850.0)
        ablation = (("gamma", "0.95"), ("phases", phases))
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [0, 1, 0, 0], 820.0, overrides=ablation, tag="no_curriculum")
    rows = paper_task_runs.run_rows(tmp_path)
    ablation = paper_task_runs.override_rows(rows)
    assert list(ablation["contrast"]) == ["dtdpg no_curriculum - dtdpg gamma:0.95"]  # paired although the tags differ
    assert list(ablation["n"]) == [2] and [text.split(" ± ")[0] for text in ablation["train_success"]] == ["-50.0"]
    figure = paper_task_runs.plot_success(rows, tmp_path, tmp_path / "success.png")
    labels = {line.get_label().replace("\n", " ") for line in figure.axes[0].get_lines() if "seed" in line.get_label()}
    assert labels == {"DT-DPG paper gamma:0.95 NOMA (2 seeds)", "DT-DPG paper NOMA no_curriculum (2 seeds)"}


def test_paper_task_runs_names_runs_by_their_overrides_where_one_tag_covers_several(tmp_path):
    paper_task_runs = load_script("paper_task_runs")
    for seed in (0, 1):
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [1, 1, 0], 850.0, tag="sweep")
        more = (("gamma", "0.95"), ("tau", "0.01"))
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [0, 1, 0], 820.0, overrides=more, tag="sweep")
    rows = paper_task_runs.run_rows(tmp_path)
    assert paper_task_runs.naming_tags(rows) == set()
    assert list(paper_task_runs.override_rows(rows)["contrast"]) == ["dtdpg gamma:0.95 tau:0.01 - dtdpg gamma:0.95"]
    figure = paper_task_runs.plot_success(rows, tmp_path, tmp_path / "success.png")
    labels = {line.get_label().replace("\n", " ") for line in figure.axes[0].get_lines() if "seed" in line.get_label()}
    assert labels == {"DT-DPG paper gamma:0.95 NOMA (2 seeds)", "DT-DPG paper gamma:0.95 tau:0.01 NOMA (2 seeds)"}


def test_paper_task_runs_reads_reproduce_s_paper_task_runs_as_train_runs_of_their_preset(tmp_path):
    paper_task_runs = load_script("paper_task_runs")
    phases = "[{'name': 'a', 'reward_phase': 'combined'}]"
    no_norm = (("phases", phases), ("policy_kwargs", "dict(actor_norm='none')"))
    for seed in (0, 4):
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [1, 0], 810.0, overrides=(("phases", phases),))
        _fake_paper_task_run(tmp_path, "dtdpg", "noma", seed, [0, 0], 800.0, overrides=no_norm)
    header = "group,preset,algorithm,algo,multiple_access,training,episodes,learning_rate,tag,seed,success_rate,mqi,"
    header += "train_wall_s,train_success,train_success_first,train_success_last,train_episodes,scenario,eval_episodes\n"
    rows = [
        f"{algo}_noma_paper_task_500,paper,X,{algo},NOMA,radio_map,2,,paper_task_500,{seed},1.0,{mqi},9.0,{success},"
        f"{success},{success},2,{scenario},{20 if scenario else ''}"
        for algo, success, mqi in (("dtdpg", 1.0, 850.0), ("ddpg", 0.25, 830.0))
        for seed, scenario in ((0, ""), (4, "mall"))  # rows of a later job name the default room
    ]
    (tmp_path / "reproduce.csv").write_text(header + "\n".join(rows) + "\n")
    runs = paper_task_runs.with_tables(paper_task_runs.run_rows(tmp_path), [tmp_path / "reproduce.csv"])
    assert len(runs) == 8 and set(runs["run_id"]) >= {"dtdpg_noma_paper_task_500_s0", "ddpg_noma_paper_task_500_s4"}
    assert list(paper_task_runs.summary_rows(runs)["n"]) == [2, 2, 2, 2]  # the named room is the default one
    ablation = paper_task_runs.override_rows(runs).set_index("contrast")
    no_norm = "dtdpg phases:combined policy_kwargs:dict(actor_norm='none')"
    assert sorted(ablation.index) == sorted(
        [
            "dtdpg phases:combined - dtdpg",
            "dtdpg phases:combined - ddpg",
            f"{no_norm} - dtdpg phases:combined",  # one override more
            f"{no_norm} - dtdpg",  # and two
            f"{no_norm} - ddpg",
        ]
    )
    assert set(ablation["n"]) == {2}
    assert ablation.loc["dtdpg phases:combined - dtdpg", "train_success"].startswith("-50.0 ± ")
    assert ablation.loc["dtdpg phases:combined - ddpg", "train_success"].startswith("25.0 ± ")
    assert ablation.loc["dtdpg phases:combined - ddpg", "test_mqi"].startswith("-20.0 ± ")
    assert ablation.loc[f"{no_norm} - ddpg", "train_success"].startswith("-25.0 ± ")


def test_paper_task_runs_counts_timestep_runs_stored_with_the_unused_episodes_as_one_configuration(tmp_path):
    paper_task_runs = load_script("paper_task_runs")
    for seed, episodes in ((0, 500), (1, None)):  # stored before and after train --timesteps recorded no episodes
        run_id = f"ddpg_noma_s{seed}"
        (tmp_path / "runs" / run_id).mkdir(parents=True)
        spec = {"algo": "ddpg", "multiple_access": "noma", "seed": seed, "episodes": episodes, "timesteps": 300}
        result = {"spec": spec, "eval": {"summary": {"success_rate": 1.0, "mqi": 800.0}}, "train": {"wall_s": 2.0}}
        (tmp_path / "runs" / run_id / "result.json").write_text(json.dumps(result))
    rows = paper_task_runs.run_rows(tmp_path)
    assert rows["budget_episodes"].isna().all() and list(rows["timesteps"]) == [300, 300]
    assert list(paper_task_runs.summary_rows(rows)["n"]) == [2]


def test_learner_gap_measures_only_the_run_folders_of_its_pattern(tmp_path):
    # reproduce keeps several experiments' runs in one folder; --runs picks one experiment's (the table pools by
    # algorithm and mode): a folder matching no pattern is never loaded (this one's model is not a zip)
    gap = load_script("learner_gap")
    run = tmp_path / "runs" / "dtdpg_noma_s0_radio_map_500_lr0.0001_tuned_goal"
    run.mkdir(parents=True)
    (run / "model.zip").write_bytes(b"not a model")
    with pytest.raises(SystemExit, match=r"no models in .*runs/\*_500_tuned_goal/model\.zip"):
        gap.measure(tmp_path, 1, 0, runs="*_500_tuned_goal")
    with pytest.raises(Exception, match="zip"):  # matched: loaded
        gap.measure(tmp_path, 1, 0, runs="*_lr0.0001_tuned_goal")


def test_learner_gap_splits_a_policy_s_mqi_into_its_path_and_its_power_split():
    # The decomposition of benchmarks/learner_gap.py: the shortest paths with the exact best split lose nothing to
    # their split; with the radio-blind equal split they lose what the best split on the same positions gains.
    from noma_radiomap.planners import ShortestPathPlanner

    gap = load_script("learner_gap")
    env = gym.make("NomaRadioMap-v0", channel="radio_map", multiple_access="noma")
    records = {power: gap.mission_splits(ShortestPathPlanner(power=power), env, 3, 10_000) for power in ("best", "equal")}
    for best, equal in zip(records["best"], records["equal"], strict=True):
        assert best["power_loss"] == 0.0 and best["outage_steps"] == best["outage_best_power"]
        assert equal["steps"] == best["steps"]  # the same paths
        assert equal["outage_best_power"] == best["outage_best_power"]
        assert equal["mqi_best_power"] == pytest.approx(best["mqi"])
        assert equal["power_loss"] >= 0.0
        # The best split already transmits the whole P_max; scaling a split up in the same ratio never adds outages
        assert best["outage_full_power"] == best["outage_steps"]
        assert equal["outage_full_power"] <= equal["outage_steps"]
        assert 0.0 < equal["power_used"] <= 1.0
    assert sum(r["power_loss"] for r in records["equal"]) > 0.0
    # The equal split leaves half of P_max unused once one robot has arrived
    assert min(r["power_used"] for r in records["equal"]) < 1.0
