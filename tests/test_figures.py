"""Figures and tables a reader understands: legends, out-of-room interferers, the success curve, CI formatting."""

import dataclasses
import importlib.util
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from phased_env import PhasedPointEnv  # noqa: E402
from scipy import stats  # noqa: E402
from stable_baselines3 import DDPG  # noqa: E402
from stable_baselines3.common.logger import configure  # noqa: E402

import sb3_dtdpg  # noqa: E402
from noma_radiomap import RadioMap, load_scenario  # noqa: E402
from sb3_dtdpg.experiments import aggregate, plots, tables  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small():
    return RadioMap.for_scenario(load_scenario("small"))


def legend_texts(legend):
    return [text.get_text() for text in legend.get_texts()]


def test_map_legend_names_every_marker_and_sits_below_the_map(small):
    _, ax = plt.subplots()
    small.plot(ax, kind="sinr")
    labels = " | ".join(legend_texts(ax.get_legend()))
    for expected in ("AP", "interferer", "outage", "obstacle (blocks robots", "hanging obstacle", "outside the room"):
        assert expected in labels
    ax.figure.canvas.draw()
    assert ax.get_legend().get_window_extent().y1 < ax.get_window_extent().y0  # below the map: off the data
    plt.close(ax.figure)


@pytest.mark.parametrize("name", ["small", "mall"])
def test_axes_include_interferers_outside_the_room(name):
    scenario = load_scenario(name)
    _, ax = plt.subplots()
    RadioMap.for_scenario(scenario).plot(ax, legend=False)
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    outside = [i for i in scenario.interferers if not (0 <= i.position[0] <= scenario.room.width)]
    assert outside, "the built-in scenarios have an interferer outside the room"
    for interferer in scenario.interferers:
        assert x0 < interferer.position[0] < x1 and y0 <= interferer.position[1] <= y1
    plt.close(ax.figure)


def test_far_interferer_is_drawn_at_the_wall_with_an_arrow():
    scenario = load_scenario("small")
    far = dataclasses.replace(scenario.interferers[0], position=(40.0, 4.0, 2.0))
    radio_map = RadioMap(dataclasses.replace(scenario, interferers=(far,)))
    _, ax = plt.subplots()
    radio_map.plot(ax, legend=False)
    assert ax.get_xlim() == (0.0, scenario.room.width)  # the map is not shrunk to reach it
    arrows = [a for a in ax.texts if getattr(a, "arrow_patch", None) is not None]
    assert len(arrows) == 1 and arrows[0].xy == pytest.approx((scenario.room.width, 4.0))
    assert any("28 m outside" in t.get_text() for t in ax.texts)
    plt.close(ax.figure)


