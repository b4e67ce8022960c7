"""Scenario files (docs/SCENARIOS.md): built-ins, round trips, and validation of every field."""

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from noma_radiomap import RadioMap, Scenario, list_scenarios, load_scenario
from noma_radiomap.motion import GridMotion


@pytest.fixture(scope="module")
def small_dict():
    return load_scenario("small").to_dict()


def test_builtins_listed_and_load():
    names = list_scenarios()
    assert {"mall", "small", "warehouse"} <= set(names)
    for name in names:
        scenario = load_scenario(name)
        assert scenario.name == name
        assert scenario.n_robots == len(scenario.robots) >= 1


def test_mall_follows_table_one():
    s = load_scenario("mall")
    assert (s.room.width, s.room.depth, s.room.resolution) == (55.0, 30.0, 0.5)
    assert (s.room.nx, s.room.ny) == (110, 60)
    assert s.n_robots == 2
    assert s.radio.frequency_mhz == 2000
    assert s.radio.bandwidth_per_robot_hz == 15_000
    assert s.radio.qos_rate_bps == 60_000
    assert s.radio.noise_dbm_per_hz == -100.0
    assert s.ap.max_power_dbm == 20.0
    assert s.robot.v_max == 1.0
    assert s.mission.outage_penalty == 1.0
    # the AP antenna is 2 m above the robots' antennas (the paper's "altitude intercept")
    assert s.ap.position[2] - s.robot.antenna_height == pytest.approx(2.0)
    assert {i.name for i in s.interferers} == {"upstairs", "outdoor"}
    outdoor = next(i for i in s.interferers if i.name == "outdoor")
    assert outdoor.position[0] > s.room.width  # beyond the right-hand wall
    assert all(len(r.destinations) >= 2 for r in s.robots)


def test_dict_round_trip_and_hash(small_dict):
    scenario = Scenario.from_dict(small_dict)
    assert scenario == load_scenario("small")
    assert hash(scenario) == hash(load_scenario("small"))
    again = Scenario.from_dict(scenario.to_dict())
    assert again == scenario
    changed = copy.deepcopy(small_dict)
    changed["ap"]["max_power_dbm"] = 10.0
    assert Scenario.from_dict(changed) != scenario


def test_yaml_file_round_trip(tmp_path, small_dict):
    path = tmp_path / "office.yaml"
    path.write_text(yaml.safe_dump(small_dict))
    assert load_scenario(path) == load_scenario(str(path)) == load_scenario("small")
    assert load_scenario(path).source == str(path)


def test_optional_lists_and_resolution_change(small_dict):
    data = copy.deepcopy(small_dict)
    del data["interferers"]
    del data["obstacles"]
    scenario = Scenario.from_dict(data)
    assert scenario.interferers == () and scenario.obstacles == ()
    finer = load_scenario("small").with_resolution(0.25)
    assert (finer.room.nx, finer.room.ny) == (48, 32)


