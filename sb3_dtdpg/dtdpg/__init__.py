from sb3_dtdpg.dtdpg.dtdpg import DTDPG
from sb3_dtdpg.dtdpg.policies import CnnPolicy, DTDPGPolicy, MlpPolicy, MultiInputPolicy

__all__ = ["DTDPG", "CnnPolicy", "DTDPGPolicy", "MlpPolicy", "MultiInputPolicy"]