def test_render_legend_explains_robots_and_map():
    import gymnasium as gym

    import noma_radiomap  # noqa: F401

    env = gym.make("NomaRadioMap-v0", scenario="small", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3
    labels = legend_texts(env.unwrapped._renderer.figure.axes[0].get_legend())
    for expected in ("robot 0", "robot 1", "destination", "path since reset", "AP", "outage"):
        assert any(expected in label for label in labels), expected
    env.close()


def test_trajectory_legend_names_policies_robots_and_markers(tmp_path):
    path = np.stack([np.linspace([1.0, 1.0], [5.0, 2.0], 6), np.linspace([1.0, 7.0], [9.0, 6.0], 6)], axis=1)
    figure = plots.plot_trajectories(
        "small",
        {"NOMA": {"DT-DPG": path, "planner": path + 0.2}},
        tmp_path / "t.png",
        destinations={"NOMA": np.array([[5.0, 2.0], [9.0, 6.0]])},
    )
    assert (tmp_path / "t.png").stat().st_size > 0
    labels = legend_texts(figure.legends[0])
    for expected in ("DT-DPG", "planner", "robot 0", "robot 1", "start", "end of the episode", "destination", "AP"):
        assert any(expected == label or label.startswith(expected) for label in labels), expected
    assert all(ax.get_legend() is None for ax in figure.axes)  # nothing drawn over the maps
    figure.canvas.draw()
    assert figure.legends[0].get_window_extent().y1 < min(ax.get_window_extent().y0 for ax in figure.axes)


def write_run(folder, success, mqi=None):
    logger = configure(str(folder), ["tensorboard"])
    for episode, value in enumerate(success, start=1):
        logger.record("mission/success", float(value))
        logger.record("mission/mqi", float(episode if mqi is None else mqi[episode - 1]))
        logger.record("episode/number", episode)
        logger.dump(step=10 * episode)
    logger.close()
    return folder


def test_success_curve_is_a_plain_rolling_mean(tmp_path):
    success = [0, 0, 1, 1, 0, 1, 1, 1, 0, 1]
    folder = write_run(tmp_path / "run", success)
    curve = plots.rolling_curve(folder, plots.SUCCESS_TAG, window=4)
    expected = pd.Series(success, index=np.arange(1, 11), dtype=float).rolling(4, min_periods=1).mean()
    np.testing.assert_allclose(curve.to_numpy(), expected.to_numpy())
    np.testing.assert_array_equal(curve.index.to_numpy(), np.arange(1, 11))


def test_a_curve_restarts_its_window_at_the_transfer(tmp_path):
    # Episodes 1-3 in the first phase (the third transfers and logs phase 1), 4-6 in the second, another reward.
    logger = configure(str(tmp_path), ["tensorboard"])
    for episode, (value, phase) in enumerate([(100, 0), (110, 0), (120, 1), (-50, 1), (-40, 1), (-30, 1)], start=1):
        logger.record("episode/return", float(value))
        logger.record("mission/mqi", float(value))
        logger.record("curriculum/phase", phase)
        logger.record("episode/number", episode)
        logger.dump(step=10 * episode)
    logger.close()
    curve = plots.rolling_curve(tmp_path, plots.RETURN_TAG, window=3)
    assert list(curve) == [100.0, 105.0, 110.0, -50.0, -45.0, -40.0]  # was (110 + 120 - 50) / 3 = 60 at episode 4
    # the MQI keeps its meaning across the transfer: one window over both phases
    assert plots.rolling_curve(tmp_path, "mission/mqi", window=3)[4] == pytest.approx(60.0)


def test_learning_curves_state_the_window_and_stay_in_range(tmp_path):
    runs = [write_run(tmp_path / f"s{k}", np.random.default_rng(k).integers(0, 2, 30)) for k in range(3)]
    figure = plots.plot_learning_curves({"DT-DPG NOMA": runs, "DDPG NOMA": runs[:1]}, tmp_path / "c.png", smooth=5)
    mqi_ax, success_ax = figure.axes
    assert "rolling mean over the last 5 training episodes" in success_ax.get_ylabel()
    assert "rolling mean over the last 5 training episodes" in mqi_ax.get_ylabel()
    low, high = success_ax.get_ylim()
    assert -0.05 <= low and high <= 1.05
    for band in success_ax.collections:  # the bootstrap band of a rate stays a rate
        vertices = np.concatenate([p.vertices for p in band.get_paths()])
        assert vertices[:, 1].min() >= 0.0 and vertices[:, 1].max() <= 1.0
    labels = legend_texts(figure.legends[0])
    assert "DT-DPG NOMA (3 seeds)" in labels and "DDPG NOMA (1 seed)" in labels


def test_a_mean_cut_at_a_short_run_says_where_it_ends(tmp_path):
    # one run of 10 episodes beside two of 40: the group's mean stops at 10 (it averages every run) and said nothing
    rng = np.random.default_rng(3)
    runs = [write_run(tmp_path / f"s{k}", rng.integers(0, 2, n)) for k, n in enumerate((40, 40, 10))]
    figure = plots.plot_learning_curves({"A": runs, "B": runs[:2]}, tmp_path / "c.png", smooth=5)
    labels = legend_texts(figure.legends[0])
    assert "A (3 seeds, to episode 10 of 40)" in labels and "B (2 seeds)" in labels


def test_learning_curves_of_one_seed_per_group_claim_no_ci(tmp_path):
    runs = [write_run(tmp_path / f"s{k}", np.random.default_rng(k).integers(0, 2, 20)) for k in range(2)]
    title, note = "Learning curves on small, tiny budget", {"band_note": True}  # compare's title
    figure = plots.plot_learning_curves(
        {"DT-DPG NOMA": runs[:1], "DDPG NOMA": runs[1:]}, tmp_path / "a.png", title=title, **note
    )
    assert legend_texts(figure.legends[0]) == ["DT-DPG NOMA (1 seed)", "DDPG NOMA (1 seed)"]  # was a CI entry, no band
    assert figure.get_suptitle() == "Learning curves on small, tiny budget (one seed per curve, no CI)"
    figure = plots.plot_learning_curves({"DT-DPG NOMA": runs, "DDPG NOMA": runs[1:]}, tmp_path / "b.png", title=title, **note)
    assert "95 % bootstrap CI over seeds" in legend_texts(figure.legends[0])
    assert figure.get_suptitle() == f"{title} (mean and 95 % CI over seeds)"


def test_mission_logger_for_a_plain_sb3_algorithm(tmp_path):
    from tbparse import SummaryReader

    from sb3_dtdpg import MissionLoggerCallback

    assert sb3_dtdpg.MissionLoggerCallback is MissionLoggerCallback and "MissionLoggerCallback" in sb3_dtdpg.__all__
    env = PhasedPointEnv(starts=[[0.5, 0.5]], destinations=[[0.5, 0.55]], arrival_radius=0.5)
    model = DDPG("MlpPolicy", env, learning_starts=100, policy_kwargs={"net_arch": [8]}, tensorboard_log=str(tmp_path))
    model.learn(4, callback=sb3_dtdpg.MissionLoggerCallback(), log_interval=1)
    scalars = SummaryReader(str(tmp_path)).scalars
    success = scalars[scalars.tag == "mission/success"].sort_values("step")
    assert list(success["value"]) == [1.0] * 4  # one point per (one-step, successful) episode


def test_iqm_and_stratified_bootstrap():
    scores = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 100.0])
    assert aggregate.iqm(scores) == pytest.approx(stats.trim_mean(scores, 0.25)) == pytest.approx(3.5)
    low, high = aggregate.stratified_bootstrap_ci(scores)
    assert scores.min() <= low <= aggregate.iqm(scores) <= high <= scores.max()
    assert aggregate.stratified_bootstrap_ci(scores) == (low, high)  # seeded
    assert all(math.isnan(b) for b in aggregate.stratified_bootstrap_ci([3.0]))
    # Stratified: each task's runs are resampled within the task, so constant tasks give a point interval.
    by_task = np.array([[1.0, 10.0], [1.0, 10.0], [1.0, 10.0]])
    assert aggregate.stratified_bootstrap_ci(by_task, statistic=np.mean) == pytest.approx((5.5, 5.5))
    band_low, band_high = aggregate.pointwise_bootstrap_ci(np.array([[0.0, 1.0], [1.0, 1.0]]))
    assert np.all(band_low >= [0.0, 1.0]) and np.all(band_high <= [1.0, 1.0])


