import os
import tempfile

import torch as th

# Tiny networks on a small shared CI machine: one intra-op thread is several times faster than contended threads
th.set_num_threads(1)

# SB3 gives every learn() without a logger of its own an empty folder "SB3-<time>" in the temp directory; the suite
# calls learn() hundreds of times (and its spawned workers inherit this): one folder for the run, removed after it
_SB3_LOGDIR = tempfile.TemporaryDirectory(prefix="sb3-dtdpg-tests-")
os.environ.setdefault("SB3_LOGDIR", _SB3_LOGDIR.name)
