"""The paper-task experiment of ``reproduce``: its runs, the training success rate it reads and the claim it checks."""

from __future__ import annotations

import dataclasses
import json

import gymnasium as gym
import pandas as pd
import pytest
from stable_baselines3.common.logger import configure

from sb3_dtdpg import cli
from sb3_dtdpg.experiments import paper_task, reproduce
from sb3_dtdpg.experiments.reproduce import job_specs, reproduce_specs, run_reproduce
from sb3_dtdpg.experiments.runs import get_budget, result_path, run_identity

MICRO = get_budget("_micro")


def _write_successes(log_dir, successes):
    logger = configure(str(log_dir), ["tensorboard"])
    for episode, success in enumerate(successes, start=1):
        logger.record("mission/success", float(success))
        logger.record("episode/number", episode)
        logger.dump(episode)
    logger.close()


def _fake_result(spec, mqi):
    summary = {"n_episodes": 1.0, "success_rate": 0.0, "mqi": mqi, "outage_steps": 3.0, "mission_time": 9.0}
    return {
        "identity": run_identity(spec),
        "spec": dataclasses.asdict(spec),
        "run_id": spec.run_id,
        "group": spec.group,
        "train": {"timesteps": 10, "episodes": spec.episodes, "wall_s": 1.0, "steps_per_s": 1.0},
        "eval": {"summary": summary, "episodes": [], "trajectories": []},
    }


def test_the_runs_are_the_paper_task_with_both_presets_and_their_own_ids():
    experiments = reproduce_specs(MICRO, seeds=2)
    specs = experiments["paper_task"]
    assert {(s.algo, s.hyperparams, s.multiple_access, s.seed) for s in specs} == {
        (a, h, m, seed) for a in ("dtdpg", "ddpg") for h in ("paper", "tuned") for m in ("noma", "oma") for seed in (0, 1)
    }
    assert {(s.env_id, s.observation, s.channel, s.episodes) for s in specs} == {
        ("NomaRadioMapPaper-v0", "paper", "radio_map", MICRO.episodes)
    }
    others = {s.run_id for name, group in experiments.items() if name != "paper_task" for s in group}
    ids = [s.run_id for s in specs]
    assert len(set(ids)) == len(ids) and others.isdisjoint(ids)  # one output folder holds every experiment
    env = gym.make(specs[0].env_id, **specs[0].env_kwargs)
    assert env.observation_space.shape == (3 * 2,)  # Eq. (24): position and gain per robot, nothing else
    assert env.unwrapped.scenario.mission.max_steps == 1000
    # "reality" training: the same runs with Rayleigh fading for Table II's longer budget, under ids of their own
    reality = experiments["paper_task_reality"]
    assert [dataclasses.replace(s, channel="radio_map", episodes=MICRO.episodes, tag="") for s in reality] == [
        dataclasses.replace(s, tag="") for s in specs
    ]
    assert {(s.channel, s.episodes) for s in reality} == {("rayleigh", MICRO.task_long_episodes)}
    assert {s.run_id for s in reality}.isdisjoint(others - {s.run_id for s in reality})


def test_training_success_is_read_per_episode_from_the_run_log(tmp_path):
    _write_successes(tmp_path, [0, 0, 1, 0, 1, 1])
    overall, first, last, episodes = paper_task.training_success(tmp_path, window=3)
    assert (overall, first, last, episodes) == (pytest.approx(0.5), pytest.approx(1 / 3), pytest.approx(2 / 3), 6)
    assert paper_task.training_success(tmp_path / "absent")[3] == 0


def test_the_paper_claim_is_not_judged_without_training_logs(tmp_path):
    specs = [s for s in paper_task.paper_task_specs(MICRO, seeds=1, modes=("noma",)) if s.hyperparams == "paper"]
    results = {spec.run_id: _fake_result(spec, mqi=100.0) for spec in specs}  # no TensorBoard logs written
    summary = paper_task.paper_task_tables(tmp_path, MICRO, specs, results, progress=False).set_index("algorithm")
    assert summary.loc["DDPG", "paper_claim"] == "< 20 %: n/a (no training logs)"  # was "does not hold"
    assert summary.loc["DT-DPG", "paper_claim"] == "> 95 %: n/a (no training logs)"


