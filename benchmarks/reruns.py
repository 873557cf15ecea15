"""The error estimate's reruns: what the sampled cases of a stored study cost.

Run: ``python -m benchmarks reruns [--repeat 5]``. Takes the 10,000-case LHS study of
``python -m benchmarks endtoend`` (``lti``/``exact``, 3 s at 1 ms), reruns its error sample
(``studies.run.error_estimate.error_sample``: 4 cases) as the estimate does on the service's two workers
(``sample_arrays`` of the 4 cases in one task: with the study's own model and at the reference level,
nonlinear with the adaptive reference integrator, one batch each) and as it did before, one task a case,
and prints the CPU time of each, and of the reference runs alone, median and best of ``--repeat`` passes
after one warm-up pass, with the load average beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

from benchmarks.endtoend import study_definition


def main(args: list[str]) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks reruns")
    parser.add_argument("--repeat", type=int, default=5)
    opts = parser.parse_args(args)

    from isolab.engine import simulate
    from isolab.studies.inputs.study import parse_study
    from isolab.studies.run.error_estimate import REFERENCE_PAIR, error_sample, sample_arrays

    study = parse_study(study_definition(10_000, "exact", 3.0))
    definition = json.dumps(study.model_dump(mode="json"))
    cases = error_sample(study)
    batches = [study.batch(np.array([c])) for c in cases]

    def together() -> None:
        sample_arrays(definition, cases, REFERENCE_PAIR)

    def one_by_one() -> None:
        for c in cases:
            sample_arrays(definition, c, REFERENCE_PAIR)

    def references() -> None:
        for b in batches:
            simulate(b, *REFERENCE_PAIR, dt=1e-3)

    print(f"error sample {cases}, load average {os.getloadavg()[0]:.2f} at the start")
    for name, run in (
        ("sample_arrays, 4 cases in one call (ours + reference)", together),
        ("sample_arrays, one call a case", one_by_one),
        ("reference runs alone, one a case", references),
    ):
        run()
        seconds = []
        for _ in range(opts.repeat):
            t0 = time.process_time()
            run()
            seconds.append(time.process_time() - t0)
        print(f"{name}: CPU median {statistics.median(seconds):.3f} s, best {min(seconds):.3f} s")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
