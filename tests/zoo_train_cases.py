"""
Run ``python -m sb3_dtdpg.train`` command lines one after the other in this one Python process, each in its own
folder, and write each one's exit status and standard error: the tests of its error lines pay for importing torch,
SB3 and the RL Zoo once instead of once per command line (about 4 s each).

Usage: ``python tests/zoo_train_cases.py CASES.json RESULTS.json``, with CASES a JSON list of ``{"cwd": folder,
"argv": [arguments]}``; RESULTS gets a list of ``{"returncode": int, "stderr": str}`` in the same order.
"""

import contextlib
import io
import json
import os
import sys
import traceback


def run_case(cwd: str, argv: list[str]) -> dict:
    """
    :param cwd: the folder to run the command line in
    :param argv: its arguments
    :return: its exit status and standard error, as the interpreter would end on them
    """
    from sb3_dtdpg.train import main

    os.chdir(cwd)
    sys.argv = ["sb3_dtdpg.train", *argv]
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
        try:
            main()
            status = 0
        except SystemExit as end:
            if end.code is None or isinstance(end.code, int):
                status = end.code or 0
            else:  # sys.exit("message"): printed, status 1
                print(end.code, file=sys.stderr)
                status = 1
        except BaseException:  # an uncaught exception: its traceback, status 1
            traceback.print_exc()
            status = 1
    return {"returncode": status, "stderr": stderr.getvalue()}


if __name__ == "__main__":
    cases_path, results_path = sys.argv[1:3]
    with open(cases_path) as file:
        cases = json.load(file)
    results = [run_case(case["cwd"], case["argv"]) for case in cases]
    with open(results_path, "w") as file:
        json.dump(results, file)
