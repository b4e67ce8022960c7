"""
``python -m sb3_dtdpg.enjoy``: the RL Zoo's ``enjoy`` with DT-DPG registered, to watch or evaluate
a model trained with ``python -m sb3_dtdpg.train`` (``--algo dtdpg --env NomaRadioMap-v0 -f logs/``).
Needs the ``zoo`` extra.

A model is refused on an env built with other settings than it was trained with (scenario, observation, downlink
mode, e.g. through ``--env-kwargs``), as ``sb3-dtdpg enjoy`` refuses it (:func:`sb3_dtdpg.env_settings.check_settings`):
one error line, exit status 2; so is an env that cannot be built with the run's env_kwargs (an unknown keyword or
value, e.g. ``--env-kwargs scenario:"'nosuch'"``).
"""

from __future__ import annotations

import contextlib
import sys
import traceback
import warnings
from collections.abc import Iterator
from types import ModuleType
from typing import Any, NoReturn


class _SettingsCheckedAlgo:
    """
    An algorithm class as the zoo's enjoy uses it (``ALGOS[algo].load(path, ...)``): the loaded model's recorded env
    settings are checked against the env the zoo built for it.

    :param algo_class: the SB3 algorithm class
    :param envs: the envs the zoo built so far (the last is the one the model runs on)
    """

    def __init__(self, algo_class: type, envs: list[Any]) -> None:
        self.algo_class, self.envs = algo_class, envs

    def __getattr__(self, name: str) -> Any:
        return getattr(self.algo_class, name)

    def load(self, path: Any, *args: Any, **kwargs: Any) -> Any:
        """
        The class's ``load``, then :func:`~sb3_dtdpg.env_settings.check_settings` of the model's recorded settings.

        :raises sb3_dtdpg.env_settings.EnvSettingsMismatch: the env has other settings (the env is closed)
        """
        from sb3_dtdpg.env_settings import EnvSettingsMismatch, check_settings

        model = self.algo_class.load(path, *args, **kwargs)
        if not self.envs:  # this rl_zoo3 builds its env elsewhere: say that the settings went unchecked
            warnings.warn(f"the model {path}: its env settings could not be checked with this rl_zoo3 version", stacklevel=2)
        else:
            try:
                check_settings(getattr(model, "env_settings", None), self.envs[-1], f"the model {path}")
            except EnvSettingsMismatch:
                self.envs[-1].close()
                raise
        return model


class _EnvKwargsError(Exception):
    """The zoo's enjoy could not build the env with its env_kwargs (``main`` prints it as one error line)."""


@contextlib.contextmanager
def _checking_env_settings(zoo_enjoy: ModuleType) -> Iterator[None]:
    """
    Within it, the zoo's ``enjoy()`` refuses a model on an env of other settings. The zoo builds the env
    (``create_test_env``), then loads the model without it; both are wrapped in ``zoo_enjoy`` (the module
    ``rl_zoo3.enjoy``) to keep the env and check the model against it, and restored on leaving.

    :param zoo_enjoy: the module ``rl_zoo3.enjoy``
    """
    envs: list[Any] = []
    create_test_env, algos = zoo_enjoy.create_test_env, zoo_enjoy.ALGOS

    def create_and_keep(env_id: str, *args: Any, **kwargs: Any) -> Any:
        try:
            envs.append(create_test_env(env_id, *args, **kwargs))
        except (ValueError, TypeError) as error:  # an env_kwargs value or keyword the env does not take
            env_kwargs = kwargs.get("env_kwargs")
            where = "--env-kwargs or the run's args.yml"
            raise _EnvKwargsError(f"env {env_id} with env_kwargs {env_kwargs!r} ({where}): {error}") from None
        return envs[-1]

    zoo_enjoy.create_test_env = create_and_keep
    zoo_enjoy.ALGOS = {name: _SettingsCheckedAlgo(algo_class, envs) for name, algo_class in algos.items()}
    try:
        yield
    finally:
        zoo_enjoy.create_test_env, zoo_enjoy.ALGOS = create_test_env, algos


def main() -> None:
    """Run the RL Zoo's enjoy script with ``dtdpg`` among its algorithms."""
    try:
        from sb3_dtdpg.zoo import register_dtdpg  # first: its error names the extra to install
    except ModuleNotFoundError as error:
        sys.exit(f"python -m sb3_dtdpg.enjoy: error: {error}")
    import rl_zoo3.enjoy

    from sb3_dtdpg.env_settings import EnvSettingsMismatch

    register_dtdpg()
    try:
        with _checking_env_settings(rl_zoo3.enjoy):
            rl_zoo3.enjoy.enjoy()
    except (EnvSettingsMismatch, _EnvKwargsError) as error:
        _user_error(error)
    except (AssertionError, ValueError) as error:
        # The zoo's own checks of the log folder and the model file (asserts among them) are the user's error
        if traceback.extract_tb(error.__traceback__)[-1].name != "get_model_path":
            raise
        _user_error(error)


def _user_error(error: Exception) -> NoReturn:
    """Print ``error`` as one error line and exit with status 2 (argparse's for a usage error)."""
    print(f"python -m sb3_dtdpg.enjoy: error: {error}", file=sys.stderr)
    sys.exit(2)


if __name__ == "__main__":
    main()