def test_the_table_checks_the_paper_claim_and_pairs_by_seed(tmp_path):
    specs = [s for s in paper_task.paper_task_specs(MICRO, seeds=2, modes=("noma",)) if s.hyperparams == "paper"]
    # DDPG finds the destination in 10 % of its episodes (the paper: < 20 %), DT-DPG in 50 % or 70 % (not > 95 %)
    rates = {("ddpg", 0): [1] + [0] * 9, ("ddpg", 1): [0] * 9 + [1], ("dtdpg", 0): [1, 0] * 5, ("dtdpg", 1): [1] * 7 + [0] * 3}
    results = {}
    for spec in specs:
        _write_successes(tmp_path / "tb" / spec.run_id, rates[spec.algo, spec.seed])
        results[spec.run_id] = _fake_result(spec, mqi=100.0 * (1 + spec.seed) + (50.0 if spec.algo == "dtdpg" else 0.0))
    summary = paper_task.paper_task_tables(tmp_path, MICRO, specs, results, progress=False).set_index("algorithm")
    assert summary.loc["DDPG", "train_success"] == pytest.approx(0.1)
    assert summary.loc["DT-DPG", "train_success"] == pytest.approx(0.6)
    assert summary.loc["DDPG", "paper_claim"] == "< 20 %: holds"  # 10 % on both seeds
    # 50 % and 70 %: the mean is short of 95 %, the t-interval of two seeds is not
    assert summary.loc["DT-DPG", "paper_claim"].startswith("> 95 %: does not hold on the mean (its CI reaches up to ")
    # the planners on the same missions, and the learners as a fraction of them
    assert summary.loc["best planner", "mqi_of_best"] == 1.0 and summary.loc["best planner", "preset"] == "-"
    assert summary.loc["DT-DPG", "mqi_of_shortest"] == pytest.approx(
        summary.loc["DT-DPG", "mqi"] / summary.loc["shortest-path planner", "mqi"]
    )
    paired = pd.read_csv(tmp_path / "paper_task_paired.csv").iloc[0]
    assert paired["n"] == 2 and paired["mqi"] == pytest.approx(50.0) and paired["train_success"] == pytest.approx(0.5)
    assert paired["train_success_last"] == paired["train_success_first"] == pytest.approx((0.5 + 0.7) / 2 - 0.1)  # 10 < 100
    for name in ("paper_task.md", "paper_task_runs.csv", "fig_paper_task_success.png"):
        assert (tmp_path / name).stat().st_size > 0
    # the same runs as if trained with Rayleigh fading: tables of their own, which say so
    paper_task.paper_task_tables(tmp_path, MICRO, specs, results, progress=False, channel="rayleigh")
    assert "with Rayleigh fading" in (tmp_path / "paper_task_reality.md").read_text().splitlines()[0]
    assert pd.read_csv(tmp_path / "paper_task_reality_runs.csv").equals(pd.read_csv(tmp_path / "paper_task_runs.csv"))
    assert (tmp_path / "fig_paper_task_reality_success.png").stat().st_size > 0


def test_reproduce_trains_only_the_chosen_modes(tmp_path):
    with pytest.raises(ValueError, match=r"multiple_access: unknown \['cdma'\]"):
        run_reproduce(tmp_path, budget="_micro", seeds=1, experiments=["paper_task"], multiple_access=["cdma"])
    specs = reproduce_specs(MICRO, seeds=1)["paper_task"]
    for spec in specs:
        if spec.multiple_access == "oma":  # finished: nothing of the chosen runs is left to train
            path = result_path(tmp_path, spec)
            path.parent.mkdir(parents=True)
            path.write_text(json.dumps(_fake_result(spec, mqi=1.0)))
    tables = run_reproduce(
        tmp_path, budget="_micro", seeds=1, progress=False, experiments=["paper_task"], multiple_access=["oma"]
    )
    assert not any(result_path(tmp_path, s).exists() for s in specs if s.multiple_access == "noma")
    learners = tables["paper_task"][tables["paper_task"]["preset"] != "-"]
    assert set(tables["paper_task"]["multiple_access"]) == {"OMA"} and len(learners) == 4
    assert "| OMA | 1 seed |" in (tmp_path / "paper_task.md").read_text()


