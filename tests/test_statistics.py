"""Few-seed statistics (IQM, CIs, performance profiles, probability of improvement) and their figures."""

import math

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from sb3_dtdpg.experiments import aggregate, plots


def test_probability_of_improvement_counts_pairs_and_ties_half():
    # pairs (x, y): 3>1 3>2 3=3 | 4>1 4>2 4>3 | 5>... : 8 wins and 1 tie of 9
    probability, low, high = aggregate.probability_of_improvement([3.0, 4.0, 5.0], [1.0, 2.0, 3.0])
    assert probability == pytest.approx(8.5 / 9)
    assert 0.0 <= low <= probability <= high <= 1.0
    assert aggregate.probability_of_improvement([1.0, 2.0], [1.0, 2.0])[0] == pytest.approx(0.5)
    assert math.isnan(aggregate.probability_of_improvement([1.0], [0.0, 2.0])[1])


def test_performance_profile_is_the_share_above_each_threshold():
    share, low, high = aggregate.performance_profile([0.1, 0.5, 0.9, 0.9], [0.0, 0.5, 0.95])
    assert list(share) == [1.0, 0.5, 0.0]
    assert np.all(low <= share) and np.all(share <= high)
    assert low[0] == high[0] == 1.0 and low[2] == high[2] == 0.0  # every resample agrees there


def test_the_bootstrap_is_seeded_and_the_cis_contain_the_statistic():
    scores = np.array([0.2, 0.4, 0.5, 0.55, 0.9])
    assert aggregate.stratified_bootstrap_ci(scores, seed=3) == aggregate.stratified_bootstrap_ci(scores, seed=3)
    low, high = aggregate.stratified_bootstrap_ci(scores)
    assert low <= aggregate.iqm(scores) <= high
    with_nan = np.array([np.nan, *scores])  # NaNs are dropped in every resample
    low, high = aggregate.stratified_bootstrap_ci(with_nan)
    assert low <= aggregate.iqm(scores) <= high and not math.isnan(low)


@pytest.mark.parametrize("shape", [(20,), (5, 3), (2,), (7, 4)])
def test_the_iqm_ci_of_all_resamples_at_once_is_that_of_one_resample_at_a_time(shape):
    rng = np.random.default_rng(sum(shape))
    scores = np.round(rng.normal(850.0, 20.0, size=shape), 1)  # rounded: ties, as MQIs have
    per_resample = aggregate.stratified_bootstrap_ci(scores, statistic=lambda x: aggregate.iqm(x), seed=5)
    assert aggregate.stratified_bootstrap_ci(scores, seed=5) == per_resample  # bit for bit


def test_plot_statistics_writes_the_three_figures(tmp_path):
    rng = np.random.default_rng(0)
    rows = [
        {"algorithm": algo, "multiple_access": mode, "mqi": float(base + rng.normal(0, 5)), "mqi_scale": 1000.0}
        for algo, base in (("DT-DPG", 920.0), ("DDPG", 880.0))
        for mode in ("NOMA", "OMA")
        for _ in range(3)
    ]
    written = plots.plot_statistics(pd.DataFrame(rows), tmp_path, "small, tiny budget")
    assert [p.name for p in written] == ["statistics_iqm.png", "statistics_profiles.png", "statistics_improvement.png"]
    for path in written:
        with Image.open(path) as image:
            assert image.size[0] > 400 and len(np.unique(np.asarray(image.convert("L")))) > 10


def test_tables_keep_runs_of_an_unset_setting_and_pair_one_run_per_seed():
    from sb3_dtdpg.experiments import tables

    records = pd.DataFrame(
        {
            "algorithm": ["DDPG", "DDPG", "DT-DPG", "DT-DPG"] * 2,
            "multiple_access": ["NOMA"] * 4 + ["OMA"] * 4,
            "seed": [0, 1] * 4,
            "learning_rate": [float("nan")] * 8,  # the algorithm's default learning rate
            "mqi": [800.0, 810.0, 820.0, 830.0, 790.0, 800.0, 810.0, 820.0],
            **{metric: 0.0 for metric in ("success_rate", "outage_steps", "mission_time", "train_timesteps")},
        }
    )
    summary = tables.summarise(records, by=("algorithm", "learning_rate"))
    assert list(summary["n"]) == [4, 4]  # was empty: the NaN key dropped every run
    paired = tables.paired_differences(records, "multiple_access", "NOMA", "OMA", by=("algorithm",))
    assert list(paired["n"]) == [2, 2] and list(paired["mqi"]) == [10.0, 10.0]
    with pytest.raises(ValueError, match=r"several runs of seeds \[0, 1\] .*add the columns that tell them apart"):
        tables.paired_differences(records, "multiple_access", "NOMA", "OMA")  # two algorithms per seed and side


