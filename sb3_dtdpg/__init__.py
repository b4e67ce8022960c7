"""sb3-dtdpg: DT-DPG (deep transfer deterministic policy gradient) for Stable-Baselines3."""

__version__ = "0.1.0"
