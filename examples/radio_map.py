"""Write the paper's Fig. 4 for a scenario: the AP's power distribution map and the SINR map.

Usage (``--out`` is a folder, as for ``sb3-dtdpg map``; the figure is ``<out>/maps_<scenario name>.png``)::

    python examples/radio_map.py --scenario mall --out results/maps
    python examples/radio_map.py --scenario path/to/my_scenario.yaml --out my_maps
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from noma_radiomap import RadioMap, list_scenarios, load_scenario
from sb3_dtdpg.arguments import positive_int
from sb3_dtdpg.common.files import safe_name


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="mall", help=f"built-in name ({', '.join(list_scenarios())}) or YAML path")
    parser.add_argument("--out", default="results/maps", help="output folder (default: results/maps)")
    parser.add_argument("--dpi", type=positive_int, default=120, help="resolution of the PNG (default: 120)")
    args = parser.parse_args(argv)
    try:
        scenario = load_scenario(args.scenario)
    except ValueError as error:  # names the scenario and the built-in ones
        parser.error(f"--scenario: {error}")

    radio_map = RadioMap.for_scenario(scenario)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"maps_{safe_name(scenario.name)}.png"  # the name is the YAML's text: never a path
    radio_map.plot_maps(str(path), dpi=args.dpi)
    print(
        f"{scenario.name}: {radio_map.nx} x {radio_map.ny} cells, outage share (one robot, full AP power) "
        f"{radio_map.outage_share():.1%}, SINR {radio_map.sinr_map_db.min():.1f} .. {radio_map.sinr_map_db.max():.1f} dB"
    )
    print(f"wrote {path}")
    return path


if __name__ == "__main__":
    main()
