"""examples/: a bad option is one error line before any work, and a trained model is saved before it is tested."""

import matplotlib.pyplot as plt
import pytest
from scripts import load_script


def example(name: str):
    return load_script(name, folder="examples")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--eval-episodes", "0"], "argument --eval-episodes: expected a positive integer, got '0'"),
        (["--timesteps", "0"], "argument --timesteps: expected a positive integer, got '0'"),
        (["--threads", "-1"], "argument --threads: expected a positive integer, got '-1'"),
    ],
)
def test_quickstart_checks_its_options_before_training(args, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        example("quickstart").main([*args, "--save-path", str(tmp_path / "model.zip")])
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_quickstart_saves_where_it_says_and_shows_an_undefined_ci_as_such(tmp_path, capsys):
    save_path = tmp_path / "model"  # no suffix: SB3 writes model.zip
    example("quickstart").main(["--timesteps", "200", "--eval-episodes", "1", "--save-path", str(save_path)])
    out = capsys.readouterr().out
    assert (tmp_path / "model.zip").is_file() and f"saved to {tmp_path / 'model.zip'}, loaded" in out
    assert "± n/a" in out and "nan" not in out  # one test episode has no CI


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "bogus"], "--scenario: scenario 'bogus': unknown built-in name"),
        (["--dpi", "0"], "argument --dpi: expected a positive integer, got '0'"),
    ],
)
def test_radio_map_example_errors_are_one_line_and_create_nothing(args, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        example("radio_map").main([*args, "--out", str(tmp_path / "maps")])
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "maps").exists()
    plt.close("all")
