"""
``python -m sb3_dtdpg.enjoy``: the RL Zoo's ``enjoy`` with DT-DPG registered, to watch or evaluate
a model trained with ``python -m sb3_dtdpg.train`` (``--algo dtdpg --env NomaRadioMap-v0 -f logs/``).
Needs the ``zoo`` extra.
"""

import sys


def main() -> None:
    """Run the RL Zoo's enjoy script with ``dtdpg`` among its algorithms."""
    try:
        from sb3_dtdpg.zoo import register_dtdpg  # first: its error names the extra to install
    except ModuleNotFoundError as error:
        sys.exit(f"python -m sb3_dtdpg.enjoy: error: {error}")
    import rl_zoo3.enjoy

    register_dtdpg()
    rl_zoo3.enjoy.enjoy()


if __name__ == "__main__":
    main()