def test_a_chosen_preset_trains_only_its_half_of_the_paper_task():
    both = job_specs(MICRO, 1, "tuned", experiments=["paper_task", "ddpg_vs_dtdpg"])
    table_i = job_specs(MICRO, 1, "tuned", experiments=["paper_task", "ddpg_vs_dtdpg"], paper_task_presets=["paper"])
    paper_runs = {s.run_id for s in reproduce_specs(MICRO, 1)["paper_task"]}
    assert {s.hyperparams for s in both if s.run_id in paper_runs} == {"paper", "tuned"}
    assert {s.hyperparams for s in table_i if s.run_id in paper_runs} == {"paper"}
    # the other experiments keep their own set: the filter is the paper task's
    assert [s for s in both if s.run_id not in paper_runs] == [s for s in table_i if s.run_id not in paper_runs]
    assert len(table_i) == len(both) - len(paper_runs) // 2
    with pytest.raises(ValueError, match=r"paper_task_presets: unknown \['table_i'\], expected some of \['paper', 'tuned'\]"):
        job_specs(MICRO, 1, paper_task_presets=["table_i"])
    with pytest.raises(ValueError, match=r"paper_task_presets: expected a list of names, got the string 'paper'"):
        job_specs(MICRO, 1, paper_task_presets="paper")


@pytest.mark.parametrize(
    ("options", "presets"), [([], None), (["--preset", "tuned"], ["tuned"]), (["--preset", "paper"], ["paper"])]
)
def test_reproduces_preset_option_picks_the_paper_tasks_runs_only_when_given(tmp_path, monkeypatch, options, presets):
    calls = []
    monkeypatch.setattr(reproduce, "run_reproduce", lambda *args, **kwargs: calls.append(kwargs))
    argv = ["reproduce", "--budget", "tiny", "--experiments", "paper_task", "--out", str(tmp_path), "--no-progress"]
    assert cli.main([*argv, *options]) == 0
    assert calls[0]["paper_task_presets"] == presets and calls[0]["hyperparams"] == (presets or ["tuned"])[0]


def test_runs_of_two_folders_merge_into_one_table_and_conflicts_are_refused():
    def runs(preset, algorithm, seeds, mqi=0.0):
        group = f"{algorithm}_{preset}"
        return pd.DataFrame(
            [
                {"group": group, "preset": preset, "algorithm": algorithm, "multiple_access": "NOMA", "seed": seed}
                | {"success_rate": 1.0, "mqi": mqi + seed, "train_success": 0.5}
                for seed in seeds
            ]
        )

    earlier = pd.concat([runs("tuned", "DDPG", [0, 1]), runs("paper", "DT-DPG", [0, 1])])
    later = pd.concat([runs("tuned", "DDPG", [1, 2]), runs("paper", "DT-DPG", [2])])
    merged = paper_task.merge_runs([earlier, later])
    # each run once (seed 1 of DDPG is in both with the same results), Table I first, seeds in order
    assert list(zip(merged["preset"], merged["seed"], strict=True)) == [("paper", s) for s in range(3)] + [
        ("tuned", s) for s in range(3)
    ]
    with pytest.raises(ValueError, match="run DDPG_tuned seed 1: different results"):
        paper_task.merge_runs([earlier, runs("tuned", "DDPG", [1], mqi=5.0)])


