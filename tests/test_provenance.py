"""Each run records the library versions it was made with, and reusing runs of other versions is warned about."""

import json
import re
import warnings

import pytest
import torch as th

from sb3_dtdpg.experiments.provenance import OtherVersionsWarning, made_with, version_differences
from sb3_dtdpg.experiments.runs import RunSpec, result_path, run_many, run_one

pytestmark = pytest.mark.filterwarnings("ignore:The inplace keyword:DeprecationWarning", "ignore::FutureWarning")

SPEC = RunSpec("ddpg", "noma", 0, 3, scenario="small", eval_episodes=1, eval_before_transfer=False, observation="paper")


def _rewrite(path, change):
    record = json.loads(path.read_text())
    change(record)
    path.write_text(json.dumps(record))


def _other_torch(record):
    record["made_with"]["torch"] = "2.4.0"


def test_made_with_names_the_running_libraries_and_cpu_kernels():
    versions = made_with()
    assert versions["torch"] == th.__version__
    assert versions["cpu_capability"] == th.backends.cpu.get_cpu_capability()
    assert {"python", "sb3_dtdpg", "stable_baselines3", "numpy", "gymnasium"} <= set(versions)


def test_only_library_versions_count_as_differences():
    current = made_with()
    assert version_differences(dict(current, cpu_capability="other", python="0.0")) == {}
    assert version_differences(None) == {} and version_differences({}) == {}  # a record of before versions were kept
    assert version_differences(dict(current, numpy="1.0")) == {"numpy": ("1.0", current["numpy"])}


def test_a_reused_result_of_other_versions_is_warned_about_and_one_of_these_is_not(tmp_path):
    other = RunSpec("ddpg", "noma", 1, 3, scenario="small", eval_episodes=1, eval_before_transfer=False, observation="paper")
    with warnings.catch_warnings():
        warnings.simplefilter("error", OtherVersionsWarning)
        run_many([SPEC, other], tmp_path, n_workers=1, progress=False)
        result = json.loads(result_path(tmp_path, SPEC).read_text())
        assert result["made_with"] == made_with()
        assert run_many([SPEC, other], tmp_path, n_workers=1, progress=False).skipped == [SPEC.run_id, other.run_id]

    _rewrite(result_path(tmp_path, SPEC), _other_torch)
    with pytest.warns(
        OtherVersionsWarning, match=rf"1 of 2 stored runs .*\(torch 2\.4\.0, now {re.escape(th.__version__)}: 1 run\)"
    ):
        report = run_many([SPEC, other], tmp_path, n_workers=1, progress=False)
    assert report.skipped == [SPEC.run_id, other.run_id]  # reused as they are
    with pytest.warns(OtherVersionsWarning, match="reused"):
        run_one(SPEC, tmp_path, resume=True)

    _rewrite(result_path(tmp_path, SPEC), lambda record: record.pop("made_with"))  # made before versions were kept
    with warnings.catch_warnings():
        warnings.simplefilter("error", OtherVersionsWarning)
        run_many([SPEC, other], tmp_path, n_workers=1, progress=False)


def test_the_command_line_shows_a_warning_as_one_line(tmp_path):
    """``sb3-dtdpg`` shows warnings as its own notices, ``<command>: warning: <message>`` (was: Python's
    ``.../provenance.py:<line>: OtherVersionsWarning: ...`` and the source line that raised it)."""
    import os
    import subprocess
    import sys

    run_one(SPEC, tmp_path)
    _rewrite(result_path(tmp_path, SPEC), _other_torch)
    argv = ["train", "--algo", "ddpg", "--preset", "paper", "--observation", "paper", "--scenario", "small"]
    argv += ["--episodes", "3", "--eval-episodes", "1", "--eval-seed", "10000", "--no-progress", "--out", str(tmp_path)]
    env = {**os.environ, "PYTHONWARNINGS": "ignore::DeprecationWarning,ignore::FutureWarning"}
    done = subprocess.run([sys.executable, "-m", "sb3_dtdpg.cli", *argv], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert [line for line in lines if "warning" in line.lower()] == [
        f"sb3-dtdpg train: warning: OtherVersionsWarning: 1 of 1 stored runs in {tmp_path} were made with other "
        f"library versions (torch 2.4.0, now {th.__version__}: 1 run); they are reused as they are. Use a new output "
        "folder to make every run with the running versions."
    ]