def _set(path, value):
    """A mutation that sets ``data[path...] = value`` (path as a tuple of keys / indices)."""

    def mutate(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return mutate


def _delete(path):
    def mutate(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]

    return mutate


def _append(path, value):
    def mutate(data):
        target = data
        for key in path:
            target = target[key]
        target.append(value)

    return mutate


# small: room 12 x 8 m at 0.5 m; a wall at x in [6, 6.5] with a doorway at y in [5, 6.5];
# AP at (3, 4, 3.5); robots start in the left half and go to the right half.
BAD_CASES = {
    "missing key": (_delete(("room", "width")), r"room\.width: missing key"),
    "missing top-level key": (_delete(("mission",)), r"mission: missing key"),
    "unknown key": (_set(("room", "height"), 3.0), r"room\.height: unknown key"),
    "unknown top-level key": (_set(("robots_count",), 2), r"robots_count: unknown key"),
    "wrong type": (_set(("room", "width"), "wide"), r"room\.width: expected a number, got 'wide' \(str\)"),
    "bool is not a number": (_set(("robot", "v_max"), True), r"robot\.v_max: expected a number, got True"),
    "wrong type of section": (_set(("radio",), [1, 2]), r"radio: expected a mapping, got \[1, 2\]"),
    "non-finite": (_set(("radio", "noise_dbm_per_hz"), math.nan), r"radio\.noise_dbm_per_hz: expected a finite number"),
    "zero resolution": (_set(("room", "resolution"), 0), r"room\.resolution: must be > 0, got 0"),
    "negative width": (_set(("room", "width"), -12.0), r"room\.width: must be > 0, got -12\.0"),
    "resolution not dividing": (_set(("room", "resolution"), 0.35), r"room\.resolution: 0\.35 must divide room\.width"),
    "non-positive bandwidth": (_set(("radio", "bandwidth_per_robot_hz"), 0.0), r"radio\.bandwidth_per_robot_hz: must be > 0"),
    "negative wall loss": (_set(("radio", "wall_loss_db"), -1.0), r"radio\.wall_loss_db: must be >= 0, got -1\.0"),
    "non-positive body": (_set(("robot", "body_height"), 0.0), r"robot\.body_height: must be > 0, got 0\.0"),
    "max_steps not integer": (_set(("mission", "max_steps"), 2.5), r"mission\.max_steps: expected an integer, got 2\.5"),
    "empty name": (_set(("name",), ""), r"name: expected a non-empty string, got ''"),
    "box outside the room": (
        _set(("obstacles", 0, "boxes", 1), [6.0, 6.5, 6.5, 9.0, 0.0, 4.0]),
        r"obstacles\[0\]\.boxes\[1\]: box \[6\.0, 6\.5, 6\.5, 9\.0, 0\.0, 4\.0\] is outside the room",
    ),
    "box z_top <= z_bottom": (
        _set(("obstacles", 1, "boxes", 0), [3.5, 1.0, 4.5, 2.0, 0.8, 0.8]),
        r"obstacles\[1\]\.boxes\[0\]: z_top must be > z_bottom, got \[3\.5, 1\.0, 4\.5, 2\.0, 0\.8, 0\.8\]",
    ),
    "box zero size": (
        _set(("obstacles", 1, "boxes", 0), [3.5, 1.0, 3.5, 2.0, 0.0, 0.8]),
        r"obstacles\[1\]\.boxes\[0\]: non-positive size .* got \[3\.5, 1\.0, 3\.5, 2\.0, 0\.0, 0\.8\]",
    ),
    "box negative bottom": (
        _set(("obstacles", 1, "boxes", 0), [3.5, 1.0, 4.5, 2.0, -0.5, 0.8]),
        r"obstacles\[1\]\.boxes\[0\]: z_bottom must be >= 0",
    ),
    "box of 5 numbers": (
        _set(("obstacles", 1, "boxes", 0), [3.5, 1.0, 4.5, 2.0, 0.8]),
        r"obstacles\[1\]\.boxes\[0\]: expected a list of 6 numbers, got \[3\.5, 1\.0, 4\.5, 2\.0, 0\.8\]",
    ),
    "box with a string": (
        _set(("obstacles", 1, "boxes", 0), [3.5, 1.0, "x", 2.0, 0.0, 0.8]),
        r"obstacles\[1\]\.boxes\[0\]\[2\]: expected a number, got 'x'",
    ),
    "obstacle without boxes": (_set(("obstacles", 1, "boxes"), []), r"obstacles\[1\]\.boxes: expected a non-empty list"),
    "duplicate obstacle name": (_set(("obstacles", 1, "name"), "wall"), r"obstacles\[1\]\.name: 'wall' is not unique"),
    "AP inside an obstacle": (
        _set(("ap", "position"), [6.25, 2.0, 2.0]),
        r"ap\.position: \[6\.25, 2\.0, 2\.0\] is inside obstacles\[0\]\.boxes\[0\]",
    ),
    "AP inside an obstacle snapped to the grid": (
        # the wall's box is x in [6, 6.5]; a thinner wall [6.0, 6.2] still snaps to the cell [6, 6.5]
        lambda d: (
            _set(("obstacles", 0, "boxes", 0), [6.0, 0.0, 6.2, 5.0, 0.0, 4.0])(d),
            _set(("ap", "position"), [6.3, 2.0, 2.0])(d),
        ),
        r"ap\.position: \[6\.3, 2\.0, 2\.0\] is inside obstacles\[0\]\.boxes\[0\] .*snapped to the grid: \[6\.0, 0\.0, 6\.5",
    ),
    "AP outside the room": (
        _set(("ap", "position"), [13.0, 2.0, 2.0]),
        r"ap\.position: \[13\.0, 2\.0, 2\.0\] is outside the room",
    ),
    "AP of 2 numbers": (
        _set(("ap", "position"), [3.0, 4.0]),
        r"ap\.position: expected a list of 3 numbers, got \[3\.0, 4\.0\]",
    ),
    "interferer named ap": (_set(("interferers", 0, "name"), "ap"), r"interferers\[0\]\.name: 'ap' is not unique"),
    "interferer without power": (_delete(("interferers", 0, "power_dbm")), r"interferers\[0\]\.power_dbm: missing key"),
    "no robots": (_set(("robots",), []), r"robots: expected a non-empty list, got \[\]"),
    "start region without free cells": (
        _set(("robots", 0, "start"), [6.0, 1.0, 6.4, 2.0]),
        r"robots\[0\]\.start: region \[6\.0, 1\.0, 6\.4, 2\.0\] has no free cell",
    ),
    "start region inverted": (
        _set(("robots", 0, "start"), [2.5, 0.5, 0.5, 2.5]),
        r"robots\[0\]\.start: need x0 <= x1 and y0 <= y1, got \[2\.5, 0\.5, 0\.5, 2\.5\]",
    ),
    "destination outside the room": (
        _set(("robots", 1, "destinations", 1), [11.0, 8.5]),
        r"robots\[1\]\.destinations\[1\]: \[11\.0, 8\.5\] is outside the room",
    ),
    "destination in a blocked cell": (
        _set(("robots", 1, "destinations", 0), [6.2, 2.0]),
        r"robots\[1\]\.destinations\[0\]: \[6\.2, 2\.0\] lies in a blocked cell \(12, 4\)",
    ),
    "destination unreachable": (
        _append(("obstacles",), {"name": "door", "boxes": [[6.0, 5.0, 6.5, 6.5, 0.0, 2.0]]}),
        r"robots\[0\]\.destinations\[0\]: \[10\.0, 2\.0\] is unreachable from robots\[0\]\.start region",
    ),
    "no destinations": (_set(("robots", 0, "destinations"), []), r"robots\[0\]\.destinations: expected a non-empty list"),
    "destinations not a list": (
        _set(("robots", 0, "destinations"), "east"),
        r"robots\[0\]\.destinations: expected a list, got 'east'",
    ),
}


@pytest.mark.parametrize("case", list(BAD_CASES))
def test_bad_input_raises_with_field_path_and_value(case, small_dict):
    mutate, pattern = BAD_CASES[case]
    data = copy.deepcopy(small_dict)
    mutate(data)
    with pytest.raises(ValueError, match=pattern):
        Scenario.from_dict(data)


def test_a_start_cell_in_a_pocket_is_unreachable(small_dict):
    # Part of the start region is walled off from the rest: starts drawn there could never arrive.
    data = copy.deepcopy(small_dict)
    data["obstacles"].append({"name": "pen", "boxes": [[1.0, 0.0, 1.5, 1.5, 0.0, 2.0], [0.0, 1.0, 1.0, 1.5, 0.0, 2.0]]})
    with pytest.raises(ValueError, match=r"robots\[0\]\.destinations\[0\]: \[10\.0, 2\.0\] is unreachable"):
        Scenario.from_dict(data)


def test_top_level_not_a_mapping():
    with pytest.raises(ValueError, match=r"scenario: expected a mapping, got \['a'\] \(list\)"):
        Scenario.from_dict(["a"])


def test_unknown_builtin_lists_known_names():
    with pytest.raises(ValueError, match=r"'supermarket': unknown built-in name .*'mall'.*'small'"):
        load_scenario("supermarket")


def test_malformed_yaml_names_file_and_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nroom: {width: 10.0, depth: 5.0\nrobot: [1, 2\n")
    with pytest.raises(ValueError, match=r"broken\.yaml, line \d+, column \d+: malformed YAML"):
        load_scenario(path)


def test_invalid_field_in_file_names_file(tmp_path, small_dict):
    data = copy.deepcopy(small_dict)
    data["room"]["resolution"] = -0.5
    path = tmp_path / "office.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ValueError, match=r"office\.yaml: room\.resolution: must be > 0, got -0\.5"):
        load_scenario(path)


def test_empty_yaml_file(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    with pytest.raises(ValueError, match=r"empty\.yaml: scenario: expected a mapping, got None"):
        load_scenario(Path(path))


@pytest.mark.parametrize("name", ["mall", "warehouse"])
def test_destinations_reachable_by_straight_motion(name):
    # docs/SCENARIOS.md ("mall design"): every destination is reached from every start cell by moving at full
    # speed straight at it, sliding along walls (no concave trap), well within the episode's step limit.
    scenario = load_scenario(name)
    radio_map = RadioMap.for_scenario(scenario)
    motion = GridMotion(
        radio_map.blocked, scenario.room, scenario.robot.v_max * scenario.mission.time_step, scenario.robot.arrival_radius
    )
    for u, robot in enumerate(scenario.robots):
        starts = radio_map.cell_center(*radio_map.start_cells(u).T)
        for destination in robot.destinations:
            goal = np.array([destination], dtype=float)
            for start in starts:
                position = start.reshape(1, 2)
                for _ in range(scenario.mission.max_steps // 4):
                    heading = (goal - position) / np.linalg.norm(goal - position)
                    position, arrived = motion.move(position, heading, goal)
                    if arrived[0]:
                        break
                assert arrived[0], f"{name}: robot {u} from {start} stops at {position[0]}, short of {destination}"


def test_a_scenario_changed_in_code_is_validated_by_the_env():
    import dataclasses

    import gymnasium as gym

    import noma_radiomap  # noqa: F401  (registers the envs)

    small = load_scenario("small")
    rewarded_outage = dataclasses.replace(small, mission=dataclasses.replace(small.mission, outage_penalty=-5.0))
    with pytest.raises(ValueError, match=r"mission\.outage_penalty: .*>= 0") as error:  # was +5 for every outage step
        gym.make("NomaRadioMap-v0", scenario=rewarded_outage)
    assert str(error.value).startswith("scenario 'small' (a Scenario object, as given): ")  # not the file's fault
    no_power = dataclasses.replace(small, ap=dataclasses.replace(small.ap, max_power_dbm=float("nan")))
    with pytest.raises(ValueError, match=r"ap\.max_power_dbm"):  # was NaN powers and MQI under a finite reward
        gym.make("NomaRadioMap-v0", scenario=no_power)
    louder = dataclasses.replace(small, ap=dataclasses.replace(small.ap, max_power_dbm=small.ap.max_power_dbm + 3))
    env = gym.make("NomaRadioMap-v0", scenario=louder)  # a valid change is taken as given
    assert env.unwrapped.scenario == louder
    # and with the types a YAML file gives: numpy and integral float numbers, lists (they broke the TimeLimit and
    # the radio map's cache)
    for max_steps in (np.int64(20), 20.0):
        env = gym.make(
            "NomaRadioMap-v0",
            scenario=dataclasses.replace(small, mission=dataclasses.replace(small.mission, max_steps=max_steps)),
        )
        assert type(env.unwrapped.scenario.mission.max_steps) is int and env.spec.max_episode_steps == 20
    listed = gym.make("NomaRadioMap-v0", scenario=dataclasses.replace(small, robots=list(small.robots)))
    assert listed.unwrapped.scenario == small
