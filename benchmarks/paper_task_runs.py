"""The paper-task runs of an output folder of ``sb3-dtdpg train`` as one table: training success and test results.

``reproduce``'s ``paper_task`` experiment tabulates its own runs; this reads runs trained one at a time, e.g. the
Table I preset with a single value changed on the paper's task::

    for seed in 0 1 2 3 4; do for algo in dtdpg ddpg; do
      sb3-dtdpg train --algo $algo --env NomaRadioMapPaper-v0 --preset paper --hyperparams gamma:0.95 \\
          --episodes 500 --seed $seed --out results/paper_task_ablation --no-progress
    done; done
    python benchmarks/paper_task_runs.py results/paper_task_ablation --csv docs/csv/paper_task_gamma.csv \\
        --figure docs/figures/paper_task_gamma_success.png

Training success is the share of training episodes in which every robot reached its destination (all episodes,
the first 100, the last 100; :func:`sb3_dtdpg.experiments.paper_task.training_success` on the run's TensorBoard
folder); the test columns are the run's 20 Rayleigh test missions. ``--figure`` draws the training success per
episode (a rolling mean over 20 episodes, as ``reproduce``'s paper-task figure), one curve per configuration and
algorithm, the mean over its seeds with a 95 % CI band. Below the per-run table: mean and 95 % CI per configuration
(t-interval over seeds), DT-DPG - DDPG paired by seed; where runs of both downlinks are there, NOMA - OMA per
algorithm paired by seed; where runs add overrides to another set-up's (an ablation: DT-DPG with ``phases:[...]``
beside the runs without), each algorithm of the ablation against the set-up's, paired by seed (a curriculum shows as
its reward phases, ``phases:combined/combined``; a variant trained with ``train --tag`` as its tag). A configuration
is every setting of a run but its algorithm and seed (:data:`CONFIGURATION_FIELDS`: preset, overrides, learning
rate, multiple access, env, scenario, channel, training episodes, ...); the tables show those that differ between
the runs, the others are printed once.

``--with-csv`` adds the runs of per-run tables this script wrote before (``--csv``), e.g. of runs whose folders are
gone, to those of the folder: the OMA runs of the same set-up beside the NOMA ones of ``docs/csv/``::

    python benchmarks/paper_task_runs.py results/paper_task_oma --with-csv docs/csv/paper_task_gamma.csv \
        --csv docs/csv/paper_task_gamma.csv --figure docs/figures/paper_task_gamma_oma_success.png

A run in both is the folder's. The figure draws the folder's runs only (a table holds no per-episode success).
``--with-csv`` reads the per-run table of ``reproduce``'s paper-task experiment too (``docs/csv/paper_task_runs.csv``):
its runs count as ``train`` runs of the same preset without overrides, so that an ablation trained with ``train``
pairs with them (the tuned set without DT-DPG's curriculum, docs/RESULTS.md).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import io
import json
import math
import re
import textwrap
from pathlib import Path
from typing import Any

import pandas as pd

from sb3_dtdpg.evaluation import format_ci, mean_ci
from sb3_dtdpg.experiments.paper_task import ENV_ID, training_success
from sb3_dtdpg.experiments.specs import RunSpec
from sb3_dtdpg.experiments.tables import paired_differences

METRICS = ("train_success", "train_success_first100", "train_success_last100", "test_success", "test_mqi")
#: The columns that make a configuration, whose runs differ only in algorithm and seed: column -> the RunSpec field
#: it holds (``sb3-dtdpg train --hyperparams learning_rate:...`` sets ``learning_rate``, not ``overrides``). Every
#: field that changes a run's result is one; ``episodes`` is the number of training episodes logged.
CONFIGURATION_FIELDS = {
    "preset": "hyperparams",
    "overrides": "overrides",
    "learning_rate": "learning_rate",
    "multiple_access": "multiple_access",
    "env_id": "env_id",
    "scenario": "scenario",
    "channel": "channel",
    "budget_episodes": "episodes",
    "timesteps": "timesteps",
    "observation": "observation",
    "power_mapping": "power_mapping",
    "inducing": "inducing",
    "destination_episodes": "destination_episodes",
    "tag": "tag",
    "eval_episodes": "eval_episodes",
    "eval_seed": "eval_seed",
    "eval_channel": "eval_channel",
}
CONFIGURATION = list(CONFIGURATION_FIELDS)
#: The configuration columns shown even when every run has the same value
ALWAYS_SHOWN = ["preset", "overrides", "multiple_access"]
_DEFAULTS = {field.name: field.default for field in dataclasses.fields(RunSpec)}


def _spec_value(spec: dict[str, Any], field: str) -> Any:
    """:return: a field of a stored run spec, RunSpec's default where a result of an earlier version lacks it (no
    episodes count for a run of a budget in timesteps: runs stored with the CLI's unused ``--episodes`` are its; the
    default room, named or not, as None)"""
    if field == "episodes" and spec.get("timesteps") is not None:
        return None
    value = spec.get(field, _DEFAULTS.get(field))
    if field == "scenario":
        return _scenario(value, spec.get("env_id", _DEFAULTS["env_id"]))
    if field == "overrides":
        return " ".join(f"{name}:{text}" for name, text in value or [])
    return None if value is dataclasses.MISSING else value


def _scenario(name: Any, env_id: str) -> Any:
    """:return: the scenario of a run, None for its env id's default room, given by name or not (the default as
    :func:`sb3_dtdpg.experiments.specs.run_identity` reads it, :func:`noma_radiomap.registration.default_scenario`)"""
    from noma_radiomap.registration import default_scenario

    return None if name == default_scenario(env_id) else name


def run_rows(out: Path) -> pd.DataFrame:
    """
    :param out: an output folder of ``sb3-dtdpg train`` (``runs/<run id>/result.json``, ``tb/<run id>/``)
    :return: one row per finished run, sorted by configuration (:data:`CONFIGURATION`), algorithm and seed
    """
    rows = []
    for result_file in sorted((out / "runs").glob("*/result.json")):
        result = json.loads(result_file.read_text())
        spec, test = result["spec"], result["eval"]["summary"]
        run_id = result_file.parent.name
        every, first, last, n_episodes = training_success(out / "tb" / run_id)
        rows.append(
            {
                "run_id": run_id,
                "algo": spec["algo"],
                **{column: _spec_value(spec, field) for column, field in CONFIGURATION_FIELDS.items()},
                "seed": spec["seed"],
                "episodes": n_episodes,
                "train_success": every,
                "train_success_first100": first,
                "train_success_last100": last,
                "test_success": test["success_rate"],
                "test_mqi": test["mqi"],
                "wall_s": result["train"]["wall_s"],
            }
        )
    frame = pd.DataFrame(rows)
    return _sorted(frame) if rows else frame


def _sorted(frame: pd.DataFrame) -> pd.DataFrame:
    """:return: the runs sorted by configuration (:data:`CONFIGURATION`), algorithm (DT-DPG first) and seed"""
    order = [*CONFIGURATION, "algo", "seed"]
    return frame.sort_values(order, ascending=[column != "algo" for column in order], kind="stable")


def with_tables(frame: pd.DataFrame, tables: list[Path]) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :param tables: per-run tables written by ``--csv`` (the columns of :func:`run_rows`), or by ``reproduce``'s
        paper-task experiment (:func:`reproduce_runs`)
    :return: the runs of ``frame`` and those of the tables that ``frame`` has not (by run id), sorted as
        :func:`run_rows` sorts; every value as read from a CSV file, so that a value missing in one source and in
        another compares equal
    :raises ValueError: a table lacks a column of :func:`run_rows`, naming the file and the columns
    """
    columns = ["run_id", "algo", *CONFIGURATION, "seed", "episodes", *METRICS, "wall_s"]
    read = []
    for table in tables:
        rows = pd.read_csv(table)
        if set(_REPRODUCE_COLUMNS) <= set(rows.columns):
            rows = _as_read(reproduce_runs(rows))
        missing = [column for column in columns if column not in rows.columns]
        if missing:
            raise ValueError(f"--with-csv {table}: not a table of this script (no columns {', '.join(missing)})")
        read.append(rows[columns])
    own = _as_read(frame) if not frame.empty else pd.DataFrame(columns=columns)
    return _sorted(pd.concat([own, *read], ignore_index=True).drop_duplicates("run_id"))  # the first: the folder's


