from sb3_dtdpg.dtdpg.dtdpg import DTDPG
from sb3_dtdpg.dtdpg.policies import DTDPGPolicy, MlpPolicy

__all__ = ["DTDPG", "DTDPGPolicy", "MlpPolicy"]
