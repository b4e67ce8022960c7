"""noma_radiomap: NOMA indoor robots on a radio map (Gymnasium environment)."""

__version__ = "0.1.0"