def _as_read(frame: pd.DataFrame) -> pd.DataFrame:
    """:return: ``frame`` as written to a CSV file and read back"""
    return pd.read_csv(io.StringIO(frame.to_csv(index=False)))


#: The columns of ``reproduce``'s per-run paper-task table that :func:`reproduce_runs` reads
_REPRODUCE_COLUMNS = {
    "group": "run_id",
    "algo": "algo",
    "preset": "preset",
    "learning_rate": "learning_rate",
    "multiple_access": "multiple_access",
    "scenario": "scenario",
    "training": "channel",
    "episodes": "budget_episodes",
    "seed": "seed",
    "train_episodes": "episodes",
    "train_success": "train_success",
    "train_success_first": "train_success_first100",
    "train_success_last": "train_success_last100",
    "success_rate": "test_success",
    "mqi": "test_mqi",
    "train_wall_s": "train_wall_s",
}


def reproduce_runs(rows: pd.DataFrame) -> pd.DataFrame:
    """
    :param rows: the per-run table of ``sb3-dtdpg reproduce``'s paper-task experiment (``paper_task_runs.csv``, e.g.
        ``docs/csv/paper_task_runs.csv``)
    :return: its runs as :func:`run_rows` gives runs of ``sb3-dtdpg train`` with the same settings: no overrides,
        the paper's task and state, the default test; the run id ``<group>_s<seed>``. Its tag, which names
        ``reproduce``'s experiment, is left out, so that ``train`` runs of the set-up pair with these.
    """
    runs = rows[list(_REPRODUCE_COLUMNS)].rename(columns=_REPRODUCE_COLUMNS)
    runs["run_id"] = [f"{group}_s{seed}" for group, seed in zip(runs["run_id"], runs["seed"], strict=True)]
    runs["multiple_access"] = runs["multiple_access"].str.lower()
    runs["scenario"] = [_scenario(name, ENV_ID) for name in runs["scenario"]]
    defaults = {column: _spec_value({}, field) for column, field in CONFIGURATION_FIELDS.items()}
    fixed = {"overrides": "", "env_id": ENV_ID, "observation": "paper", "timesteps": None, "tag": ""}
    for column in CONFIGURATION:
        if column not in runs.columns:
            runs[column] = fixed.get(column, defaults[column])
    return runs.rename(columns={"train_wall_s": "wall_s"})


