"""Write the paper's Fig. 4 for a scenario: the AP's power distribution map and the SINR map.

Usage::

    python examples/radio_map.py --scenario mall --out mall_radio_map.png
    python examples/radio_map.py --scenario path/to/my_scenario.yaml --out my_map.png
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")

from noma_radiomap import RadioMap, list_scenarios, load_scenario


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="mall", help=f"built-in name ({', '.join(list_scenarios())}) or YAML path")
    parser.add_argument("--out", default=None, help="PNG path (default: <scenario name>_radio_map.png)")
    parser.add_argument("--dpi", type=int, default=120)
    args = parser.parse_args(argv)

    scenario = load_scenario(args.scenario)
    radio_map = RadioMap.for_scenario(scenario)
    out = args.out or f"{scenario.name}_radio_map.png"
    radio_map.plot_maps(out, dpi=args.dpi)
    print(
        f"{scenario.name}: {radio_map.nx} x {radio_map.ny} cells, outage share (one robot, full AP power) "
        f"{radio_map.outage_share():.1%}, SINR {radio_map.sinr_map_db.min():.1f} .. {radio_map.sinr_map_db.max():.1f} dB"
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