def records(seeds, scenario="small"):
    rows = [
        {
            "group": "g",
            "spec": {
                "algo": "dtdpg",
                "multiple_access": "noma",
                "channel": "radio_map",
                "episodes": 5,
                "learning_rate": None,
                "tag": "",
                "seed": seed,
                "scenario": scenario,
            },
            "eval": {"summary": {"success_rate": 0.5, "mqi": 40.0 + seed, "outage_steps": 3.0, "mission_time": 20.0}},
            "train": {"timesteps": 100, "wall_s": 1.0},
        }
        for seed in range(seeds)
    ]
    return tables.run_records(rows)


def test_table_says_1_seed_and_n_a_never_nan():
    summary = tables.summarise(records(1))
    text = tables.format_markdown(summary)
    assert "1 seed |" in text and "seeds" not in text
    assert "nan" not in text.lower() and "± n/a" in text and "[n/a]" in text
    assert tables.format_ci(0.5, math.nan, 0, 100.0) == "50 ± n/a"
    assert tables.format_ci(math.nan, 1.0) == "-"
    assert "2 seeds" in tables.format_markdown(tables.summarise(records(2)))


def test_scale_note_where_the_papers_mqi_meets_another_scale():
    summary = tables.summarise(records(2, "small"))
    assert "(of 100)" in tables.format_markdown(summary)
    summary["paper_mqi"] = 929.0
    assert "Paper MQI (mall, of 1000)" in tables.format_markdown(summary)
    assert any("Scales differ" in note and "100" in note for note in tables.table_notes(summary))
    on_mall = tables.summarise(records(2, "mall"))
    on_mall["paper_mqi"] = 929.0
    assert not any("Scales differ" in note for note in tables.table_notes(on_mall))


