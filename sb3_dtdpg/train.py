"""
``python -m sb3_dtdpg.train``: the RL Zoo's ``train`` with DT-DPG registered.

Every zoo flag works as documented by rl_zoo3 (``--algo dtdpg --env NomaRadioMap-v0 -tb runs/``,
``--optimize --storage ... --study-name ...``, ``--trial-id``, ...). Without ``--conf-file`` the package's
own ``zoo_configs/<algo>.yml`` is used (:func:`sb3_dtdpg.zoo.default_config`). Needs the ``zoo`` extra.
"""

import sys


def main() -> None:
    """Run the RL Zoo's training script with ``dtdpg`` among its algorithms."""
    try:
        from sb3_dtdpg.zoo import ExperimentManager, register_dtdpg  # first: its error names the extra to install
    except ModuleNotFoundError as error:
        sys.exit(f"python -m sb3_dtdpg.train: error: {error}")
    import rl_zoo3.train

    register_dtdpg()
    # rl_zoo3.train builds the experiment from its own module-level name: use the fixed manager.
    rl_zoo3.train.ExperimentManager = ExperimentManager  # type: ignore[misc]
    rl_zoo3.train.train()


if __name__ == "__main__":
    main()
