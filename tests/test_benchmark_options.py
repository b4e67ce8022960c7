"""The timing and calibration scripts of benchmarks/: a count they cannot use is one error line before any work."""

import sys

import pytest
from scripts import load_script


@pytest.mark.parametrize(
    ("script", "args", "message"),
    [
        ("train_speed", ["--repeats", "0"], "argument --repeats: expected a positive integer, got '0'"),  # printed nan ratios
        ("train_speed", ["--batch-size", "1"], "argument --batch-size: expected a batch size >= 2, got '1'"),
        ("train_speed", ["--net-arch", "64", "0"], "argument --net-arch: expected a positive integer, got '0'"),
        ("update_breakdown", ["--updates", "0"], "argument --updates: expected a positive integer, got '0'"),
        ("env_speed", ["--rounds", "0"], "argument --rounds: expected a positive integer, got '0'"),  # a ZeroDivisionError
        ("env_speed", ["--steps", "0"], "argument --steps: expected a positive integer, got '0'"),
        ("radiomap_build", ["--repeats", "0"], "argument --repeats: expected a positive integer, got '0'"),
        ("room_calibration", ["--episodes", "0"], "argument --episodes: expected a positive integer, got '0'"),
        ("room_calibration", ["--scenario", "bogus"], "--scenario: scenario 'bogus': unknown built-in name"),
        ("power_shares", ["--workers", "0"], "argument --workers: expected a positive integer, got '0'"),  # 0 ran on every CPU
    ],
)
def test_a_count_it_cannot_use_is_one_error_line(script, args, message, monkeypatch, capsys):
    module = load_script(script)
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *args])
    with pytest.raises(SystemExit) as exit_info:
        module.main()
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
