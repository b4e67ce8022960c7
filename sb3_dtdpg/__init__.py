"""sb3-dtdpg: DT-DPG (deep transfer deterministic policy gradient) for Stable-Baselines3."""

from sb3_dtdpg.common.callbacks import CurriculumTransferCallback
from sb3_dtdpg.common.noise import LinearDecayOUNoise
from sb3_dtdpg.common.phases import Phase
from sb3_dtdpg.dtdpg import DTDPG, CnnPolicy, MlpPolicy, MultiInputPolicy
from sb3_dtdpg.missions import MissionLoggerCallback

__version__ = "0.1.0"

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
]
