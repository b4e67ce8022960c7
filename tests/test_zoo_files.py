"""The RL Zoo files are the presets: each zoo_configs/*.yml is what sb3_dtdpg.zoo_files writes from sb3_dtdpg.presets."""

from pathlib import Path

import pytest
import yaml

from sb3_dtdpg import presets
from sb3_dtdpg.common.phases import parse_phases
from sb3_dtdpg.zoo_files import FILES, MISSION_IDS, write_zoo_files, zoo_entries, zoo_text

CONFIGS = Path(__file__).resolve().parents[1] / "zoo_configs"


@pytest.mark.parametrize("name", sorted(FILES))
def test_each_file_is_written_from_the_presets(name):
    assert (CONFIGS / f"{name}.yml").read_text() == zoo_text(name), "run: python -m sb3_dtdpg.zoo_files zoo_configs"
    entries = yaml.safe_load((CONFIGS / f"{name}.yml").read_text())
    assert entries == zoo_entries(name)
    algo, preset, _, _ = FILES[name]
    expected = presets.settings(algo, preset)
    for env_id in MISSION_IDS:
        entry = entries[env_id]
        assert {key: entry[key] for key in expected if key != "phases"} == {k: v for k, v in expected.items() if k != "phases"}
        if "phases" in expected:
            assert parse_phases(entry["phases"]) == parse_phases(expected["phases"])


def test_every_file_is_shipped_and_no_other(tmp_path):
    assert sorted(path.name for path in CONFIGS.glob("*.yml")) == sorted(f"{name}.yml" for name in FILES)
    written = write_zoo_files(tmp_path)
    assert [path.read_text() for path in written] == [(CONFIGS / path.name).read_text() for path in written]
