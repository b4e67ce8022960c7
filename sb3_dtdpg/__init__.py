"""sb3-dtdpg: DT-DPG (deep transfer deterministic policy gradient) for Stable-Baselines3.

The public names are imported on first use (PEP 562), so that ``import sb3_dtdpg.cli`` (``sb3-dtdpg --help``)
does not import torch and Stable-Baselines3.
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from typing import Any

try:
    __version__ = version("sb3-dtdpg")
except PackageNotFoundError:  # a source tree on sys.path, not installed
    __version__ = "0+unknown"

#: Where each public name lives.
_EXPORTS = {
    "DTDPG": "sb3_dtdpg.dtdpg",
    "CnnPolicy": "sb3_dtdpg.dtdpg",
    "MlpPolicy": "sb3_dtdpg.dtdpg",
    "MultiInputPolicy": "sb3_dtdpg.dtdpg",
    "CurriculumTransferCallback": "sb3_dtdpg.common.callbacks",
    "ExactCheckpointCallback": "sb3_dtdpg.common.checkpoints",
    "load_checkpoint": "sb3_dtdpg.common.checkpoints",
    "LinearDecayOUNoise": "sb3_dtdpg.common.noise",
    "Phase": "sb3_dtdpg.common.phases",
    "MissionLoggerCallback": "sb3_dtdpg.missions",
    "preset": "sb3_dtdpg.presets",
}

__all__ = [
    "DTDPG",
    "CnnPolicy",
    "CurriculumTransferCallback",
    "ExactCheckpointCallback",
    "LinearDecayOUNoise",
    "MissionLoggerCallback",
    "MlpPolicy",
    "MultiInputPolicy",
    "Phase",
    "__version__",
    "load_checkpoint",
    "preset",
]


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'sb3_dtdpg' has no attribute {name!r}")
    value = getattr(import_module(_EXPORTS[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
