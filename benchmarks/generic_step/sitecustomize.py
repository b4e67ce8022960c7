"""
Run ``sb3-dtdpg`` with SB3's generic training step: DT-DPG with ``lean=False`` and SB3's own ``DDPG`` as the
``ddpg`` baseline (in place of ``LeanDDPG``): the reference that the lean step matches bit for bit.

Python imports ``sitecustomize`` at start-up from its path, in every process (the job's spawned workers too), so
putting this folder first on ``PYTHONPATH`` switches a whole job, e.g. the paper-scale runs of docs/BENCHMARKS.md,
side by side with the same command without it::

    PYTHONPATH=benchmarks/generic_step sb3-dtdpg reproduce --budget paper --experiments ddpg_vs_dtdpg \\
        --n-seeds 1 --workers 1 --no-progress --out results/generic &
    sb3-dtdpg reproduce --budget paper --experiments ddpg_vs_dtdpg --n-seeds 1 --workers 1 --no-progress \\
        --out results/lean

The two give the same results (the runs' identities ignore the switch); only the training times differ.
"""

import functools

from stable_baselines3 import DDPG

from sb3_dtdpg import DTDPG, baselines

baselines._CLASSES["ddpg"] = DDPG
_lean_init = DTDPG.__init__


@functools.wraps(_lean_init)
def _generic_init(self, *args, **kwargs):
    kwargs["lean"] = False
    _lean_init(self, *args, **kwargs)


DTDPG.__init__ = _generic_init
