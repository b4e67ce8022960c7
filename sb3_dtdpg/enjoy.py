"""
``python -m sb3_dtdpg.enjoy``: the RL Zoo's ``enjoy`` with DT-DPG registered, to watch or evaluate
a model trained with ``python -m sb3_dtdpg.train`` (``--algo dtdpg --env NomaRadioMap-v0 -f logs/``).
Needs the ``zoo`` extra.
"""

import sys
import traceback


def main() -> None:
    """Run the RL Zoo's enjoy script with ``dtdpg`` among its algorithms."""
    try:
        from sb3_dtdpg.zoo import register_dtdpg  # first: its error names the extra to install
    except ModuleNotFoundError as error:
        sys.exit(f"python -m sb3_dtdpg.enjoy: error: {error}")
    import rl_zoo3.enjoy

    register_dtdpg()
    try:
        rl_zoo3.enjoy.enjoy()
    except (AssertionError, ValueError) as error:
        # The zoo's own checks of the log folder and the model file (asserts among them) are the user's error
        if traceback.extract_tb(error.__traceback__)[-1].name != "get_model_path":
            raise
        print(f"python -m sb3_dtdpg.enjoy: error: {error}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
