"""Hostile scenarios: limits checked at load time, physical ranges, and YAML details (duplicates, typos, encodings)."""

import copy
import re
import time

import numpy as np
import pytest
import yaml

from noma_radiomap import NomaRadioMapEnv, Scenario, load_scenario
from noma_radiomap.scenario import (
    MAX_GRID_CELLS,
    MAX_MESSAGE_CHARS,
    MAX_NESTING,
    MAX_NODES,
    MAX_SUBSTEPS,
    RANGES,
    ScenarioLoader,
)


@pytest.fixture(scope="module")
def small_dict():
    return load_scenario("small").to_dict()


def _with(**changes):
    """A mutation setting ``data[a][b] = value`` for each ``a__b=value`` (``a=value`` at the top)."""

    def mutate(data):
        for path, value in changes.items():
            keys = path.split("__")
            target = data
            for key in keys[:-1]:
                target = target[int(key)] if isinstance(target, list) else target[key]
            target[keys[-1]] = value

    return mutate


# Each case: a mutation of `small` and the start of the error message (the field path and the value).
HOSTILE = {
    # item 4: inputs that would exhaust the machine
    "1e8-cell grid": (_with(room__resolution=0.0012), r"room\.resolution: 0\.0012 gives 6\.67e\+07 cells"),
    "subnormal resolution": (_with(room__resolution=5e-324), r"room\.resolution: 5e-324 gives inf cells"),
    "huge room": (_with(room__width=1e7), r"room\.width: 10000000\.0 is outside the physical range"),
    "one step never returns": (_with(robot__v_max=1e6 / 1e4, mission__time_step=3600), r"robot\.v_max: 100\.0 m/s x"),
    "too many sub-steps": (_with(robot__v_max=99.0), rf"robot\.v_max: 99\.0 .* more than the limit of {MAX_SUBSTEPS}"),
    "huge name": (_with(name="x" * 10_000), r"name: 10000 characters, more than the limit"),
    "int beyond float": (_with(room__width=10**400), r"room\.width: .* out of range"),
    "100k robots": (lambda d: d.__setitem__("robots", d["robots"] * 50_000), r"robots: 100000 entries, more than"),
    # item 5: non-finite or absurd physics
    "+400 dBm AP": (_with(ap__max_power_dbm=400.0), r"ap\.max_power_dbm: 400\.0 is outside the physical range"),
    "-400 dBm AP": (_with(ap__max_power_dbm=-400.0), r"ap\.max_power_dbm: -400\.0 is outside"),
    "+400 dBm interferer": (_with(interferers__0__power_dbm=400.0), r"interferers\[0\]\.power_dbm: 400\.0 is outside"),
    "interferer 1e9 m away": (_with(interferers__0__position=[1e9, 0, 0]), r"interferers\[0\]\.position\[0\]: 1000000000"),
    "huge bandwidth": (_with(radio__bandwidth_per_robot_hz=1e300), r"radio\.bandwidth_per_robot_hz: 1e\+300 is outside"),
    "huge QoS rate": (_with(radio__qos_rate_bps=1e200), r"radio\.qos_rate_bps: 1e\+200 is outside"),
    "noise above -100 dBm/Hz": (_with(radio__noise_dbm_per_hz=30.0), r"radio\.noise_dbm_per_hz: 30\.0 is outside"),
    "1 Hz carrier": (_with(radio__frequency_mhz=1e-6), r"radio\.frequency_mhz: 1e-06 is outside"),
    "1000 dB wall": (_with(radio__wall_loss_db=1000.0), r"radio\.wall_loss_db: 1000\.0 is outside"),
    "huge NLoS coefficient": (_with(radio__nlos_distance_coefficient=1e5), r"radio\.nlos_distance_coefficient: 100000"),
    "huge penalty": (_with(mission__outage_penalty=1e300), r"mission\.outage_penalty: 1e\+300 is outside"),
    "huge t_total": (_with(mission__t_total=1e300), r"mission\.t_total: 1e\+300 is outside"),
    "billion steps": (_with(mission__max_steps=10**9), r"mission\.max_steps: 1000000000 is outside"),
    "day-long step": (_with(mission__time_step=86_400.0), r"mission\.time_step: 86400\.0 is outside"),
    "overflowing time cost": (_with(mission__time_cost=1e39), r"mission\.time_cost: 1e\+39 is outside the physical range"),
    "huge arrival reward": (_with(mission__arrival_reward=-1e7), r"mission\.arrival_reward: -10000000\.0 is outside"),
    "huge success reward": (_with(mission__success_reward=1e30), r"mission\.success_reward: 1e\+30 is outside"),
    "antenna 100 m high": (_with(robot__antenna_height=100.0), r"robot\.antenna_height: 100\.0 is outside"),
    "AP 100 m high": (_with(ap__position=[3.0, 4.0, 100.0]), r"ap\.position\[2\]: 100\.0 is outside"),
    "body taller than antenna": (_with(robot__body_height=2.0), r"robot\.body_height: 2\.0 must be below robot\.antenna"),
    "body as tall as antenna": (_with(robot__body_height=1.5), r"robot\.body_height: 1\.5 must be below"),
    "rocket robot": (_with(robot__v_max=1e9), r"robot\.v_max: 1000000000\.0 is outside"),
    # item 6: keys
    "typo'd key": (
        lambda d: d["radio"].__setitem__("wal_loss_db", d["radio"].pop("wall_loss_db")),
        r"radio\.wal_loss_db: unknown key \(did you mean 'wall_loss_db'\?\)",
    ),
    "typo'd section": (lambda d: d.__setitem__("robto", d.pop("robot")), r"robto: unknown key \(did you mean 'robot'\?\)"),
    "non-string key": (_with(room__3=1.0), r"room\.3: unknown key"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_scenario_gives_a_named_error_fast(case, small_dict):
    mutate, pattern = HOSTILE[case]
    data = copy.deepcopy(small_dict)
    mutate(data)
    start = time.process_time()  # this process's CPU time: the work done, not other load on the machine
    with pytest.raises(ValueError, match=pattern) as error:
        Scenario.from_dict(data)
    assert time.process_time() - start < 2.0
    assert len(str(error.value)) < 4 * MAX_MESSAGE_CHARS + 300


def test_limits_are_generous_for_real_rooms(small_dict):
    data = copy.deepcopy(small_dict)
    data["room"]["resolution"] = 0.25  # 48 x 32 cells, 2 sub-steps at v_max 1
    assert Scenario.from_dict(data).room.shape == (48, 32)
    assert 110 * 60 < MAX_GRID_CELLS


def _write(tmp_path, text, name="s.yaml"):
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


@pytest.fixture
def small_yaml(small_dict):
    return yaml.safe_dump(small_dict, sort_keys=False)


def test_duplicate_keys_are_errors(tmp_path, small_yaml):
    text = small_yaml.replace("resolution: 0.5", "resolution: 0.5\n  resolution: 0.25", 1)
    path = _write(tmp_path, text)
    with pytest.raises(ValueError, match=rf"{path}, line \d+, column \d+: malformed YAML: duplicate key 'resolution' \(first"):
        load_scenario(path)
    top = _write(tmp_path, small_yaml + "name: other\n", "top.yaml")
    with pytest.raises(ValueError, match=r"duplicate key 'name' \(first at line 1\)"):
        load_scenario(top)


def test_typo_in_a_file_is_reported_as_unknown_with_a_suggestion(tmp_path, small_yaml):
    path = _write(tmp_path, small_yaml.replace("wall_loss_db:", "wal_loss_db:", 1))
    with pytest.raises(ValueError, match=rf"{path}: radio\.wal_loss_db: unknown key \(did you mean 'wall_loss_db'\?\)"):
        load_scenario(path)


@pytest.mark.parametrize(
    ("text", "value"),
    [("15e3", 15_000.0), ("1.5E4", 15_000.0), ("+15e+3", 15_000.0), ("150e2", 15_000.0), ("1.5e4", 15_000.0)],
)
def test_exponent_numbers_are_numbers(tmp_path, small_yaml, text, value):
    path = _write(tmp_path, small_yaml.replace("bandwidth_per_robot_hz: 15000.0", f"bandwidth_per_robot_hz: {text}", 1))
    assert load_scenario(path).radio.bandwidth_per_robot_hz == value


def test_exponent_speed_is_a_number_then_range_checked(tmp_path, small_yaml):
    path = _write(tmp_path, small_yaml.replace("v_max: 1.0", "v_max: 1.0e9", 1))
    with pytest.raises(ValueError, match=r"robot\.v_max: 1000000000\.0 is outside the physical range"):
        load_scenario(path)


HOSTILE_FILES = {
    "latin-1": (b"name: caf\xe9\n", r"not a UTF-8 text file \(byte 9"),
    "utf-16": ("name: small\n".encode("utf-16"), r"not a UTF-8 text file"),
    "binary": (bytes(range(256)), r"not a UTF-8 text file"),
    # libyaml's own limit (1000 levels) may come first: it reads ahead of the composer's
    "deep lists": ("name: " + "[" * 100_000 + "]" * 100_000, rf"nesting deeper than the limit of {MAX_NESTING}|nesting depth"),
    "deep mappings": ("".join(" " * k + f"k{k}:\n" for k in range(200)) + " " * 200 + "x: 1\n", r"nesting deeper"),
    "huge file": ("# " + "x" * 5_000_000 + "\n", r"bytes, more than the limit"),
    "malformed": ("name: [\n", r"line \d+, column \d+: malformed YAML"),
    "unhashable key": ("? [1, 2]\n: 3\n", r"malformed YAML"),
    "python tag": ("name: !!python/object/apply:os.system [echo hi]\n", r"malformed YAML"),
    "a list": ("- 1\n- 2\n", r"scenario: expected a mapping"),
    "empty": ("", r"scenario: expected a mapping, got None"),
}


@pytest.mark.parametrize("case", list(HOSTILE_FILES))
def test_hostile_file_gives_a_value_error_naming_the_file(tmp_path, case):
    content, pattern = HOSTILE_FILES[case]
    path = _write(tmp_path, content)
    start = time.process_time()
    with pytest.raises(ValueError, match=pattern) as error:
        load_scenario(path)
    assert str(error.value).startswith(str(path))
    assert len(str(error.value)) < 1000
    assert time.process_time() - start < 5.0


def test_alias_bomb_in_a_name_is_reported_at_once(tmp_path, small_yaml):
    # 9**9 strings once expanded: refused while the file is composed, before anything is built or printed
    bomb = "name: [&a [x, x, x, x, x, x, x, x, x], " + ", ".join(
        f"&{chr(98 + k)} [{', '.join(['*' + chr(97 + k)] * 9)}]" for k in range(8)
    )
    path = _write(tmp_path, small_yaml.replace("name: small", bomb + "]", 1))
    start = time.process_time()
    with pytest.raises(ValueError, match=rf"{path}, line 1, column .*: more than the limit of {MAX_NODES:,} values") as e:
        load_scenario(path)
    assert time.process_time() - start < 1.0 and len(str(e.value)) < 1000


def _alias_bomb(small_dict, part):
    """The two files of the report: 1000 obstacles aliasing one 10 000-box list; 10 000 robots aliasing 10 000
    destinations. Each list is within MAX_LIST_ITEMS; the expanded total is 7e7 and 3e8 values."""
    rest = {key: value for key, value in small_dict.items() if key not in ("obstacles", "robots")}
    text = yaml.safe_dump(rest, sort_keys=False)
    if part == "obstacles":
        boxes = ", ".join(["[0.1, 0.1, 0.2, 0.2, 0, 1]"] * 10_000)
        text += f"obstacles:\n- name: o0\n  boxes: &b [{boxes}]\n"
        text += "".join(f"- name: o{k}\n  boxes: *b\n" for k in range(1, 1000))
        return text + yaml.safe_dump({"robots": small_dict["robots"]})
    start = small_dict["robots"][0]["start"]
    text += f"robots:\n- start: &s {start}\n  destinations: &d [{', '.join(['[1, 1]'] * 10_000)}]\n"
    return text + "- start: *s\n  destinations: *d\n" * 9_999


@pytest.mark.parametrize(("part", "kilobytes"), [("obstacles", 280), ("robots", 200)])
def test_aliases_that_multiply_lists_are_refused_fast(tmp_path, small_dict, part, kilobytes):
    path = _write(tmp_path, _alias_bomb(small_dict, part))
    assert path.stat().st_size > kilobytes * 1000  # the size of the report's files
    start = time.process_time()
    with pytest.raises(ValueError, match=rf"^{path}, line \d+, column \d+: more than the limit of {MAX_NODES:,} values"):
        load_scenario(path)
    # Without the limit these files load for minutes (> 240 s, growing past 1 GB); refused they take ~0.1-1 s of CPU
    # depending on the machine, so 5 s tells the two apart on a slow CI machine too.
    assert time.process_time() - start < 5.0


def test_a_recursive_alias_is_refused(tmp_path, small_yaml):
    path = _write(tmp_path, small_yaml.replace("name: small", "name: &n [1, *n]", 1))
    with pytest.raises(ValueError, match=rf"{path}, line 1, column \d+: malformed YAML: recursive alias"):
        load_scenario(path)


def test_unreadable_path_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="unknown built-in name and no such file"):
        load_scenario(tmp_path / "missing.yaml")


def _big_room(small_dict, n_interferers):
    """The report's room: 1000 x 1000 m at 0.5 m (4e6 cells, within MAX_GRID_CELLS), with interferers."""
    data = copy.deepcopy(small_dict)
    data["room"].update(width=1000.0, depth=1000.0, resolution=0.5)
    data["interferers"] = [{"name": f"i{k}", "position": [1.0 + k, 1.0, 2.0], "power_dbm": 10.0} for k in range(n_interferers)]
    return data


def test_a_scenario_too_big_for_memory_is_refused_before_anything_is_allocated(small_dict):
    import tracemalloc

    data = _big_room(small_dict, 50)
    tracemalloc.start()
    start = time.process_time()
    try:
        with pytest.raises(
            ValueError, match=r"4,000,000 cells x 51 transmitters .* need about 14\.\d+ GiB .* cap of 1\.00 GiB"
        ):
            Scenario.from_dict(data)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.process_time() - start < 1.0 and peak < 50 * 2**20  # nothing of the grid's size was built


def test_the_memory_cap_is_documented_and_overridable(small_dict, monkeypatch):
    from noma_radiomap import RadioMap, radiomap

    assert radiomap.MAX_MEMORY_BYTES == 2**30
    estimate = radiomap.estimated_memory(Scenario.from_dict(_big_room(small_dict, 1)))  # 1 interferer: under the cap
    assert estimate["cells"] == 4_000_000 and estimate["transmitters"] == 2
    parts = estimate["maps"] + estimate["tables"] + estimate["occlusion"] + estimate["starts"]
    assert estimate["total"] == parts < 2**30
    small = load_scenario("small")
    monkeypatch.setenv("NOMA_RADIOMAP_MAX_MEMORY_BYTES", "2e10")
    assert Scenario.from_dict(_big_room(small_dict, 50)).room.shape == (2000, 2000)  # allowed by the user
    monkeypatch.setenv("NOMA_RADIOMAP_MAX_MEMORY_BYTES", "1000")  # the radio map checks again
    with pytest.raises(ValueError, match=r"384 cells x 2 transmitters .* more than the cap"):
        RadioMap(small)
    monkeypatch.setenv("NOMA_RADIOMAP_MAX_MEMORY_BYTES", "lots")
    with pytest.raises(ValueError, match=r"NOMA_RADIOMAP_MAX_MEMORY_BYTES: expected a positive number of bytes, got 'lots'"):
        RadioMap(small)


def test_start_regions_too_big_for_memory_are_refused_at_load(small_dict):
    """1 000 robots each starting anywhere in a 200 x 200 m room at 0.5 m: the env's mission sampler would keep
    160 000 start cells per robot (> 2.4 GB); the estimate counts them and the file is refused at load."""
    import tracemalloc

    data = copy.deepcopy(small_dict)
    data["room"].update(width=200.0, depth=200.0, resolution=0.5)
    data["robots"] = [{"start": [0.0, 0.0, 200.0, 200.0], "destinations": [[100.0, 100.0]]} for _ in range(1000)]
    assert len(yaml.safe_dump(data)) < 100_000
    tracemalloc.start()
    start = time.process_time()
    try:
        with pytest.raises(
            ValueError,
            match=r"robots: 1,000 robots' start regions x destinations \(160,000,000 start cells x destinations in all"
            r".* need about 2\.\d+ GiB .* 2\.\d+ GiB of start-cell tables\), more than the cap of 1\.00 GiB",
        ):
            Scenario.from_dict(data)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert time.process_time() - start < 1.0 and peak < 50 * 2**20


def test_the_builtin_scenarios_stay_far_under_the_memory_cap():
    from noma_radiomap import list_scenarios, radiomap

    for name in list_scenarios():
        scenario = load_scenario(name)
        assert radiomap.estimated_memory(scenario)["total"] < 2**30 // 20, name
        assert radiomap.missions_memory(64, scenario, "geodesic")["total"] < 2**30 // 20, name


def test_geodesic_distance_tables_count_against_the_memory_cap(monkeypatch):
    """inducing='geodesic' gives every mission a float64 table per robot per cell at its first reset: counted when
    the env is built, before anything is allocated."""
    from noma_radiomap import radiomap
    from noma_radiomap.vector import NomaRadioMapVecEnv

    start = time.process_time()
    with pytest.raises(
        ValueError,
        match=r"num_envs, inducing: 60,000 missions need about 6\.04 GiB with inducing='geodesic' \(5\.90 GiB of "
        r"distance tables: 2 robots x 6,600 cells x 8 bytes per mission, .*\), more than the cap of 1\.00 GiB",
    ):
        NomaRadioMapVecEnv(60_000, scenario="mall", inducing="geodesic")
    assert time.process_time() - start < 2.0
    NomaRadioMapVecEnv(60_000, scenario="mall")  # Euclidean: 60 000 missions are within the cap
    monkeypatch.setenv("NOMA_RADIOMAP_MAX_MEMORY_BYTES", str(5 * 2**20))
    NomaRadioMapVecEnv(1000, scenario="small")  # 2.3 MiB
    with pytest.raises(ValueError, match=r"num_envs, inducing: 1,000 missions need about 8\.\d MiB"):
        NomaRadioMapVecEnv(1000, scenario="small", inducing="geodesic")
    # A single env's tables count too: a table per robot, and the radio map's cached distance fields (4 destinations)
    need = radiomap.missions_memory(1, load_scenario("small"), "geodesic")
    assert need["distances"] == 8 * 384 * (2 + 4) and need["total"] == need["missions"] + need["distances"]


@pytest.mark.parametrize(
    ("field", "name"),
    [("name", "a\x00b"), ("name", "\x1b[31mred"), ("obstacles", "wall\x1b[2J"), ("interferers", "out\u202edoor")],
)
def test_names_with_control_characters_are_refused(small_dict, field, name):
    data = copy.deepcopy(small_dict)
    if field == "name":
        data["name"], path = name, "name"
    else:
        data[field][0]["name"], path = name, f"{field}[0].name"
    with pytest.raises(ValueError, match=rf"^{re.escape(path)}: .* holds a control character") as error:
        Scenario.from_dict(data)
    assert "\x1b" not in str(error.value) and "\x00" not in str(error.value)  # quoted, not echoed raw
    data = copy.deepcopy(small_dict)
    data["name"] = "Café 3 (é, ü, 漢字) - ok"  # printable Unicode is fine
    assert Scenario.from_dict(data).name == data["name"]


def test_an_arrival_radius_that_covers_every_start_is_refused_at_load(small_dict):
    """The env's mission sampler refuses a destination every start cell is within arrival_radius of; the load
    gives the same message, before anything is built."""
    data = copy.deepcopy(small_dict)
    data["robot"]["arrival_radius"] = 1000.0  # within its range, larger than the room's diagonal
    message = r"robots\[0\]\.start: every free cell of \[0\.5, 0\.5, 2\.5, 2\.5\] is within arrival_radius of destination"
    with pytest.raises(ValueError, match=message):
        Scenario.from_dict(data)
    data["robot"]["arrival_radius"] = 1.1
    data["robots"][0]["destinations"].append([1.5, 1.5])  # the start region's centre: 1.1 m reaches all its cells
    with pytest.raises(ValueError, match=r"robots\[0\]\.start: .* within arrival_radius of destination \[1\.5, 1\.5\]"):
        Scenario.from_dict(data)


# --- YAML 1.2 integers, merge keys, numpy values, radio settings, the memory cap's variable ----------------------


@pytest.mark.parametrize(
    ("text", "value"),
    [("0300", 300), ("010", 10), ("0o10", 8), ("0x10", 16), ("1_000", 1000), ("-12", -12), ("1:00", "1:00"), ("0b10", "0b10")],
)
def test_integers_are_read_by_yaml_1_2_rules(text, value):
    """PyYAML's YAML 1.1 rules read 0300 as octal 192, 1:00 as sexagesimal 60 and 0o10 as a string."""
    from noma_radiomap.scenario import ScenarioLoader

    loaded = yaml.load(f"a: {text}\n", Loader=ScenarioLoader)["a"]
    assert loaded == value and type(loaded) is type(value)


@pytest.mark.parametrize(
    ("text", "value"),
    [("true", True), ("False", False), ("TRUE", True), ("no", "no"), ("NO", "NO"), ("on", "on"), ("off", "off"), ("y", "y")],
)
def test_booleans_are_read_by_yaml_1_2_rules(text, value):
    """PyYAML's YAML 1.1 rules read no, on, off, yes, y and n as booleans."""
    from noma_radiomap.scenario import ScenarioLoader

    loaded = yaml.load(f"a: {text}\n", Loader=ScenarioLoader)["a"]
    assert loaded == value and type(loaded) is type(value)


def test_a_room_named_no_keeps_its_name(tmp_path, small_yaml):
    assert load_scenario(_write(tmp_path, small_yaml.replace("name: small", "name: NO", 1))).name == "NO"


@pytest.mark.parametrize("tag", ["", "!!int "])
def test_an_integer_too_long_to_read_is_out_of_range_not_malformed(tmp_path, small_yaml, tag):
    path = _write(tmp_path, small_yaml.replace("max_steps: 60", f"max_steps: {tag}{'9' * 5000}", 1))
    with pytest.raises(ValueError, match=rf"^{path}, line \d+, column \d+: an integer of 5,000 digits is out of range$"):
        load_scenario(path)


def test_a_leading_zero_is_no_octal_prefix_in_a_scenario_file(tmp_path, small_yaml):
    assert "max_steps: 60" in small_yaml
    assert load_scenario(_write(tmp_path, small_yaml.replace("max_steps: 60", "max_steps: 010", 1))).mission.max_steps == 10
    path = _write(tmp_path, small_yaml.replace("max_steps: 60", "max_steps: 1:00", 1))
    with pytest.raises(ValueError, match=rf"^{path}: mission\.max_steps: expected an integer, got '1:00' \(str\)"):
        load_scenario(path)
    path = _write(tmp_path, small_yaml.replace("max_steps: 60", "max_steps: !!int 1:00", 1))
    with pytest.raises(ValueError, match=rf"^{path}, line \d+, column \d+: malformed YAML: expected an integer, got '1:00'"):
        load_scenario(path)


def test_merge_keys_work_and_explicit_keys_override_them(tmp_path, small_yaml, small_dict):
    robot = small_dict["robot"]
    body = f"body_height: {robot['body_height']}, antenna_height: {robot['antenna_height']}"
    anchored = small_yaml.replace("name: small", "name: small\nbase: &base {v_max: 0.5, arrival_radius: 0.7}", 1)
    start, end = anchored.index("robot:\n"), anchored.index("radio:\n")
    merged = f"{anchored[:start]}robot: {{<<: *base, {body}, arrival_radius: 0.4}}\n{anchored[end:]}"
    data = yaml.load(merged, Loader=ScenarioLoader)
    assert data.pop("base") == {"v_max": 0.5, "arrival_radius": 0.7}
    scenario = Scenario.from_dict(data)
    assert (scenario.robot.v_max, scenario.robot.arrival_radius) == (0.5, 0.4)  # merged; overridden
    inline = small_yaml.replace("  v_max: 1.0\n", "  <<: {v_max: 0.5}\n", 1)
    assert "<<" in inline and load_scenario(_write(tmp_path, inline)).robot.v_max == 0.5
    twice = _write(tmp_path, small_yaml.replace("  v_max: 1.0\n", "  <<: {v_max: 0.5}\n  v_max: 1.0\n  v_max: 2.0\n", 1))
    with pytest.raises(ValueError, match=r"malformed YAML: duplicate key 'v_max' \(first at line \d+\)"):
        load_scenario(twice)
    not_a_mapping = _write(tmp_path, small_yaml.replace("  v_max: 1.0\n", "  <<: 3\n  v_max: 1.0\n", 1))
    with pytest.raises(ValueError, match=r"malformed YAML: expected a mapping or list of mappings for merging"):
        load_scenario(not_a_mapping)


def test_numpy_scalars_and_arrays_are_numbers_and_lists(small_dict):
    data = copy.deepcopy(small_dict)
    data["room"]["width"] = np.float32(12.0)
    data["robot"]["v_max"] = np.float16(1.0)
    data["mission"]["max_steps"] = np.int64(60)
    data["ap"]["position"] = np.asarray(data["ap"]["position"], dtype=np.float32)
    data["robots"][0]["destinations"] = np.asarray(data["robots"][0]["destinations"])
    data["obstacles"][0]["boxes"] = np.asarray(data["obstacles"][0]["boxes"])
    scenario = Scenario.from_dict(data)
    assert scenario == Scenario.from_dict(small_dict)
    assert type(scenario.room.width) is float and type(scenario.mission.max_steps) is int
    assert all(type(x) is float for x in scenario.ap.position + scenario.robots[0].destinations[0])

    def shown(value):  # the value and its type, as numpy shows them: np.True_ (bool) in numpy 2, True (bool_) in numpy 1
        return re.escape(f"{value!r} ({type(value).__name__})")

    for value, pattern in [
        (np.bool_(True), r"room\.width: expected a number, got " + shown(np.bool_(True))),
        (np.complex64(12.0), r"room\.width: expected a number, got " + shown(np.complex64(12.0))),
        (np.float32(np.nan), r"room\.width: expected a finite number, got nan"),
        (np.array(12.0), r"room\.width: expected a number, got array\(12\.\) \(ndarray\)"),
    ]:
        data["room"]["width"] = value
        with pytest.raises(ValueError, match=pattern):
            Scenario.from_dict(data)
    data["room"]["width"] = 12.0
    data["mission"]["max_steps"] = np.bool_(True)
    with pytest.raises(ValueError, match=r"mission\.max_steps: expected an integer, got " + shown(np.bool_(True))):
        Scenario.from_dict(data)
    data["mission"]["max_steps"] = 60
    data["robots"][0]["destinations"] = np.array([[True, False]])
    with pytest.raises(ValueError, match=r"robots\[0\]\.destinations\[0\]\[0\]: expected a number, got True \(bool\)"):
        Scenario.from_dict(data)
    data["robots"][0]["destinations"] = np.zeros((0, 2))
    with pytest.raises(ValueError, match=r"robots\[0\]\.destinations: expected a non-empty list, got array\(\["):
        Scenario.from_dict(data)


@pytest.mark.parametrize("point", [[12.0, 4.0], [6.0, 8.0], [12.0, 8.0], [-0.0001, 4.0]])
def test_a_destination_on_the_far_walls_is_refused_at_load_as_by_the_reset_option(small_dict, point):
    """The room's cells span [0, width) x [0, depth): the env's reset option refuses (12, 8); the load does too."""
    env = NomaRadioMapEnv(scenario=Scenario.from_dict(small_dict))
    with pytest.raises(ValueError, match=r"options\['destinations'\]\[1\]: .* is outside the room"):
        env.reset(seed=0, options={"destinations": [[10.0, 2.0], point]})
    data = copy.deepcopy(small_dict)
    data["robots"][1]["destinations"] = [point]
    with pytest.raises(
        ValueError,
        match=rf"^robots\[1\]\.destinations\[0\]: {re.escape(str(point))} is outside the room's cells "
        r"\[0, 12\.0\) x \[0, 8\.0\)",
    ):
        Scenario.from_dict(data)


def test_a_destination_just_inside_the_far_walls_loads_and_is_a_reset_option(small_dict):
    data = copy.deepcopy(small_dict)
    inside = [float(np.nextafter(12.0, 0.0)), 4.0]
    data["robots"][1]["destinations"] = [inside]
    env = NomaRadioMapEnv(scenario=Scenario.from_dict(data))
    env.reset(seed=0, options={"destinations": [[10.0, 2.0], inside]})
    assert env.destinations[1].tolist() == inside


def test_no_builtin_scenario_has_a_destination_on_its_far_walls():
    from noma_radiomap import list_scenarios

    for name in list_scenarios():
        scenario = load_scenario(name)
        points = np.array([p for robot in scenario.robots for p in robot.destinations])
        assert scenario.room.contains(points).all(), name


def test_a_noise_power_that_would_underflow_is_refused(small_dict):
    """The tester's case: N0 B = 1e-28 W/Hz x 1e-300 Hz is 0 in float64, and a step divided by it."""
    data = copy.deepcopy(small_dict)
    data["radio"].update(noise_dbm_per_hz=-250.0, bandwidth_per_robot_hz=1e-300)
    data["interferers"] = []
    with pytest.raises(ValueError, match=r"radio\.bandwidth_per_robot_hz: 1e-300 is outside the physical range \[1, 1e\+10\]"):
        Scenario.from_dict(data)


@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_the_extremes_of_the_radio_ranges_give_finite_rates(small_dict, multiple_access):
    """The corner of RANGES with the largest SINR: the least noise over the narrowest band, the strongest AP at the
    lowest frequency, no interferer, a robot right under the AP (path loss clipped at 1 m)."""
    data = copy.deepcopy(small_dict)
    data["radio"].update(
        noise_dbm_per_hz=RANGES["radio.noise_dbm_per_hz"][0],
        bandwidth_per_robot_hz=RANGES["radio.bandwidth_per_robot_hz"][0],
        frequency_mhz=RANGES["radio.frequency_mhz"][0],
    )
    data["ap"].update(position=[1.25, 1.25, data["robot"]["antenna_height"]], max_power_dbm=RANGES["ap.max_power_dbm"][1])
    data["interferers"] = []
    env = NomaRadioMapEnv(scenario=Scenario.from_dict(data), multiple_access=multiple_access, reward_phase="combined")
    obs, _ = env.reset(seed=0, options={"starts": [[1.25, 1.25], [1.25, 6.75]]})
    for action in ([0.0, 0.0, 1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0, 0.0, -1.0]):  # full power to one or both
        obs, reward, _, _, info = env.step(np.array(action))
        assert np.isfinite(obs).all() and np.isfinite(reward)
        assert np.isfinite(info["rate_bps"]).all() and np.isfinite(info["sinr_db"]).all()
        assert info["sinr_db"].max() > 250.0  # the SINR is huge indeed (about 290 dB), and finite
    assert np.isfinite(env.radio_map.sinr_map_db).all()


@pytest.mark.parametrize("value", [float("inf"), float("nan"), -5, 0, "lots", None, True])
def test_a_bad_memory_cap_attribute_is_named(monkeypatch, value):
    # The attribute set from Python follows the variable's rule (was an OverflowError for inf, a TypeError for None).
    from noma_radiomap import radiomap

    monkeypatch.delenv("NOMA_RADIOMAP_MAX_MEMORY_BYTES", raising=False)
    monkeypatch.setattr(radiomap, "MAX_MEMORY_BYTES", value)
    message = rf"^noma_radiomap.radiomap.MAX_MEMORY_BYTES: expected a positive number of bytes, got {re.escape(repr(value))}$"
    with pytest.raises(ValueError, match=message):
        load_scenario("small")
    monkeypatch.setattr(radiomap, "MAX_MEMORY_BYTES", 2e10)  # a float that is a number of bytes is taken
    assert radiomap.memory_cap() == 20_000_000_000


@pytest.mark.parametrize("text", ["inf", "1e400", "-inf", "nan", "abc", "0"])
def test_a_bad_memory_cap_variable_is_named_without_a_scenario_file(monkeypatch, tmp_path, small_yaml, text):
    monkeypatch.setenv("NOMA_RADIOMAP_MAX_MEMORY_BYTES", text)
    message = rf"^NOMA_RADIOMAP_MAX_MEMORY_BYTES: expected a positive number of bytes, got {re.escape(repr(text))}$"
    for scenario in ("small", _write(tmp_path, small_yaml)):
        with pytest.raises(ValueError, match=message):
            load_scenario(scenario)
