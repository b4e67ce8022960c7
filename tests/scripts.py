"""Load the repository's scripts (``benchmarks/``, ``examples/``), which are not a package, as modules for the tests."""

import importlib.util
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def load_script(name: str, folder: str = "benchmarks") -> ModuleType:
    """
    :param name: the script's file name without ``.py`` (e.g. ``"targets"``)
    :param folder: its folder in the repository
    :return: the script as a fresh module (its ``main`` not run)
    """
    spec = importlib.util.spec_from_file_location(f"{folder}_{name}", ROOT / folder / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