def summary_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :return: per configuration and algorithm: ``n`` (seeds) and ``<metric> ± <95 % CI>`` text per metric
    """
    rows = []
    for key, group in frame.groupby([*CONFIGURATION, "algo"], sort=False, dropna=False):
        row = dict(zip([*CONFIGURATION, "algo"], key, strict=True))
        row["n"] = len(group)
        for metric in METRICS:
            row[metric] = _with_ci(*mean_ci(group[metric].to_numpy(dtype=float)), metric)
        rows.append(row)
    return pd.DataFrame(rows)


def paired_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :return: DT-DPG - DDPG per configuration on the seeds both have: ``n`` (pairs) and ``<difference> ± <95 % CI>``
    """
    return _paired(frame, "algo", ("dtdpg", "ddpg"), CONFIGURATION)


def access_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :return: NOMA - OMA per configuration but the downlink, and per algorithm, on the seeds both have: ``n`` (pairs)
        and ``<difference> ± <95 % CI>``; empty where no configuration has runs of both
    """
    by = [*(column for column in CONFIGURATION if column != "multiple_access"), "algo"]
    return _paired(frame, "multiple_access", ("noma", "oma"), by)


def override_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """
    :param frame: output of :func:`run_rows`
    :return: the ablations of a set-up: runs whose overrides are another set-up's and more (e.g. DT-DPG with
        ``gamma:0.95 phases:[...]`` beside runs with ``gamma:0.95``) minus the set-up's runs of the same algorithm,
        and, where the ablation trains one algorithm only, of the set-up's other algorithms too (DT-DPG without its
        curriculum against DDPG, which trains on the same reward); paired by seed within the rest of the
        configuration: ``n`` (pairs) and ``<difference> ± <95 % CI>``; empty where there are none
    """
    by = [column for column in CONFIGURATION if column not in ("overrides", "tag")]
    variants = frame.assign(
        variant=[
            f"{algo} {_text(tag)} {_text(text)}"
            for algo, tag, text in zip(frame["algo"], frame["tag"], frame["overrides"], strict=True)
        ]
    )
    kinds = variants[["algo", "tag", "overrides", "variant"]].drop_duplicates("variant")
    items = {variant: _override_items(text) for variant, text in zip(kinds["variant"], kinds["overrides"], strict=True)}
    algos = variants.groupby("overrides", dropna=False)["algo"].nunique()
    names = naming_tags(frame)
    tables = []
    for _, first in kinds.iterrows():
        for _, second in kinds.iterrows():
            ablation, base = items[first["variant"]], items[second["variant"]]
            if base < ablation and (first["algo"] == second["algo"] or algos[first["overrides"]] == 1):
                rows = _paired(variants, "variant", (first["variant"], second["variant"]), by)
                contrast = f"{_variant_label(first, names)} - {_variant_label(second, names)}"
                tables.append(rows.assign(contrast=contrast))
    rows = [table for table in tables if not table.empty]
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=[*by, "contrast", "n", *METRICS])


def _override_items(text: Any) -> frozenset[str]:
    """:return: the ``name:value`` items of an overrides text (none for ``-``)"""
    return frozenset(item for item in _OVERRIDE_START.split(_text(text)) if item != "-")


def naming_tags(frame: pd.DataFrame) -> set[str]:
    """
    :param frame: output of :func:`run_rows`
    :return: the tags (``train --tag``) that name a variant: given to runs of one set of overrides only, so that a
        label may show the tag instead of the overrides
    """
    tagged = frame[frame["tag"].map(_text) != "-"]
    counts = tagged.groupby("tag")["overrides"].nunique(dropna=False)
    return {tag for tag, count in counts.items() if count == 1}


def _variant_label(kind: pd.Series, names: set[str]) -> str:
    """:return: e.g. ``dtdpg gamma:0.95 phases:combined/combined``, the algorithm and its overrides
    (:func:`_short_overrides`), or the algorithm and its tag where the tag is one of ``names``
    (:func:`naming_tags`: ``dtdpg no_curriculum``)"""
    name = kind["tag"] if kind["tag"] in names else _short_overrides(kind["overrides"])
    return kind["algo"] if name == "-" else f"{kind['algo']} {name}"


#: Where one ``name:value`` of an overrides text begins (values such as a list of phases hold spaces)
_OVERRIDE_START = re.compile(r" (?=[A-Za-z_]\w*:)")


def _short_overrides(text: Any) -> str:
    """:return: an overrides text for a label: a curriculum's ``phases`` as its reward phases
    (``phases:combined/combined``), any other value longer than 80 characters cut to its first 30 and ``...``;
    ``-`` for none"""
    items = [item.partition(":") for item in _OVERRIDE_START.split(_text(text))]
    return " ".join(name + colon + _short_value(name, value) for name, colon, value in items)


def _short_value(name: str, value: str) -> str:
    if name == "phases":
        try:
            return "/".join(str(phase.get("reward_phase", phase.get("name"))) for phase in ast.literal_eval(value))
        except (ValueError, SyntaxError, TypeError, AttributeError):
            pass
    return value if len(value) <= 80 else value[:30] + "..."


def _paired(frame: pd.DataFrame, contrast: str, sides: tuple[str, str], by: list[str]) -> pd.DataFrame:
    """:return: the metrics' differences ``sides[0] - sides[1]`` of column ``contrast``, paired by seed within each
    configuration of ``by``, as ``<difference> ± <95 % CI>`` text (see :func:`paired_differences`)"""
    differences = paired_differences(frame, contrast, *sides, by=by, metrics=METRICS)
    if differences.empty:
        return pd.DataFrame(columns=[*by, "contrast", "n", *METRICS])
    for metric in METRICS:
        differences[metric] = [
            _with_ci(value, half, metric) for value, half in zip(differences[metric], differences[f"{metric}_ci"], strict=True)
        ]
    return differences[[*by, "contrast", "n", *METRICS]]


def shown_configuration(frame: pd.DataFrame) -> tuple[list[str], dict[str, str]]:
    """
    :param frame: output of :func:`run_rows`
    :return: the configuration columns to show (:data:`ALWAYS_SHOWN` and those that differ between runs) and the
        value of each other one, the same in every run
    """
    shown = [column for column in CONFIGURATION if column in ALWAYS_SHOWN or frame[column].map(_text).nunique() > 1]
    common = {column: _text(frame[column].iloc[0]) for column in CONFIGURATION if column not in shown}
    return shown, common


def plot_success(frame: pd.DataFrame, out: Path, path: Path) -> Any:
    """
    The training success per episode of the runs of ``frame``, one curve per configuration and algorithm.

    :param frame: output of :func:`run_rows`
    :param out: the output folder of the runs (their TensorBoard folders are ``<out>/tb/<run id>``)
    :param path: the PNG to write
    :return: the figure
    """
    from sb3_dtdpg.experiments import plots, tables

    configuration, common = shown_configuration(frame)
    names = naming_tags(frame)
    groups: dict[str, list[Path]] = {}
    for _, row in frame.iterrows():
        # a tag that names the variant stands for its overrides, shown where the tags differ between runs
        named = row["tag"] in names and "tag" in configuration
        shown = [_label_text(column, row[column]) for column in configuration if not (named and column == "overrides")]
        label = " ".join([tables.ALGO_LABELS[row["algo"]], *(text for text in shown if text != "-")])
        label = textwrap.fill(label, width=40, break_long_words=False)  # two legend columns fit the figure's width
        groups.setdefault(label, []).append(out / "tb" / row["run_id"])
    channel = {"radio_map": "radio-map training", "rayleigh": "Rayleigh training"}.get(common.get("channel", "-"), "")
    return plots.plot_learning_curves(
        groups,
        path,
        tags=((plots.SUCCESS_TAG, "training episodes reaching the destination"),),
        smooth=20,
        title=f"The paper's task: training success per episode\n{channel}".rstrip(),
        band_note=True,
    )


def _label_text(column: str, value: Any) -> str:
    """:return: a configuration value as a figure's legend shows it: the downlink in capitals"""
    return _shown_text(column, value).upper() if column == "multiple_access" else _shown_text(column, value)


