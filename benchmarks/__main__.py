"""``python -m benchmarks [pairs] ...``: run the benchmarks and print their figures."""

import sys

from benchmarks import kernels, pairs

COMMANDS = {"pairs": pairs.main, "kernels": kernels.main}

if __name__ == "__main__":
    args = sys.argv[1:]
    name = args[0] if args and args[0] in COMMANDS else "pairs"
    rest = args[1:] if args and args[0] in COMMANDS else args
    COMMANDS[name](rest)
