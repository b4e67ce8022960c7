"""benchmarks/learning.py: its options are checked before any training, and its report keeps the finished runs."""

import argparse
import csv
import json
import subprocess
import sys

import pytest
from scripts import ROOT, load_script

SCRIPT = ROOT / "benchmarks" / "learning.py"


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--workers", "0"),
        ("--eval-episodes", "0"),
        ("--tail", "0"),
        ("--phase1-episodes", "-3"),
        ("--hyperparams", "[1]"),
        ("--seeds", "-1"),
    ],
)
def test_a_bad_option_is_one_error_line_naming_it(option, value, tmp_path):
    done = subprocess.run(
        [sys.executable, str(SCRIPT), option, value, "--out", str(tmp_path / "out")], capture_output=True, text=True
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"argument {option}: expected " in done.stderr and repr(value) in done.stderr
    assert not (tmp_path / "out").exists()


def _phase1(seed: int, reached: bool) -> dict:
    return {
        "seed": seed,
        "phase1_reached_95": reached,
        "phase1_episodes": 40,
        "phase1_timesteps": 4000,
        "phase1_seconds": 1.0,
        "phase1_success_curve": [reached],
        "phase1_mqi_curve": [1.0],
    }


def test_the_report_holds_the_finished_runs_and_no_earlier_rows(tmp_path):
    learning = load_script("learning")
    (tmp_path / "learning.csv").write_text("seed,replay_handling\n7,keep\n")  # an earlier benchmark's rows
    args = argparse.Namespace(seeds=[0, 1, 2], handlings=["keep"], phase1_only=True, out=str(tmp_path))
    report = learning._write_report(args, {0: _phase1(0, True), 2: _phase1(2, True)}, [], 0.0, complete=False)
    assert not report["complete"] and [p["seed"] for p in report["phase1"]] == [0, 2]
    assert report["bar_95_within_budget"] == {"seeds_reached": [0, 2], "holds": True}
    with open(tmp_path / "learning.csv") as f:
        rows = list(csv.DictReader(f))
    assert [row["seed"] for row in rows] == ["0", "2"] and "phase1_success_curve" not in rows[0]
    assert json.loads((tmp_path / "learning.json").read_text())["phase1"][1]["seed"] == 2

    args.phase1_only = False  # phase 2 asked for, none finished: no rows, no handling averaged over nothing
    report = learning._write_report(args, {0: _phase1(0, False)}, [], 0.0, complete=False)
    assert report["replay_handling"] == {} and (tmp_path / "learning.csv").read_text() == ""
    assert report["bar_95_within_budget"]["holds"] is False
