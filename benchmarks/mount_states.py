"""``python -m benchmarks mount_states [cases]``: engine time per step of one case of the article scene
with and without mounts' internal states (an air mount's orifice as a Zener state: 4 states; an elastomer
ladder of 3 branches on 3 axes: 36 states), per fidelity/integrator pair that models them, warm kernels,
one batch, best of three."""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np
import yaml

from isolab.engine import simulate
from isolab.engine.scene import concat
from isolab.studies.inputs.study import scene_batch, validate_scene

EXAMPLE = Path(__file__).parents[1] / "studies" / "examples" / "article-scriber.yaml"
AIR = {
    "effective_area": "0.03 m^2",
    "volume": "20 l",
    "reservoir_volume": "40 l",
    "orifice": {"area": "2 mm^2", "length": "50 mm", "model": "zener"},
}
ELASTOMER = {"loss_factor": 0.1, "stiffening": 1.16, "f_low": "5 Hz", "f_high": "50 Hz"}
PAIRS = (("lti", "exact", 1e-3), ("lti", "rk4", 2e-4), ("ltv", "rk4", 2e-4))


def _batch(cases: int, **isolators: object):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["isolators"].update(copy.deepcopy(isolators))
    batch, _ = scene_batch(validate_scene(data))
    return concat([batch] * cases)


def per_step(batch, fidelity: str, integrator: str, dt: float) -> float:
    """Best of three engine times per step of one case, s."""
    simulate(batch.take([0]), fidelity, integrator, dt)  # compile or load the kernels
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        r = simulate(batch, fidelity, integrator, dt)
        best = min(best, time.perf_counter() - t0)
    steps = float(np.sum(np.asarray(batch.duration) / np.asarray(r.dt)))
    return best / steps


def main(args: list[str]) -> None:
    cases = int(args[0]) if args else 16
    variants = {
        "plain air": _batch(cases),
        "air, orifice zener (4 states)": _batch(cases, air=AIR),
        "elastomer": _batch(cases, preset="elastomer"),
        "elastomer ladder (36 states)": _batch(cases, preset="elastomer", elastomer=ELASTOMER),
    }
    print(f"engine time per step of one case, ns ({cases} cases per batch, best of 3)")
    print(f"{'scene':34s}" + "".join(f"{f + '/' + i:>14s}" for f, i, _ in PAIRS))
    for name, batch in variants.items():
        row = [per_step(batch, f, i, dt) * 1e9 for f, i, dt in PAIRS]
        print(f"{name:34s}" + "".join(f"{v:14.0f}" for v in row))
