import os
import tempfile

import pytest
import torch as th

# Tiny networks on a small shared CI machine: one intra-op thread is several times faster than contended threads
th.set_num_threads(1)

# SB3 gives every learn() without a logger of its own an empty folder "SB3-<time>" in the temp directory; the suite
# calls learn() hundreds of times (and its spawned workers inherit this): one folder for the run, removed after it
_SB3_LOGDIR = tempfile.TemporaryDirectory(prefix="sb3-dtdpg-tests-")
os.environ.setdefault("SB3_LOGDIR", _SB3_LOGDIR.name)

#: Test modules with module fixtures that take many seconds to build (the planners' test missions, an Optuna study,
#: the RL Zoo's error runs). Under ``pytest -n N`` each of them runs on one worker, so its fixtures are built once,
#: not on every worker; xdist sends these first (its larger work units go first), the other tests one by one.
GROUPED_MODULES = ("tests/test_room.py", "tests/test_zoo.py", "tests/test_zoo_errors.py")

try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # pytest without xdist: no workers to group for
    pass
else:

    class _GroupedModulesScheduling(LoadScopeScheduling):
        """xdist's ``load`` distribution, but the tests of :data:`GROUPED_MODULES` go to one worker each."""

        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if module in GROUPED_MODULES else nodeid

    @pytest.hookimpl(optionalhook=True)  # pytest -p no:xdist has no such hook
    def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> LoadScopeScheduling | None:
        return _GroupedModulesScheduling(config, log) if config.getvalue("dist") == "load" else None