def test_radio_map_example_out_is_a_folder(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("radio_map_example", ROOT / "examples" / "radio_map.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    path = example.main(["--scenario", "small", "--out", str(tmp_path / "maps")])
    assert path == tmp_path / "maps" / "maps_small.png" and path.stat().st_size > 0
    assert str(path) in capsys.readouterr().out
    plt.close("all")


def test_paired_differences_pair_by_seed_within_a_configuration():
    rng = np.random.default_rng(3)
    rows = []
    for training in ("radio_map", "rayleigh"):
        for seed in range(4):
            luck = rng.normal(0, 50)  # shared by both modes of a seed: pairing must cancel it
            for mode, offset in (("NOMA", 10.0 + seed), ("OMA", 0.0)):
                rows.append(
                    {
                        "training": training,
                        "multiple_access": mode,
                        "seed": seed,
                        "mqi": 900 + luck + offset,
                        "success_rate": 1.0 if mode == "NOMA" else 0.75,
                    }
                )
    records = pd.DataFrame(rows)
    records = records[~((records["training"] == "rayleigh") & (records["seed"] == 3) & (records["multiple_access"] == "OMA"))]
    paired = tables.paired_differences(records, "multiple_access", "NOMA", "OMA", by=("training",))
    assert list(paired["training"]) == ["radio_map", "rayleigh"] and list(paired["n"]) == [4, 3]  # unpaired seed left out
    assert list(paired["contrast"]) == ["NOMA - OMA"] * 2
    mean, half = tables.mean_ci(np.array([10.0, 11.0, 12.0, 13.0]))
    assert paired.loc[0, "mqi"] == pytest.approx(mean) and paired.loc[0, "mqi_ci"] == pytest.approx(half)  # luck cancelled
    assert paired.loc[1, "mqi"] == pytest.approx(11.0) and paired.loc[0, "success_rate"] == pytest.approx(0.25)
    text = tables.format_paired_markdown(paired, ("training",))
    assert "| NOMA - OMA | radio_map | 4 | 25 ± 0 | 11.5 ±" in text
    assert tables.paired_differences(records, "multiple_access", "NOMA", "TDMA", by=("training",)).empty
    records["learning_rate"] = 1e-3
    both = pd.concat(
        [
            tables.paired_differences(records, "multiple_access", "NOMA", "OMA", by=("training", "learning_rate")),
            tables.paired_differences(records, "training", "radio_map", "rayleigh", by=("multiple_access",)),
        ]
    )
    text = tables.format_paired_markdown(both, ("training", "multiple_access", "learning_rate"))
    assert "| NOMA - OMA | radio_map | - | 0.001 | 4 |" in text and "nan" not in text  # absent columns show "-"
    # Only one contrast (reproduce --experiments table_ii --multiple-access noma): its own column is in no row
    alone = tables.paired_differences(records, "training", "radio_map", "rayleigh", by=("multiple_access",))
    text = tables.format_paired_markdown(alone, ("training", "multiple_access", "learning_rate"))
    assert "| radio_map - rayleigh | - | NOMA | - | 4 |" in text and "| radio_map - rayleigh | - | OMA | - | 3 |" in text
