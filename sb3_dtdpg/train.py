"""
``python -m sb3_dtdpg.train``: the RL Zoo's ``train`` with DT-DPG registered.

Every zoo flag works as documented by rl_zoo3 (``--algo dtdpg --env NomaRadioMap-v0 -tb runs/``,
``--optimize --storage ... --study-name ...``, ``--trial-id``, ...), with one default changed: ``--num-threads``
is 1 unless given (``--num-threads -1``: torch's default). Without ``--conf-file`` the package's
own ``zoo_configs/<algo>.yml`` is used (:func:`sb3_dtdpg.zoo.default_config`). Needs the ``zoo`` extra
(``pip install -e ".[zoo]"`` in a clone of the repository).

A mistake in the hyperparameters (a file entry or a ``-params`` value: an unknown key such as ``learnin_rate``,
a ``net_arch`` too large to allocate) is one ``error:`` line with a did-you-mean and exit status 2, before
the zoo creates its log folder (:func:`sb3_dtdpg.overrides.check_constructor_kwargs`); so are zoo flags that
cannot run together (``--trial-id`` without ``--storage`` and ``--study-name``).
"""

import sys
from typing import Any

#: Keys of a zoo hyperparameter entry that the zoo itself reads (they never reach the model's constructor).
ZOO_KEYS = ("noise_type", "noise_std")
#: Constructor arguments the zoo sets from its own flags (a hyperparameter of the same name would be given twice).
ZOO_FLAGS = {"seed": "--seed", "verbose": "--verbose", "tensorboard_log": "--tensorboard-log", "device": "--device"}
#: The zoo's thread flag and this script's default for it: one torch thread, fastest for these small networks
#: (torch's own default, one thread per core, trains several times slower on a machine busy with other jobs).
THREADS_FLAG, DEFAULT_THREADS = "--num-threads", "1"


def with_default_threads(argv: list[str]) -> list[str]:
    """
    :param argv: the command-line arguments, without the program name
    :return: ``argv`` with ``--num-threads 1`` appended unless it sets the flag (in full, abbreviated or with ``=``)
    """
    for arg in argv:
        name = arg.split("=", 1)[0]
        if name.startswith("--nu") and THREADS_FLAG.startswith(name):  # argparse takes "--num-t" for the flag
            return argv
    return [*argv, THREADS_FLAG, DEFAULT_THREADS]


def _checked_manager(base: type) -> type:
    """The zoo's experiment manager, checking the model's keyword arguments before anything is created."""
    from sb3_dtdpg.overrides import HyperparameterError, check_constructor_kwargs

    class CheckedExperimentManager(base):  # type: ignore[misc, valid-type]
        def _preprocess_hyperparams(self, hyperparams: dict[str, Any]) -> tuple[Any, ...]:
            import rl_zoo3

            processed, *others = super()._preprocess_hyperparams(hyperparams)
            kwargs = {key: value for key, value in processed.items() if key != "policy"}
            where = f" (env {self.env_name.gym_id} in {self.config or 'the default config'}, or -params)"
            check_constructor_kwargs(rl_zoo3.ALGOS[self.algo], kwargs, where, extra=ZOO_KEYS, reserved=ZOO_FLAGS)
            self._check_env_kwargs(kwargs.get("phases"), where)
            return (processed, *others)

        def _check_env_kwargs(self, phases: Any, where: str) -> None:
            """Build the env once with the run's env_kwargs: a bad one, or phases of reward phases the env lacks, is an
            error line before the log folder exists."""
            import gymnasium as gym
            from stable_baselines3.common.vec_env import DummyVecEnv

            from sb3_dtdpg.common.phases import check_env_phases, parse_phases

            env_kwargs, eval_kwargs = self.env_kwargs or {}, self.eval_env_kwargs or {}
            for kwargs in (env_kwargs, eval_kwargs) if eval_kwargs != env_kwargs else (env_kwargs,):
                try:
                    env = DummyVecEnv([lambda kwargs=kwargs: gym.make(self.env_name.gym_id, **kwargs)])
                except (ValueError, TypeError) as error:
                    raise HyperparameterError(
                        f"env_kwargs {kwargs!r} (--env-kwargs, --eval-env-kwargs or the file): {error}"
                    ) from None
                try:
                    if phases is not None:
                        check_env_phases(parse_phases(phases), env)
                except ValueError as error:
                    raise HyperparameterError(f"phases{where}: {error}") from None
                finally:
                    env.close()

    return CheckedExperimentManager


def main() -> None:
    """Run the RL Zoo's training script with ``dtdpg`` among its algorithms."""
    try:
        from sb3_dtdpg.zoo import ExperimentManager, register_dtdpg  # first: its error names the extra to install
    except ModuleNotFoundError as error:
        sys.exit(f"python -m sb3_dtdpg.train: error: {error}")
    import rl_zoo3.train

    from sb3_dtdpg.overrides import HyperparameterError
    from sb3_dtdpg.zoo import ZooOptionError

    register_dtdpg()
    sys.argv[1:] = with_default_threads(sys.argv[1:])
    # rl_zoo3.train builds the experiment from its own module-level name: use the fixed manager.
    rl_zoo3.train.ExperimentManager = _checked_manager(ExperimentManager)  # type: ignore[misc]
    try:
        rl_zoo3.train.train()
    except (HyperparameterError, ZooOptionError) as error:
        print(f"python -m sb3_dtdpg.train: error: {error}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