def test_a_seed_without_training_logs_leaves_the_others_summarised_and_says_how_many(tmp_path):
    # seed 2 has no training log: its row was all "-" and the claim "n/a", for the two seeds that have one
    specs = [s for s in paper_task.paper_task_specs(MICRO, seeds=3, modes=("noma",)) if s.hyperparams == "paper"]
    results = {}
    for spec in specs:
        if spec.seed != 2:
            _write_successes(tmp_path / "tb" / spec.run_id, [1] + [0] * 9 if spec.algo == "ddpg" else [1] * 9 + [0])
        results[spec.run_id] = _fake_result(spec, mqi=100.0 + spec.seed)
    summary = paper_task.paper_task_tables(tmp_path, MICRO, specs, results, progress=False).set_index("algorithm")
    assert summary.loc["DDPG", "train_success"] == pytest.approx(0.1) and summary.loc["DDPG", "train_success_ci"] == 0.0
    assert summary.loc["DDPG", ["n", "train_n"]].tolist() == [3, 2]
    assert summary.loc["DT-DPG", "train_success_last"] == pytest.approx(0.9)
    assert summary.loc["DDPG", "paper_claim"] == "< 20 %: holds"
    assert summary.loc["DDPG", "mqi"] == pytest.approx(101.0)  # the test metrics of all three seeds
    table = (tmp_path / "paper_task.md").read_text()
    assert "| paper | DDPG | NOMA | 3 seeds (2 with training logs) | 10.0 ± 0.0 |" in table
    paired = pd.read_csv(tmp_path / "paper_task_paired.csv").iloc[0]
    assert (paired["n"], paired["train_n"]) == (3, 2) and paired["train_success"] == pytest.approx(0.8)
    assert "| DT-DPG - DDPG | paper | NOMA | 3 (2 with training logs) | 80.0 ± 0.0 |" in table
    # every seed logged: the cells as before
    for spec in (s for s in specs if s.seed == 2):
        _write_successes(tmp_path / "tb" / spec.run_id, [1] + [0] * 9 if spec.algo == "ddpg" else [1] * 9 + [0])
    paper_task.paper_task_tables(tmp_path, MICRO, specs, results, progress=False)
    assert "| paper | DDPG | NOMA | 3 seeds | 10.0 ± 0.0 |" in (tmp_path / "paper_task.md").read_text()


def test_runs_of_two_budgets_with_the_same_ids_are_not_merged_as_one(tmp_path):
    # mall-200 and small-200 train the paper task 200 episodes: the same run ids. The merge kept one budget's runs as
    # the other's duplicates (same seeds), or one configuration of both budgets' seeds (other seeds)
    def records(budget, seed, **spec_fields):
        specs = paper_task.paper_task_specs(get_budget(budget), seeds=1, modes=("noma",))
        specs = [dataclasses.replace(s, seed=seed, **spec_fields) for s in specs if s.hyperparams == "paper"]
        return paper_task._records(tmp_path, specs, {s.run_id: _fake_result(s, mqi=100.0) for s in specs})

    mall = records("mall-200", 0)
    for seed in (0, 1):
        with pytest.raises(ValueError, match=r"the runs are of several budgets \(scenario: 'mall', 'small'\)"):
            paper_task.merge_runs([mall, records("small-200", seed)])
    assert mall[["scenario", "eval_episodes"]].drop_duplicates().values.tolist() == [["mall", 20]]
    # the seeds of one configuration share one digest; a run of the same id and other settings has another
    later = records("mall-200", 1)
    assert later["configuration"].tolist() == mall["configuration"].tolist()
    assert len(paper_task.merge_runs([mall, later])) == 4
    other = records("mall-200", 1, eval_seed=7)
    with pytest.raises(ValueError, match=r"runs of dtdpg_noma_paper_task_200: several configurations under one id"):
        paper_task.merge_runs([mall, other])
    # a CSV written before these columns existed merges as before, also with the same runs' newer rows
    older = mall.drop(columns=["scenario", "eval_episodes", "configuration"])
    assert len(paper_task.merge_runs([older, mall, later])) == 4
