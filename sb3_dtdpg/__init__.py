"""sb3-dtdpg: DT-DPG (deep transfer deterministic policy gradient) for Stable-Baselines3."""

from importlib.metadata import PackageNotFoundError, version

from sb3_dtdpg.common.callbacks import CurriculumTransferCallback
from sb3_dtdpg.common.noise import LinearDecayOUNoise
from sb3_dtdpg.common.phases import Phase
from sb3_dtdpg.dtdpg import DTDPG, CnnPolicy, MlpPolicy, MultiInputPolicy
from sb3_dtdpg.missions import MissionLoggerCallback
from sb3_dtdpg.presets import preset

try:
    __version__ = version("sb3-dtdpg")
except PackageNotFoundError:  # a source tree on sys.path, not installed
    __version__ = "0+unknown"

__all__ = [
    "DTDPG",
    "CnnPolicy",
    "CurriculumTransferCallback",
    "LinearDecayOUNoise",
    "MissionLoggerCallback",
    "MlpPolicy",
    "MultiInputPolicy",
    "Phase",
    "__version__",
    "preset",
]