def test_a_score_that_is_not_finite_is_dropped_never_read_as_a_point():
    # was (825.0, 825.0): the resamples of the NaN alone had a NaN IQM, and NaN bounds read as "every resample equal"
    assert aggregate.stratified_bootstrap_ci(np.array([800.0, 850.0, np.nan])) == (800.0, 850.0)
    assert aggregate.stratified_bootstrap_ci(np.array([800.0, 850.0, np.inf])) == (800.0, 850.0)
    assert all(math.isnan(b) for b in aggregate.stratified_bootstrap_ci(np.array([800.0, np.nan])))  # was (800, 800)
    assert aggregate.stratified_bootstrap_ci(np.array([800.0, 800.0, np.nan])) == (800.0, 800.0)  # a true point
    by_task = np.array([[1.0, 10.0], [2.0, np.nan], [3.0, 12.0], [4.0, 11.0]])  # dropped within its own task
    assert aggregate.stratified_bootstrap_ci(by_task) == aggregate.stratified_bootstrap_ci(by_task, statistic=aggregate.iqm)
    assert all(math.isnan(b) for b in aggregate.stratified_bootstrap_ci(np.array([[1.0, 10.0], [2.0, np.nan]])))
    assert aggregate.iqm(np.array([1.0, np.inf, 3.0])) == 2.0  # was inf
    share, low, high = aggregate.performance_profile(np.array([0.8, np.nan]), np.array([0.5]))
    assert share[0] == 1.0 and math.isnan(low[0]) and math.isnan(high[0])  # one finite run: no CI (was 0.5 [0, 1])
    assert aggregate.probability_of_improvement([3.0, np.nan, 4.0], [1.0, 2.0])[0] == 1.0


def statistics_figures(records, tmp_path, monkeypatch):
    """:func:`plots.plot_statistics`'s figures (IQM, profiles, improvement), kept before they are closed."""
    figures = []
    save = plots.save_and_close
    monkeypatch.setattr(plots, "save_and_close", lambda fig, path: figures.append(fig) or save(fig, path))
    plots.plot_statistics(records, tmp_path, "t")
    return figures


def statistics_records(seeds=5):
    return pd.DataFrame(
        {"algorithm": algo, "multiple_access": mode, "seed": seed, "mqi": base + 3.0 * seed, "mqi_scale": 1000.0}
        for algo, base in (("DT-DPG", 840.0), ("DDPG", 830.0))
        for mode in ("NOMA", "OMA")
        for seed in range(seeds)
    )


def tick_labels(ax):
    return [label.get_text() for label in ax.get_yticklabels()]


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_statistics_figures_use_the_runs_with_a_score_and_say_how_many(bad, tmp_path, monkeypatch):
    records = statistics_records()
    first = (records["algorithm"] == "DDPG") & (records["multiple_access"] == "NOMA") & (records["seed"] == 0)
    records.loc[first, "mqi"] = bad
    iqm_figure, profiles, improvement = statistics_figures(records, tmp_path, monkeypatch)
    assert "DDPG NOMA (4 of 5 runs)" in tick_labels(iqm_figure.axes[0])  # was "(5 runs)", with 4 used
    assert "DT-DPG NOMA (5 runs)" in tick_labels(iqm_figure.axes[0])
    lines = [line for line in profiles.axes[0].get_lines() if line.get_label() in {"DT-DPG NOMA", "DDPG NOMA (4 of 5 runs)"}]
    assert len(lines) == 2 and all(np.isfinite(line.get_ydata()).all() for line in lines)  # were empty: NaN taus
    labels = tick_labels(improvement.axes[0])
    assert labels == ["DT-DPG > DDPG (NOMA, 5 vs 4 runs)", "DT-DPG > DDPG (OMA, 5 vs 5 runs)"]
    points = [line.get_xdata()[0] for line in improvement.axes[0].get_lines() if line.get_marker() == "o"]
    assert points[0] == pytest.approx(19 / 20)  # 840-852 over 833-842 (was a label without a point)


