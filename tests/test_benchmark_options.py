"""The timing and calibration scripts of benchmarks/: a count they cannot use is one error line before any work."""

import sys

import pytest
from scripts import load_script


@pytest.mark.parametrize(
    ("script", "args", "message"),
    [
        ("train_speed", ["--repeats", "0"], "--repeats must be >= 1, got 0"),  # printed ratios of no runs: nan
        ("train_speed", ["--batch-size", "1"], "--batch-size must be >= 2, got 1"),
        ("train_speed", ["--net-arch", "64", "0"], "--net-arch: layer sizes must be >= 1, got [64, 0]"),
        ("env_speed", ["--rounds", "0"], "--rounds must be >= 1, got 0"),  # a ZeroDivisionError
        ("env_speed", ["--steps", "0"], "--steps must be >= 1, got 0"),
        ("radiomap_build", ["--repeats", "0"], "--repeats must be >= 1, got 0"),  # a StatisticsError after a build
        ("room_calibration", ["--episodes", "0"], "--episodes must be >= 1, got 0"),
        ("room_calibration", ["--scenario", "bogus"], "--scenario: scenario 'bogus': unknown built-in name"),
        ("power_shares", ["--workers", "0"], "--workers must be >= 1, got 0"),  # 0 ran on every CPU
    ],
)
def test_a_count_it_cannot_use_is_one_error_line(script, args, message, monkeypatch, capsys):
    module = load_script(script)
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *args])
    with pytest.raises(SystemExit) as exit_info:
        module.main()
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
