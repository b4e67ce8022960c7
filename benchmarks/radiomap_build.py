"""Radio-map build time and memory: ``mall`` at 0.5 m and at 0.1 m resolution.

Bars: ``mall`` builds in <= 0.25 s; ``mall`` at 0.1 m (550 x 300 cells) in <= 10 s and <= 2 GiB
peak memory. Every build is fresh (``RadioMap(scenario)``, not the cache). The 0.1 m build runs
in a child process so that its peak memory is its own: reported as the peak of traced allocations
(``tracemalloc``, numpy included) and as the child's maximum resident set size (whole process,
interpreter and libraries included; the bar is checked against this one).

Usage::

    python benchmarks/radiomap_build.py [--repeats 5]

``run_radiomap_benchmark()`` returns the figures as a dict (``benchmarks/env_speed.py`` calls it too).
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc

from sb3_dtdpg.arguments import positive_int

BAR_MALL_S = 0.25
BAR_FINE_S = 10.0
BAR_FINE_BYTES = 2 * 1024**3


def _build_once(scenario) -> float:
    from noma_radiomap import RadioMap

    start = time.perf_counter()
    RadioMap(scenario)
    return time.perf_counter() - start


def _child(resolution: float) -> None:
    """Build ``mall`` at ``resolution`` once and print its time and peak memory as JSON."""
    from noma_radiomap import RadioMap, load_scenario

    scenario = load_scenario("mall").with_resolution(resolution)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    tracemalloc.start()
    start = time.perf_counter()
    radio_map = RadioMap(scenario)
    seconds = time.perf_counter() - start
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux reports KiB
    # tracemalloc slows allocation-heavy code down; time a second, untraced build as well.
    untraced = _build_once(scenario)
    print(
        json.dumps(
            {
                "shape": list(radio_map.shape),
                "seconds_traced": seconds,
                "seconds": untraced,
                "traced_peak_bytes": traced_peak,
                "max_rss_bytes": rss_peak,
                "rss_before_build_bytes": rss_before,
            }
        )
    )


def run_radiomap_benchmark(repeats: int = 5, fine_resolution: float = 0.1) -> dict:
    """
    Measure the radio-map build of ``mall`` (fresh builds) at its own resolution and at ``fine_resolution``.

    :param repeats: number of fresh builds of ``mall`` to time (the median is reported and checked)
    :param fine_resolution: the fine grid (m) built once in a child process
    :return: the figures and whether each bar holds
    """
    from noma_radiomap import load_scenario

    scenario = load_scenario("mall")
    times = [_build_once(scenario) for _ in range(repeats)]
    child = subprocess.run(
        [sys.executable, __file__, "--child", str(fine_resolution)], check=True, capture_output=True, text=True
    )
    fine = json.loads(child.stdout.strip().splitlines()[-1])
    median = statistics.median(times)
    return {
        "mall_shape": [scenario.room.nx, scenario.room.ny],
        "mall_build_s_median": median,
        "mall_build_s_first": times[0],
        "mall_build_s_min": min(times),
        "mall_bar_s": BAR_MALL_S,
        "mall_ok": median <= BAR_MALL_S,
        "fine_resolution_m": fine_resolution,
        "fine_shape": fine["shape"],
        "fine_build_s": fine["seconds"],
        "fine_build_s_traced": fine["seconds_traced"],
        "fine_traced_peak_bytes": fine["traced_peak_bytes"],
        "fine_max_rss_bytes": fine["max_rss_bytes"],
        "fine_bar_s": BAR_FINE_S,
        "fine_bar_bytes": BAR_FINE_BYTES,
        "fine_ok": fine["seconds"] <= BAR_FINE_S and fine["max_rss_bytes"] <= BAR_FINE_BYTES,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description="Radio-map build time and memory")
    parser.add_argument("--repeats", type=positive_int, default=5)
    parser.add_argument("--child", type=float, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        _child(args.child)
        return
    r = run_radiomap_benchmark(args.repeats)
    mib = 1024**2
    print(f"python {platform.python_version()}, {platform.machine()}")
    median, first, fastest = (r[f"mall_build_s_{k}"] * 1e3 for k in ("median", "first", "min"))
    print(
        f"mall {r['mall_shape'][0]}x{r['mall_shape'][1]}: build {median:.1f} ms median of {args.repeats} fresh builds "
        f"(first {first:.1f} ms, min {fastest:.1f} ms); {r['mall_build_s_median'] / r['mall_bar_s']:.2f}x of the "
        f"{r['mall_bar_s']} s bar -> {'OK' if r['mall_ok'] else 'FAIL'}"
    )
    print(
        f"mall at {r['fine_resolution_m']} m {r['fine_shape'][0]}x{r['fine_shape'][1]}: build {r['fine_build_s']:.2f} s "
        f"({r['fine_build_s'] / r['fine_bar_s']:.2f}x of the {r['fine_bar_s']:.0f} s bar; {r['fine_build_s_traced']:.2f} s "
        f"under tracemalloc), peak traced {r['fine_traced_peak_bytes'] / mib:.0f} MiB, max RSS "
        f"{r['fine_max_rss_bytes'] / mib:.0f} MiB ({r['fine_max_rss_bytes'] / r['fine_bar_bytes']:.2f}x of the 2 GiB bar) "
        f"-> {'OK' if r['fine_ok'] else 'FAIL'}"
    )


if __name__ == "__main__":
    main()
