"""
``python -m sb3_dtdpg.train``: the RL Zoo's ``train`` with DT-DPG registered.

Every zoo flag works as documented by rl_zoo3 (``--algo dtdpg --env NomaRadioMap-v0 --conf-file
zoo_configs/dtdpg.yml -tb runs/``, ``--optimize --storage ... --study-name ...``, ``--trial-id``, ...).
"""

import rl_zoo3.train

from sb3_dtdpg.zoo import ExperimentManager, register_dtdpg


def main() -> None:
    """Run the RL Zoo's training script with ``dtdpg`` among its algorithms."""
    register_dtdpg()
    # rl_zoo3.train builds the experiment from its own module-level name: use the fixed manager.
    rl_zoo3.train.ExperimentManager = ExperimentManager  # type: ignore[misc]
    rl_zoo3.train.train()


if __name__ == "__main__":
    main()
