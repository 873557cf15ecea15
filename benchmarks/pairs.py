"""Time per case and error of every fidelity/integrator pair on a scene, against the nonlinear reference.

Run: ``python -m benchmarks pairs [SCENE] [--dt 0.001] [--cases 100]``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from isolab.engine import concat, simulate
from isolab.studies.inputs.study import load_scene, scene_batch

EXAMPLE = Path(__file__).resolve().parent.parent / "studies" / "examples" / "article-scriber.yaml"
PAIRS = [
    ("lti", "exact"),
    ("lti", "rk4"),
    ("lti", "euler"),
    ("ltv", "rk4"),
    ("ltv", "euler"),
    ("nonlinear", "rk4"),
    ("nonlinear", "euler"),
    ("lti", "reference"),
    ("ltv", "reference"),
    ("nonlinear", "reference"),
]


def measure(scene_path: Path = EXAMPLE, dt: float = 1e-3, cases: int = 100) -> list[dict]:
    """Per pair: seconds per case (batched ``cases`` copies; the reference runs one case) and the relative
    error of peak Y displacement, peak isolator force and settling time against nonlinear/reference."""
    sc = load_scene(scene_path)
    one, _ = scene_batch(sc)
    many = concat([one] * cases)
    ref = simulate(one, "nonlinear", "reference", dt)
    rows = []
    for fid, integ in PAIRS:
        b = one if integ == "reference" else many
        simulate(one, fid, integ, dt)  # compile / warm caches
        t0 = time.perf_counter()
        r = simulate(b, fid, integ, dt)
        per_case = (time.perf_counter() - t0) / b.n_cases

        def rel(a, b_):
            return float(np.max(np.abs(a - b_)) / np.max(np.abs(b_)))

        rows.append(
            {
                "fidelity": fid,
                "integrator": integ,
                "dt": dt,
                "seconds_per_case": per_case,
                "err_peak_y": rel(r.peak_displacement[0, 1], ref.peak_displacement[0, 1]),
                "err_peak_force": rel(r.peak_isolator_force[0], ref.peak_isolator_force[0]),
                "err_settling": abs(float(r.settling_time[0] - ref.settling_time[0])),
                "status": int(r.status[0]),
            }
        )
    return rows


def main(argv: list[str]) -> None:
    import argparse

    p = argparse.ArgumentParser(prog="python -m benchmarks pairs")
    p.add_argument("scene", nargs="?", default=str(EXAMPLE))
    p.add_argument("--dt", type=float, default=1e-3)
    p.add_argument("--cases", type=int, default=100)
    a = p.parse_args(argv)
    rows = measure(Path(a.scene), a.dt, a.cases)
    print(f"scene {a.scene}, dt {a.dt} s; errors against nonlinear/reference (DOP853, rtol 1e-10)")
    print(
        f"{'fidelity':10s} {'integrator':10s} {'ms/case':>9s} {'cases/s':>9s} {'err peak y':>11s} "
        f"{'err force':>10s} {'err settle s':>12s}"
    )
    for r in rows:
        print(
            f"{r['fidelity']:10s} {r['integrator']:10s} {r['seconds_per_case'] * 1e3:9.3f} "
            f"{1 / r['seconds_per_case']:9.1f} {r['err_peak_y']:11.2e} {r['err_peak_force']:10.2e} "
            f"{r['err_settling']:12.3e}"
        )