def _shown_text(column: str, value: Any) -> str:
    """:return: a configuration value as the tables show it: overrides shortened (:func:`_short_overrides`)"""
    return _short_overrides(value) if column == "overrides" else _text(value)


def _text(value: Any) -> str:
    """A configuration value as table text: ``-`` for None (the default) or nothing, numbers without a trailing ``.0``."""
    if value is None or value == "" or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _with_ci(value: float, half: float, metric: str) -> str:
    return format_ci(value, half, scale=1.0 if metric == "test_mqi" else 100.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    parser.add_argument("out", type=Path, help="the output folder of the train runs")
    parser.add_argument("--csv", type=Path, default=None, help="also write the table here")
    parser.add_argument("--figure", type=Path, default=None, help="also draw the training success per episode here (PNG)")
    parser.add_argument(
        "--with-csv",
        type=Path,
        nargs="+",
        default=[],
        help="per-run tables written by --csv before, or by reproduce's paper-task experiment: their runs join the "
        "folder's (not the figure)",
    )
    args = parser.parse_args()
    if not (args.out / "runs").is_dir():
        parser.error(f"{args.out}: no runs/ folder (give the --out of the train runs)")
    for table in args.with_csv:
        if not table.is_file():
            parser.error(f"--with-csv {table}: no such file")
    folder_runs = run_rows(args.out)
    if folder_runs.empty:
        parser.error(f"{args.out}: no finished run (runs/*/result.json)")
    try:
        frame = with_tables(folder_runs, args.with_csv) if args.with_csv else folder_runs
    except ValueError as error:
        parser.error(str(error))
    if args.csv is not None:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        frame.to_csv(args.csv, index=False)
    if args.figure is not None:
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        plot_success(folder_runs, args.out, args.figure)
    configuration, common = shown_configuration(frame)
    hidden = [column for column in CONFIGURATION if column not in configuration]
    print("every run: " + ", ".join(f"{column} {value}" for column, value in common.items()) + "\n")
    shown = frame.drop(columns=["run_id", *hidden]).copy()
    for column in configuration:
        shown[column] = [_shown_text(column, value) for value in shown[column]]
    for column in ("train_success", "train_success_first100", "train_success_last100", "test_success"):
        shown[column] = (100 * shown[column]).round(1)
    print(shown.to_string(index=False, float_format=lambda value: f"{value:.1f}"))
    _print_table("mean ± 95 % CI (t-interval over seeds; n/a: one seed); success in %", summary_rows(frame), configuration)
    paired_title = "paired by seed: mean difference ± 95 % CI (t-interval over the per-seed differences); success in points"
    _print_table(paired_title, paired_rows(frame), configuration)
    _print_table("NOMA - OMA, paired by seed, per algorithm; success in points", access_rows(frame), configuration)
    override_title = "ablations: runs with more overrides minus those of the set-up, paired by seed; success in points"
    _print_table(override_title, override_rows(frame), configuration)


def _print_table(title: str, rows: pd.DataFrame, configuration: list[str]) -> None:
    """Print ``rows`` under ``title`` with the shown configuration columns as text and without the others (nothing
    for no rows)."""
    if rows.empty:
        return
    hidden = [column for column in CONFIGURATION if column not in configuration and column in rows.columns]
    shown = rows.drop(columns=hidden)
    text = {
        column: [_shown_text(column, value) for value in shown[column]] for column in configuration if column in shown.columns
    }
    print(f"\n{title}")
    print(shown.assign(**text).to_string(index=False))


if __name__ == "__main__":
    main()
