"""The wheel: built from the tree, installed into a fresh venv, used from another folder (no source tree on the path).

The venv borrows the dependencies already installed here (torch, SB3, the RL Zoo, ...) through a ``.pth`` file
instead of downloading them, but holds its own copy of sb3-dtdpg: the one from the wheel.
"""

import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
IGNORED = (".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis", "runs", "results", "logs")
# Phase 1 ends after one episode, so the zoo run below crosses a transfer
TWO_SHORT_PHASES = "phases:[dict(name='destination',n_episodes=1,sigma=0.5),dict(name='mqi',sigma=0.4)]"


def run(*args: str | Path, cwd: Path, timeout: float = 240) -> str:
    env = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    result = subprocess.run([str(a) for a in args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    output = result.stdout + result.stderr
    assert result.returncode == 0, f"{' '.join(map(str, args))} failed:\n{output[-4000:]}"
    return output


def _setuptools_version() -> tuple[int, ...]:
    try:
        return tuple(int(part) for part in version("setuptools").split(".")[:2])
    except PackageNotFoundError:
        return (0,)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel, built from a copy of the tree (building writes build/ and *.egg-info next to the sources)."""
    root = tmp_path_factory.mktemp("wheel")
    source = root / "src"
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(*IGNORED))
    # The installed setuptools when it can build this pyproject (the tests extra asks for one), else pip's isolated one
    isolation = [] if _setuptools_version() < (77,) else ["--no-build-isolation"]
    run(sys.executable, "-m", "pip", "wheel", "--no-deps", *isolation, "-q", "-w", root / "dist", source, cwd=root)
    (path,) = (root / "dist").glob("sb3_dtdpg-*.whl")
    return path


def test_the_source_distribution_runs_its_own_tests(tmp_path: Path) -> None:
    """The sdist holds what its tests read (their helpers, the docs they check, the scripts they run): they collect."""
    if _setuptools_version() < (77,):
        pytest.skip("building this pyproject needs setuptools >= 77 (the tests extra)")
    source = tmp_path / "src"
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(*IGNORED))
    build = "import sys; from setuptools import build_meta; print('SDIST', build_meta.build_sdist(sys.argv[1]))"
    output = run(sys.executable, "-c", build, tmp_path / "dist", cwd=source)
    (name,) = [line.split()[1] for line in output.splitlines() if line.startswith("SDIST ")]
    with tarfile.open(tmp_path / "dist" / name) as sdist:
        sdist.extractall(tmp_path / "unpacked", filter="data")
    (unpacked,) = (tmp_path / "unpacked").iterdir()
    expected = {
        p.relative_to(REPO).as_posix()
        for folder in ("tests", "docs", "examples", "benchmarks", "zoo_configs")
        for p in (REPO / folder).rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and not p.name.startswith(".")
    }
    held = {p.relative_to(unpacked).as_posix() for p in unpacked.rglob("*") if p.is_file()}
    assert expected - held == set()
    # The wheel built from the sdist, as `python -m build` makes it: setuptools finds each folder of package data listed
    build = "import sys; from setuptools import build_meta; print('WHEEL', build_meta.build_wheel(sys.argv[1]))"
    output = run(sys.executable, "-c", build, tmp_path / "wheel", cwd=unpacked)
    assert "is absent from the `packages` configuration" not in output
    collected = run(sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", "tests", cwd=unpacked)
    assert "error" not in collected.lower().splitlines()[-1] and "tests collected" in collected


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh venv with the wheel installed; the other dependencies come from this interpreter's site-packages."""
    root = tmp_path_factory.mktemp("venv")
    run(sys.executable, "-m", "venv", "--without-pip", root / "venv", cwd=root)
    python = root / "venv" / "bin" / "python"
    run(sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index", "-q", wheel, cwd=root)
    site_packages = Path(run(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])", cwd=root).strip())
    # Added after the install, so pip saw an empty venv. Paths listed in a .pth file are appended to sys.path, after the
    # venv's own site-packages, and the .pth files found there are not run (no editable sb3_dtdpg sneaks in).
    borrowed = dict.fromkeys(sysconfig.get_paths()[key] for key in ("purelib", "platlib"))
    (site_packages / "borrowed_dependencies.pth").write_text("".join(f"{path}\n" for path in borrowed))
    return root / "venv"


def test_wheel_holds_every_module_the_zoo_configs_and_the_license(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(REPO).as_posix() for p in (REPO / "sb3_dtdpg").rglob("*.py")}
    modules |= {p.relative_to(REPO / "envs").as_posix() for p in (REPO / "envs" / "noma_radiomap").rglob("*.py")}
    assert modules - names == set()
    assert {f"sb3_dtdpg/zoo_configs/{p.name}" for p in (REPO / "zoo_configs").glob("*.yml")} <= names
    assert {"noma_radiomap/scenarios/mall.yaml", "sb3_dtdpg/py.typed"} <= names
    assert any(name.endswith(".dist-info/licenses/LICENSE") for name in names)


def test_installed_wheel_runs_from_another_folder(venv: Path, tmp_path: Path) -> None:
    python = venv / "bin" / "python"
    check = (
        "import gymnasium as gym, noma_radiomap, sb3_dtdpg; from importlib.metadata import version; "
        "env = gym.make('NomaRadioMap-v0', scenario='small'); obs, _ = env.reset(seed=0); "
        "print('RESULT', sb3_dtdpg.__file__, noma_radiomap.__file__, sb3_dtdpg.__version__, version('sb3-dtdpg'), "
        "env.observation_space.contains(obs))"
    )
    (line,) = [line for line in run(python, "-c", check, cwd=tmp_path).splitlines() if line.startswith("RESULT ")]
    _, sb3_file, env_file, pkg_version, metadata_version, contains = line.split()
    assert Path(sb3_file).is_relative_to(venv) and Path(env_file).is_relative_to(venv)
    assert pkg_version == metadata_version != "0+unknown" and contains == "True"
    assert run(venv / "bin" / "sb3-dtdpg", "--version", cwd=tmp_path).strip() == f"sb3-dtdpg {pkg_version}"

    # The RL Zoo without --conf-file: the packaged config, --env-kwargs merged into its env_kwargs
    output = run(
        python, "-m", "sb3_dtdpg.train", "--algo", "dtdpg", "--env", "NomaRadioMap-v0", "-n", "200",
        "--env-kwargs", "scenario:'small'", "-params", "learning_starts:50", "buffer_size:1000", TWO_SHORT_PHASES,
        "--eval-freq", "-1", "--num-threads", "1", "-f", "logs", cwd=tmp_path,
    )  # fmt: skip
    assert f"Loading hyperparameters from: {venv}" in output and "sb3_dtdpg/zoo_configs/dtdpg.yml" in output
    run_dir = tmp_path / "logs" / "dtdpg" / "NomaRadioMap-v0_1"
    assert (run_dir / "NomaRadioMap-v0.zip").exists() and (run_dir / "phase_0_destination.zip").exists()
    config = (run_dir / "NomaRadioMap-v0" / "config.yml").read_text()
    assert "reward_phase: mqi" in config and "scenario: small" in config