def test_statistics_figures_leave_out_runs_of_an_unknown_scale(tmp_path, monkeypatch):
    records = statistics_records()
    records.loc[records["algorithm"] == "DDPG", "mqi_scale"] = np.nan
    figures = statistics_figures(records, tmp_path, monkeypatch)
    assert all("10 runs left out: t_total of the scenario unknown" in fig.get_suptitle() for fig in figures)
    assert tick_labels(figures[0].axes[0]) == ["DT-DPG NOMA (5 runs)", "DT-DPG OMA (5 runs)"]  # was DDPG's raw MQI
    profile_x = np.concatenate([line.get_xdata() for line in figures[1].axes[0].get_lines()])
    assert profile_x.max() < 1.0  # all on the scale of MQI / t_total (was up to 852)
    assert [text.get_text() for text in figures[2].axes[0].texts] == [
        "nothing to compare: no mode has runs of DT-DPG and of another algorithm with a score"
    ]


def test_statistics_figures_of_one_seed_claim_no_ci(tmp_path, monkeypatch):
    iqm_figure, _, improvement = statistics_figures(statistics_records(seeds=1), tmp_path, monkeypatch)
    assert improvement.axes[0].get_xlabel() == "P(a run of X scores above a run of Y)"  # was ", 95 % CI"
    assert tick_labels(improvement.axes[0])[0] == "DT-DPG > DDPG (NOMA, 1 vs 1 run)"
    assert "CI" not in iqm_figure.axes[0].get_xlabel()
    iqm_figure, _, improvement = statistics_figures(statistics_records(seeds=2), tmp_path, monkeypatch)
    assert improvement.axes[0].get_xlabel() == "P(a run of X scores above a run of Y), 95 % CI"
    assert iqm_figure.axes[0].get_xlabel() == "IQM of the test MQI / t_total (95 % stratified-bootstrap CI)"


def table_records(mqi):
    return pd.DataFrame(
        {
            "algorithm": "DT-DPG",
            "multiple_access": "NOMA",
            "seed": range(len(mqi)),
            "mqi": mqi,
            **{metric: 0.0 for metric in ("success_rate", "outage_steps", "mission_time", "train_timesteps")},
        }
    )


def test_the_iqm_cell_is_over_the_samples_of_the_mean_cell():
    from sb3_dtdpg.experiments import tables

    for bad in (np.nan, np.inf):
        summary = tables.summarise(table_records([830.0, 835.0, bad, 840.0, 845.0]))
        row = tables.format_markdown(summary).splitlines()[2].split(" | ")
        assert row[4:6] == ["-", "-"]  # the mean's "-", and the IQM's (was "837.5 [837.5, 837.5]")
    row = tables.format_markdown(tables.summarise(table_records([830.0, 835.0, 840.0, 845.0]))).splitlines()[2]
    assert "| 837.5 ± 10.3 | 837.5 [830.0, 845.0] |" in row  # finite: as before


def test_planner_fractions_are_n_a_against_a_planner_that_does_not_score_above_0():
    from sb3_dtdpg.experiments import tables

    summary = pd.DataFrame(
        {
            "algorithm": ["DT-DPG", "DDPG", "best", "shortest"] * 2,
            "multiple_access": ["NOMA"] * 4 + ["OMA"] * 4,
            "mqi": [-1000.0, -2500.0, -500.0, -600.0, -78.0, 834.0, 856.0, 0.0],
        }
    )
    fractions = tables.add_planner_fractions(summary, "best", "shortest")
    assert fractions.loc[:3, ["mqi_of_best", "mqi_of_shortest"]].isna().all().all()  # were 2.0 and 5.0: ranked backwards
    assert fractions.loc[4:, "mqi_of_best"].tolist() == pytest.approx([-78.0 / 856.0, 834.0 / 856.0, 1.0, 0.0])
    assert fractions.loc[4:, "mqi_of_shortest"].isna().all()  # a reference of 0 (was -inf, inf, nan)
