"""`benchmarks/generic_step`: a job started with it on PYTHONPATH trains with SB3's generic step (DT-DPG
``lean=False``, SB3's own DDPG), the same runs as without it (the same identities), so timings compare like for
like."""

import json
import os
import subprocess
import sys
from pathlib import Path

HOOK = Path(__file__).resolve().parents[1] / "benchmarks" / "generic_step"

PROBE = """
import json
from sb3_dtdpg.baselines import make_env, make_model
from sb3_dtdpg.experiments.runs import RunSpec, prepare_run
from sb3_dtdpg.experiments.specs import identity_digest

models = {algo: make_model(algo, make_env(algo, env_kwargs={"scenario": "small"})) for algo in ("dtdpg", "ddpg")}
specs = [RunSpec(algo, "noma", 0, 40, scenario="small", hyperparams="tuned") for algo in ("dtdpg", "ddpg")]
print(json.dumps({
    "dtdpg_lean": models["dtdpg"].lean,
    "ddpg_class": type(models["ddpg"]).__module__ + "." + type(models["ddpg"]).__name__,
    "digests": [identity_digest(prepare_run(spec)) for spec in specs],
}, sort_keys=True, default=str))
"""


def _probe(hooked: bool) -> dict:
    env = dict(os.environ)
    if hooked:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(HOOK), env.get("PYTHONPATH")]))
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_generic_step_hook_switches_both_algorithms_and_keeps_the_runs_identities():
    lean, generic = _probe(hooked=False), _probe(hooked=True)
    assert lean["dtdpg_lean"] is True and lean["ddpg_class"] == "sb3_dtdpg.dtdpg.lean.LeanDDPG"
    assert generic["dtdpg_lean"] is False and generic["ddpg_class"] == "stable_baselines3.ddpg.ddpg.DDPG"
    assert generic["digests"] == lean["digests"]  # the same runs, as stored results are compared
