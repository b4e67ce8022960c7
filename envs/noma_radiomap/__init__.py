"""noma_radiomap: NOMA indoor robots on a radio map (Gymnasium environment)."""

from noma_radiomap.env import NomaRadioMapEnv
from noma_radiomap.radiomap import RadioMap
from noma_radiomap.registration import make_env, register_envs
from noma_radiomap.scenario import Scenario, list_scenarios, load_scenario

__version__ = "0.1.0"

__all__ = ["NomaRadioMapEnv", "RadioMap", "Scenario", "list_scenarios", "load_scenario", "make_env", "register_envs"]

register_envs()
