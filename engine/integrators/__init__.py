"""Time integrators, one module each, behind one small interface.

Each module exposes ``LEVELS`` (the fidelity levels it integrates), ``ORDER`` (its convergence order, None
for exact or adaptive) and ``run(P, level, dt, n_steps, peaks, work, status)``, which integrates every
case ``c`` over ``n_steps[c]`` steps of ``dt[c]`` s, updates the running peaks and sets ``status[c]``
(0 done, 1 diverged, 3 failed) instead of raising.
"""

from isolab.engine.integrators import euler, exact, reference, rk4

INTEGRATORS = {"euler": euler, "rk4": rk4, "exact": exact, "reference": reference}
