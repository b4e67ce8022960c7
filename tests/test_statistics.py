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
