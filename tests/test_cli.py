"""The ``sb3-dtdpg`` command line: compare writes its table, CSV, figures and event files; reproduce resumes."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from stable_baselines3 import DDPG
from tbparse import SummaryReader

from sb3_dtdpg.cli import main
from sb3_dtdpg.experiments import runs
from sb3_dtdpg.experiments.compare import BEST_PLANNER, SHORTEST_PATH_PLANNER, compare_specs, run_compare
from sb3_dtdpg.experiments.reproduce import reproduce_specs, run_reproduce
from sb3_dtdpg.experiments.runs import BUDGETS, RunSpec, result_path, run_identity

# tbparse 0.0.9 sorts with pandas' deprecated `inplace=True`.
pytestmark = pytest.mark.filterwarnings("ignore:The inplace keyword:DeprecationWarning", "ignore::FutureWarning")

MICRO = BUDGETS["_micro"]  # 3 training episodes on `small`: the pipeline, not the learning


@pytest.fixture(autouse=True)
def _agg_backend(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


def test_compare_writes_table_csv_figures_and_event_files(tmp_path, capsys):
    assert main(["compare", "--budget", "_micro", "--preset", "paper", "--seeds", "2", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "DT-DPG" in printed and "DDPG" in printed and "best planner" in printed and "shortest-path planner" in printed
    for name in ("results.md", "results.csv", "results_runs.csv", "learning_curves.png", "trajectories.png"):
        assert (tmp_path / name).stat().st_size > 0, name

    summary = pd.read_csv(tmp_path / "results.csv")
    learners = summary[summary["ci_over"] == "seeds"]
    assert sorted(zip(learners["algorithm"], learners["multiple_access"], strict=True)) == [
        ("DDPG", "NOMA"),
        ("DDPG", "OMA"),
        ("DT-DPG", "NOMA"),
        ("DT-DPG", "OMA"),
    ]
    assert (learners["n"] == 2).all()
    planners = summary[summary["ci_over"] == "episodes"].set_index(["algorithm", "multiple_access"])
    assert planners.loc[("best planner", "NOMA"), "success_rate"] == 1.0
    # Every row as a fraction of both planners (in its mode); the best planner has its upper bound.
    assert planners.loc[("best planner", "NOMA"), "mqi_of_best"] == 1.0
    assert planners.loc[("shortest-path planner", "OMA"), "mqi_of_shortest"] == 1.0
    assert np.isfinite(learners["mqi_of_best"]).all() and np.isfinite(learners["mqi_of_shortest"]).all()
    assert np.isfinite(planners.loc[("best planner", "OMA"), "mqi_bound"])
    markdown = (tmp_path / "results.md").read_text()
    assert markdown.count("\n| ") == len(summary) + 1  # header + one line per row

    runs = pd.read_csv(tmp_path / "results_runs.csv")
    specs = compare_specs(MICRO, 2, observation="goal")  # the command's default observation
    assert len(runs) == len(specs) == 8
    for spec in specs:
        result = json.loads(result_path(tmp_path, spec).read_text())
        assert result["train"]["episodes"] == MICRO.episodes
        assert result["spec"]["observation"] == "goal"
        assert not (tmp_path / "runs" / spec.run_id / "progress.json").exists()  # removed with the result
        # DT-DPG's 2-episode first phase ends within the 3 episodes: it is evaluated on its last phase's reward
        trained, evaluated = (["destination", "mqi"], "mqi") if spec.algo == "dtdpg" else (["combined"], "combined")
        assert result["reward_phases"] == {"trained": trained, "evaluated": evaluated}
        assert result["eval"]["reward_phase"] == evaluated
        assert len(result["eval"]["episodes"]) == MICRO.eval_episodes
        assert (tmp_path / "runs" / spec.run_id / "model.zip").exists()
        tags = set(SummaryReader(str(tmp_path / "tb" / spec.run_id)).scalars["tag"])
        assert {"mission/mqi", "mission/success_rate", "episode/number", "episode/return"} <= tags, spec.run_id
        if spec.algo == "dtdpg":
            assert "curriculum/phase" in tags


def _fake_result(spec, mqi):
    trajectory = [[[1.0, 1.0], [1.0, 6.0]], [[2.0, 2.0], [2.0, 6.0]]]
    summary = {"n_episodes": 1.0, "success_rate": 1.0, "mqi": mqi, "outage_steps": 3.0, "mission_time": 9.0}
    summary.update({f"{k}_ci": 0.0 for k in ("mqi", "outage_steps", "mission_time", "path_length", "episode_return")})
    return {
        "identity": run_identity(spec),
        "spec": dataclasses.asdict(spec),
        "run_id": spec.run_id,
        "group": spec.group,
        "train": {"timesteps": 60 * spec.episodes, "episodes": spec.episodes, "wall_s": 1.0, "steps_per_s": 1.0},
        "eval": {"summary": summary, "episodes": [], "trajectories": [trajectory]},
    }


def test_the_mqi_scale_of_a_run_is_its_tasks_t_total():
    from sb3_dtdpg.experiments.tables import run_records

    specs = [
        RunSpec("ddpg", "noma", 0, 3, scenario="small", env_id=env_id)
        for env_id in ("NomaRadioMap-v0", "NomaRadioMapPaper-v0")
    ]
    records = run_records([_fake_result(spec, mqi=50.0) for spec in specs])
    assert list(records["mqi_scale"]) == [100.0, 1000.0]  # small's t_total; the paper's task: 1000
    # a run of a scenario file moved since (the same run: its content decides) keeps its scale, from that content
    moved = RunSpec("ddpg", "noma", 0, 3, scenario="/nowhere/room.yaml")
    result = {**_fake_result(specs[0], mqi=50.0), "spec": dataclasses.asdict(moved)}
    assert run_records([result])["mqi_scale"].tolist() == [100.0]


def test_compare_trains_on_the_channel_of_its_env_id():
    assert {spec.channel for spec in compare_specs(MICRO, 1, env_id="NomaRadioMapReality-v0")} == {"rayleigh"}
    assert {spec.channel for spec in compare_specs(MICRO, 1)} == {"radio_map"}


def test_the_api_the_cli_and_the_workers_resolve_a_compare_job_alike(tmp_path):
    # One function resolves a comparison: the env id's observation (the paper task's id: "paper"), the scenario on
    # the budget, a repeated algorithm once; a non-mission env is refused by run_compare itself, before any folder.
    from sb3_dtdpg.experiments.compare import compare_job
    from sb3_dtdpg.experiments.distributed import study_specs

    job = compare_job(MICRO, 1, ["td3", "td3"], ["noma"], "NomaRadioMapPaper-v0", "small", "paper")
    assert (job.observation, job.budget.scenario, job.modes, job.seeds) == ("paper", "small", ["noma"], 1)
    assert [(s.algo, s.observation, s.scenario) for s in job.specs] == [("td3", "paper", "small")]
    assert job.specs == study_specs(
        "compare", "_micro", 1, "paper", None, None, ["noma"], ["td3"], "NomaRadioMapPaper-v0", "small"
    )
    assert compare_job(MICRO, 1).observation == "goal"
    with pytest.raises(ValueError, match="env: compare runs on the NomaRadioMap envs, got Pendulum-v1"):
        run_compare(tmp_path / "out", MICRO, env_id="Pendulum-v1")
    assert not (tmp_path / "out").exists()


def test_a_timestep_budget_sizes_the_destination_phase_by_the_episodes_it_holds():
    # 600 steps of small's 60-step missions hold at least 10 episodes: the MQI phase comes after 6 (was after 300)
    from sb3_dtdpg.baselines import make_env
    from sb3_dtdpg.experiments.specs import build_model

    spec = RunSpec("dtdpg", "noma", 0, None, scenario="small", timesteps=600, hyperparams="paper")
    env = make_env("dtdpg", spec.env_id, "noma", "radio_map", spec.env_kwargs)
    assert build_model(spec, env, _init_setup_model=False).phases[0].n_episodes == 6


def test_ddpg_runs_stored_when_the_set_ran_sb3s_own_ddpg_class_are_the_same_runs(tmp_path):
    """The set's ddpg became LeanDDPG (SB3's DDPG, bit for bit): runs stored with SB3's class name stay this run's."""
    from stable_baselines3 import TD3

    from sb3_dtdpg.dtdpg.lean import LeanDDPG, LeanTD3
    from sb3_dtdpg.experiments.specs import _SAME_RESULT_ALGORITHMS, RunMismatchError, check_identity, identity_digest

    def name(cls):
        return f"{cls.__module__}.{cls.__qualname__}"

    assert _SAME_RESULT_ALGORITHMS == {name(LeanDDPG): name(DDPG), name(LeanTD3): name(TD3)}  # the names as recorded
    identity = run_identity(RunSpec("ddpg", "noma", 0, 20, scenario="small", hyperparams="paper"))
    assert identity["hyperparameters"]["algorithm"] == name(LeanDDPG)
    stored = json.loads(json.dumps(identity))
    stored["hyperparameters"]["algorithm"] = name(DDPG)  # as written before the change (was: "another run")
    check_identity({"identity": stored}, identity, tmp_path / "result.json")
    assert identity_digest(stored) == identity_digest(identity)
    stored["hyperparameters"]["algorithm"] = name(TD3)  # another algorithm is still another run
    with pytest.raises(RunMismatchError, match=r"hyperparameters.algorithm: 'stable_baselines3.td3.td3.TD3' stored"):
        check_identity({"identity": stored}, identity, tmp_path / "result.json")


def test_a_timestep_budget_is_recorded_as_such_not_with_the_unused_episodes_default(tmp_path, monkeypatch, capsys):
    # train --timesteps recorded episodes=500 (--episodes' default, unused) in the run's spec and identity
    from sb3_dtdpg.experiments.specs import RunMismatchError, check_identity

    seen = []

    def record_spec(spec, *args, **kwargs):
        seen.append(spec)
        raise KeyboardInterrupt  # the spec is all this test needs: no training

    monkeypatch.setattr(runs, "run_one", record_spec)
    argv = ["train", "--algo", "ddpg", "--scenario", "small", "--timesteps", "300", "--out", str(tmp_path)]
    assert main([*argv, "--hyperparams", "learning_starts:100", "--no-progress"]) == 130
    (spec,) = seen
    assert (spec.episodes, spec.timesteps) == (None, 300)
    identity = run_identity(spec)
    assert (identity["spec"]["episodes"], identity["spec"]["timesteps"]) == (None, 300)
    # a run stored with the unused count is still this run (same training), one of another budget is not
    stored = json.loads(json.dumps(identity))
    stored["spec"]["episodes"] = 500
    check_identity({"identity": stored}, identity, tmp_path / "result.json")
    stored["spec"]["timesteps"] = 600
    with pytest.raises(RunMismatchError, match=r"spec.timesteps: 600 stored, 300 now"):
        check_identity({"identity": stored}, identity, tmp_path / "result.json")
    # an episode budget's identity is as before (stored runs keep theirs), and a spec is one budget or the other
    assert run_identity(dataclasses.replace(spec, episodes=3, timesteps=None))["spec"]["episodes"] == 3
    with pytest.raises(ValueError, match=r"got episodes=3 and timesteps=300"):
        dataclasses.replace(spec, episodes=3)
    with pytest.raises(ValueError, match=r"got episodes=None and timesteps=None"):
        dataclasses.replace(spec, timesteps=None)


def test_reproduce_skips_finished_runs(tmp_path):
    experiments = reproduce_specs(MICRO, seeds=1)
    unique = list({s.run_id: s for specs in experiments.values() for s in specs}.values())
    # Table II (2 modes x 3 trainings), DDPG (2 modes), the second learning rate (2 modes), the paper task (8), in
    # "reality" (8)
    assert len(unique) == 26
    missing = next(s for s in unique if s.algo == "ddpg" and s.multiple_access == "oma")
    finished = {}
    for spec in unique:
        if spec is not missing:
            path = result_path(tmp_path, spec)
            path.parent.mkdir(parents=True)
            path.write_text(json.dumps(_fake_result(spec, mqi=12345.0)))
            finished[path] = path.read_bytes()

    # --report-only: tables from the finished runs, nothing trained.
    report = run_reproduce(tmp_path, budget="_micro", seeds=1, progress=False, train=False)
    assert not result_path(tmp_path, missing).exists()
    assert ("DDPG", "OMA") not in set(
        zip(*(report["ddpg_vs_dtdpg"][c] for c in ("algorithm", "multiple_access")), strict=True)
    )
    # ... and the table of the missing run says so; the others, whole, say nothing
    note = f"**Incomplete: 1 of 4 runs have no result yet ({missing.run_id});"
    assert note in (tmp_path / "ddpg_vs_dtdpg.md").read_text()
    assert "Incomplete" not in (tmp_path / "table_ii.md").read_text()
    # paired.md reads the same runs: it says so too (it said nothing, its DT-DPG - DDPG OMA row silently gone)
    assert "**Incomplete: 1 of " in (tmp_path / "paired.md").read_text()

    tables = run_reproduce(tmp_path, budget="_micro", seeds=1, progress=False)
    assert "Incomplete" not in (tmp_path / "ddpg_vs_dtdpg.md").read_text()
    assert "Incomplete" not in (tmp_path / "paired.md").read_text()
    for path, content in finished.items():
        assert path.read_bytes() == content  # not re-run ...
        assert not (path.parent / "model.zip").exists()  # ... nor re-trained
    real = json.loads(result_path(tmp_path, missing).read_text())
    assert real["train"]["episodes"] == MICRO.episodes and (tmp_path / "runs" / missing.run_id / "model.zip").exists()

    assert (tables["table_ii"]["mqi"] == 12345.0).all()
    assert set(tables["table_ii"]["paper_mqi"]) == {879.5, 868.5, 876.2, 929.0, 919.0}
    comparison = tables["ddpg_vs_dtdpg"].set_index(["algorithm", "multiple_access"])
    assert comparison.loc[("DDPG", "OMA"), "mqi"] == real["eval"]["summary"]["mqi"] != 12345.0
    # Table II and the learning rates, which have no planner rows, give each row's MQI over the planners' in its mode
    for name in ("table_ii", "learning_rates"):
        table = tables[name]
        for column, planner in (("mqi_of_best", BEST_PLANNER), ("mqi_of_shortest", SHORTEST_PATH_PLANNER)):
            reference = [comparison.loc[(planner, mode), "mqi"] for mode in table["multiple_access"]]
            assert np.allclose(table[column], table["mqi"] / reference), (name, column)
        assert "| of best | of shortest |" in (tmp_path / f"{name}.md").read_text()
    figures = ("fig_maps.png", "fig_reward_learning_rates.png", "fig_mqi_per_episode.png")
    for name in ("table_ii.md", "ddpg_vs_dtdpg.md", "learning_rates.md", "paired.md", *figures):
        assert (tmp_path / name).exists(), name
    assert (tmp_path / "fig_trajectories_noma_oma.png").exists()
    paired = tables["paired"]

    def paired_mqi(contrast: str, mode: str) -> float:
        # the one row of the contrast in the mode (the rows of "NOMA - OMA" have no mode: on a (contrast, mode) index,
        # which then repeats, pandas 2.0's .loc gives a Series of the row, later pandas its value)
        return paired.loc[(paired["contrast"] == contrast) & (paired["multiple_access"] == mode), "mqi"].item()

    # the fake results all score 12345: the paired differences are 0 except against the one real run
    real_vs_fake = paired_mqi("DT-DPG - DDPG", "OMA")
    assert real_vs_fake == pytest.approx(12345.0 - real["eval"]["summary"]["mqi"])
    assert paired_mqi("DT-DPG - DDPG", "NOMA") == 0.0


def test_reproduce_with_tuned_hyperparameters_compares_the_paper_learning_rate():
    experiments = reproduce_specs(MICRO, seeds=1, hyperparams="tuned")
    for name in ("paper_task", "paper_task_reality"):  # both presets on the paper's task, whatever the set
        experiments.pop(name)  # (tests/test_paper_task_experiment.py)
    specs = [s for specs in experiments.values() for s in specs]
    assert {s.hyperparams for s in specs} == {"tuned"} and all(s.run_id.endswith("_tuned_goal") for s in specs)
    assert {s.learning_rate for s in experiments["learning_rates"]} == {None, 1e-4}  # the set's own 1e-3, and 1e-4
    assert {s.learning_rate for s in reproduce_specs(MICRO, seeds=1)["learning_rates"]} == {None, 1e-3}
    paper_ids = {
        s.run_id for name, specs in reproduce_specs(MICRO, seeds=1).items() if not name.startswith("paper_task") for s in specs
    }
    assert paper_ids.isdisjoint(s.run_id for s in specs)  # one output folder can hold both sets


def test_map_and_train_commands(tmp_path):
    assert main(["map", "--scenario", "small", "--out", str(tmp_path / "maps")]) == 0
    assert (tmp_path / "maps" / "maps_small.png").stat().st_size > 0
    args = [
        "train",
        "--algo",
        "ddpg",
        "--preset",
        "paper",
        "--scenario",
        "small",
        "--episodes",
        "2",
        "--eval-episodes",
        "1",
    ]
    args.append("--no-progress")
    assert main([*args, "--tb", str(tmp_path / "tb"), "--out", str(tmp_path / "models")]) == 0
    run_dir = tmp_path / "models" / "runs" / "ddpg_noma_s0_goal"  # the goal-conditioned observation by default
    model = DDPG.load(run_dir / "model.zip")
    assert model.observation_space.shape == (9 * 2,)  # the paper's 6 values per robot, plus direction and distance
    result = json.loads((run_dir / "result.json").read_text())
    assert result["train"]["episodes"] == 2 and len(result["eval"]["episodes"]) == 1
    events = list((tmp_path / "tb" / "ddpg_noma_s0_goal").rglob("events.out.tfevents*"))
    assert events and "mission/mqi" in set(SummaryReader(str(events[0].parent)).scalars["tag"])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["compare", "--budget", "huge"], "budget must be one of"),
        (["compare", "--seeds", "0"], "expected a number of seeds from 1 to 1,000, got '0'"),
        (["train", "--algo", "ppo"], "invalid choice"),
        (["reproduce", "--preset", "fast"], "invalid choice"),
    ],
)
def test_bad_arguments_are_rejected(argv, message, capsys):
    with pytest.raises(SystemExit) as error:
        main(argv)
    assert error.value.code == 2
    assert message in capsys.readouterr().err


def test_the_scenarios_content_not_its_name_decides_a_run(tmp_path):
    # `compare --scenario mall` after a plain `compare` (scenario None: the env id's mall) was refused as another run
    from sb3_dtdpg.experiments.specs import check_identity

    default, named = RunSpec("dtdpg", "noma", 0, 36), RunSpec("dtdpg", "noma", 0, 36, scenario="mall")
    assert default.run_id == named.run_id
    check_identity({"identity": run_identity(default)}, run_identity(named), tmp_path / "result.json")
    other = RunSpec("dtdpg", "noma", 0, 36, scenario="small")
    with pytest.raises(runs.RunMismatchError, match=r"scenario\."):
        check_identity({"identity": run_identity(default)}, run_identity(other), tmp_path / "result.json")


def test_the_observation_is_part_of_a_run():
    paper, goal = RunSpec("dtdpg", "noma", 0, 3, observation="paper"), RunSpec("dtdpg", "noma", 0, 3)
    assert goal.run_id == "dtdpg_noma_s0_goal" and paper.run_id == "dtdpg_noma_s0"  # one folder can hold both
    assert goal.env_kwargs == {"observation": "goal"} and paper.env_kwargs == {"observation": "paper"}
    assert run_identity(goal)["spec"]["observation"] == "goal" != run_identity(paper)["spec"]["observation"]
    with pytest.raises(ValueError, match="observation must be one of"):
        run_compare("unused", budget="_micro", observation="relative")


def test_the_power_mapping_is_part_of_a_run_and_the_paper_s_keeps_stored_identities():
    paper = RunSpec("dtdpg", "noma", 0, 3)
    shares = dataclasses.replace(paper, power_mapping="shares")
    assert shares.run_id == "dtdpg_noma_s0_goal_shares" and shares.env_kwargs["power_mapping"] == "shares"
    assert "power_mapping" not in paper.env_kwargs
    # Runs stored before the setting existed have no power_mapping in their identity: they stay these runs
    assert "power_mapping" not in run_identity(paper)["spec"]
    assert run_identity(shares)["spec"]["power_mapping"] == "shares"
    with pytest.raises(ValueError, match=r"power_mapping must be one of \['paper', 'shares'\], got 'equal'"):
        run_identity(dataclasses.replace(paper, power_mapping="equal"))


def test_a_run_reports_its_progress_while_it_trains(tmp_path, monkeypatch):
    records = []
    write = runs.RunProgress._write

    def recording_write(self):
        write(self)
        records.append(json.loads(self.path.read_text()))
        assert runs.read_progress(tmp_path, spec) == records[-1]

    monkeypatch.setattr(runs.RunProgress, "_write", recording_write)
    monkeypatch.setattr(runs.RunProgress, "__init__", _every_step(runs.RunProgress.__init__))
    spec = RunSpec("ddpg", "noma", 0, MICRO.episodes, scenario="small", eval_episodes=1, hyperparams="paper")
    runs.run_one(spec, tmp_path)
    assert records[-1] == {"done": 3, "total": 3, "unit": "episodes", "episodes": 3}
    assert [r["done"] for r in records] == sorted(r["done"] for r in records) and records[0]["done"] == 0
    assert runs.read_progress(tmp_path, spec) is None  # removed once the result is written


def _every_step(init):
    def wrapped(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.interval = 0.0

    return wrapped


def test_reproduce_checks_every_stored_run_it_reports_before_it_trains(tmp_path):
    # A subset (--multiple-access noma) trained its runs first and only then met the OMA runs of other settings
    # that its tables read: the job failed with no tables after training
    experiments = reproduce_specs(MICRO, seeds=1, hyperparams="paper")
    oma = [s for s in experiments["ddpg_vs_dtdpg"] if s.multiple_access == "oma"]
    for spec in oma:  # results written before run identities: other runs' for this job
        result_path(tmp_path, spec).parent.mkdir(parents=True)
        result_path(tmp_path, spec).write_text('{"spec": {}}')
    with pytest.raises(runs.RunMismatchError, match=rf"belongs to another run .*; {len(oma) - 1} more stored runs"):
        run_reproduce(
            tmp_path, budget="_micro", seeds=1, progress=False, experiments=["ddpg_vs_dtdpg"], multiple_access=["noma"]
        )
    assert sorted(path.name for path in (tmp_path / "runs").iterdir()) == sorted(s.run_id for s in oma)  # nothing trained


def test_reproduce_trains_only_the_chosen_experiments(tmp_path, capsys):
    with pytest.raises(ValueError, match=r"experiments: unknown \['table_iii'\]"):
        run_reproduce(tmp_path, budget="_micro", seeds=1, experiments=["table_iii"])
    tables = run_reproduce(tmp_path, budget="_micro", seeds=1, progress=False, experiments=["ddpg_vs_dtdpg"])
    experiments = reproduce_specs(MICRO, seeds=1)
    chosen = {s.run_id for s in experiments["ddpg_vs_dtdpg"]}
    every = {s.run_id for specs in experiments.values() for s in specs}
    # the closing line counts the runs asked for, then those of every experiment
    closing = capsys.readouterr().out.strip().splitlines()[-1]
    assert closing.startswith(
        f"reproduce: {len(chosen)} of {len(chosen)} runs finished (of all experiments' {len(every)} runs, "
    )
    for spec in {s for specs in experiments.values() for s in specs}:
        assert result_path(tmp_path, spec).exists() == (spec.run_id in chosen), spec.run_id
    # the other experiments' tables are drawn from the finished runs they share (the radio-map DT-DPG runs)
    assert set(tables["table_ii"]["training"]) == {"radio_map"} and len(tables["ddpg_vs_dtdpg"]) > 4
    # its statistics figures are named after the experiment: a compare in the same folder keeps its own
    assert (tmp_path / "ddpg_vs_dtdpg_statistics_iqm.png").is_file() and not (tmp_path / "statistics_iqm.png").exists()


def test_reproduce_reports_one_experiment_in_one_mode(tmp_path):
    # `reproduce --experiments table_ii --multiple-access noma`: its paired table has only the training contrasts,
    # so no row has an "approach" label; the report must still be written (it once crashed after all the runs).
    experiments = reproduce_specs(MICRO, seeds=2)
    for spec in experiments["table_ii"]:
        if spec.multiple_access == "noma":
            path = result_path(tmp_path, spec)
            path.parent.mkdir(parents=True, exist_ok=True)
            mqi = 100.0 + spec.seed + (10.0 if spec.channel == "radio_map" else 0.0)
            path.write_text(json.dumps(_fake_result(spec, mqi=mqi)))
    tables = run_reproduce(
        tmp_path, budget="_micro", seeds=2, progress=False, train=False, experiments=["table_ii"], multiple_access=["noma"]
    )
    paired = tables["paired"]
    assert set(paired["contrast"]) == {"radio map E - reality E", "radio map E - reality L"}
    assert (paired["mqi"] == 10.0).all() and (paired["n"] == 2).all()
    text = (tmp_path / "paired.md").read_text()
    assert "| radio map E - reality E | DT-DPG | NOMA | - |" in text


def test_the_transfer_dip_counts_the_seeds_whose_log_was_read(tmp_path):
    # a run without a readable TensorBoard log gives no dip: n said 2 while the mean came from fewer seeds
    from sb3_dtdpg.experiments.reproduce import _dip_table

    experiments = reproduce_specs(MICRO, seeds=2)
    results = {spec.run_id: {"finished": True} for spec in experiments["learning_rates"]}
    dip = _dip_table(tmp_path, experiments, results)
    assert (dip["n"] == 0).all() and dip["final"].isna().all()
    assert (dip[["transfer_episode_n", "before_n", "after_n", "final_n"]] == 0).all().all()  # each column's own count
    assert (tmp_path / "transfer_dip.csv").exists()


def test_train_tag_names_the_run_on_the_mission_envs_and_the_model_on_the_others(tmp_path):
    argv = ["train", "--algo", "ddpg", "--scenario", "small", "--timesteps", "150", "--eval-episodes", "1"]
    argv += ["--hyperparams", "learning_starts:100", "--tag", "short_start", "--out", str(tmp_path), "--no-progress"]
    assert main(argv) == 0
    (run,) = [path.parent.name for path in tmp_path.glob("runs/*/result.json")]
    assert run.startswith("ddpg_noma_s0_short_start_") and [path.name for path in (tmp_path / "tb").iterdir()] == [run]
    argv = ["train", "--algo", "ddpg", "--env", "Pendulum-v1", "--timesteps", "150", "--eval-episodes", "1", "--hyperparams"]
    argv += ["learning_starts:100"]
    assert main([*argv, "--tag", "v2", "--out", str(tmp_path / "pendulum"), "--no-progress"]) == 0
    assert (tmp_path / "pendulum" / "ddpg_Pendulum-v1_s0_v2.zip").is_file()


def test_train_takes_a_torch_class_in_hyperparams_and_resumes_the_run(tmp_path, capsys):
    """``activation_fn=nn.Tanh`` as in the RL Zoo's files: the model gets it, and the run's stored text reads back
    to the same settings (a second command finds the finished run instead of refusing it as another run's)."""
    policy_kwargs = "policy_kwargs:dict(net_arch=[16, 16], activation_fn=nn.Tanh)"
    argv = ["train", "--algo", "ddpg", "--scenario", "small", "--timesteps", "300", "--eval-episodes", "1"]
    argv += ["--hyperparams", "learning_starts:100", policy_kwargs, "--out", str(tmp_path), "--no-progress"]
    assert main(argv) == 0
    (result_file,) = tmp_path.glob("runs/*/result.json")
    assert "'activation_fn': nn.Tanh" in dict(json.loads(result_file.read_text())["spec"]["overrides"])["policy_kwargs"]
    model = DDPG.load(result_file.parent / "model.zip")
    assert [type(layer).__name__ for layer in model.policy.actor.mu] == ["Linear", "Tanh", "Linear", "Tanh", "Linear", "Tanh"]
    stored = result_file.read_text()
    capsys.readouterr()
    assert main(argv) == 0 and result_file.read_text() == stored  # the finished run, not trained again
