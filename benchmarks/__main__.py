"""``python -m benchmarks [pairs|kernels|accuracy|endtoend|million|first_study|startup|mount_states|reruns] ...``: run the benchmarks and print their figures."""

import sys

from benchmarks import (
    accuracy,
    endtoend,
    first_study,
    kernels,
    million,
    mount_states,
    pairs,
    reruns,
    startup,
)

COMMANDS = {
    "pairs": pairs.main,
    "kernels": kernels.main,
    "accuracy": accuracy.main,
    "endtoend": endtoend.main,
    "million": million.main,
    "first_study": first_study.main,
    "startup": startup.main,
    "mount_states": mount_states.main,
    "reruns": reruns.main,
}

if __name__ == "__main__":
    args = sys.argv[1:]
    name = args[0] if args and args[0] in COMMANDS else "pairs"
    rest = args[1:] if args and args[0] in COMMANDS else args
    COMMANDS[name](rest)
