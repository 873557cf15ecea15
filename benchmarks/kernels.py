"""Kernel throughput on the article scene (5 s at 1 ms), against a numpy time loop and scipy's RK45.

Run: ``python -m benchmarks kernels [--big 10000] [--repeat 3]``. Prints time per case and cases per second
on one core for each fidelity/integrator pair, single case and batched, the speed-up of the batched
``lti``/``exact`` path over the alternatives at equal accuracy, and the fraction of a floating-point bound
the kernel reaches.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from benchmarks import pairs
from benchmarks.pairs import EXAMPLE
from isolab.engine import concat, simulate
from isolab.engine import model as engine_model
from isolab.engine.integrators import exact
from isolab.studies.inputs.study import load_scene, scene_batch

DURATION = 5.0
DT = 1e-3
TARGET_NS = {("lti", "exact"): 150, ("ltv", "rk4"): 800, ("nonlinear", "rk4"): 800}
"""Targets, ns per step per case on the largest batch."""
PAIRS = [pair for pair in pairs.PAIRS if pair[1] != "reference"]
"""The fixed-step pairs of ``benchmarks.pairs`` (the reference is timed against, not as a kernel)."""


def article_batch():
    """The article scene cut to 5 s, one case."""
    batch, _ = scene_batch(load_scene(EXAMPLE))
    batch.duration[:] = DURATION
    return batch


def _best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def lti_forcing_numpy(P, t: np.ndarray) -> np.ndarray:
    """The LTI level's generalised force (T, 6) for case 0 at times ``t`` (s), in numpy."""
    m = P.sm.shape[1]
    T = t.size
    rho = np.zeros((m, T, 3))
    vr = np.zeros((m, T, 3))
    ar = np.zeros((m, T, 3))
    for i in range(m):
        pt = P.pt[0, i]
        k = np.clip(np.searchsorted(pt, t, side="right") - 1, 0, None)
        before = t < pt[0]
        tau = t - pt[k]
        j = P.pj[0, i, k]
        a = np.where(before, 0.0, P.pa[0, i, k] + j * tau)
        s = np.where(
            before,
            P.ps[0, i, 0],
            P.ps[0, i, k] + (P.pv[0, i, k] + (0.5 * P.pa[0, i, k] + j * tau / 6) * tau) * tau,
        )
        rho[i] = P.rho_h[0, i] + s[:, None] * P.e[0, i]
        ar[i] = a[:, None] * P.e[0, i]
        p = P.parent[i]
        if p >= 0:
            rho[i] += rho[p] - P.rho_h[0, p]
            ar[i] += ar[p]
        _ = vr
    f = np.zeros((T, 6))
    g = np.array([0.0, 0.0, -P.g])
    for i in range(m):
        mi = P.sm[0, i]
        f[:, :3] -= mi * ar[i]
        f[:, 3:] += -mi * np.cross(rho[i], ar[i]) + mi * np.cross(rho[i] - P.rho_h[0, i], g)
    return f


def _lti_system(P) -> tuple[np.ndarray, np.ndarray]:
    """State matrix (12, 12), 1/s, and inverse mass matrix (6, 6) of case 0 on the LTI level."""
    A = np.zeros((12, 12))
    A[:6, 6:] = np.eye(6)
    A[6:, :6] = P.a21[0]
    A[6:, 6:] = P.a22[0]
    return A, P.minv[0]


def numpy_loop(P, n_steps: int) -> float:
    """Peak |Y| of case 0 by RK4 on the LTI level, written as a plain numpy time loop (m)."""
    A, Minv = _lti_system(P)
    h = DT
    t = np.arange(n_steps + 1) * h
    half = t + 0.5 * h
    f0 = lti_forcing_numpy(P, t)
    fh = lti_forcing_numpy(P, half)
    x = np.zeros(12)
    peak = 0.0
    for k in range(n_steps):
        b0 = np.concatenate([np.zeros(6), Minv @ f0[k]])
        bh = np.concatenate([np.zeros(6), Minv @ fh[k]])
        b1 = np.concatenate([np.zeros(6), Minv @ f0[k + 1]])
        k1 = A @ x + b0
        k2 = A @ (x + 0.5 * h * k1) + bh
        k3 = A @ (x + 0.5 * h * k2) + bh
        k4 = A @ (x + h * k3) + b1
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        peak = max(peak, abs(x[1]))
    return peak


def rk45(P, rtol: float) -> float:
    """Peak |Y| of case 0 on the LTI level by scipy's RK45 at ``rtol``, sampled every DT (m)."""
    A, Minv = _lti_system(P)

    def rhs(t, x):
        f = lti_forcing_numpy(P, np.array([t]))[0]
        out = A @ x
        out[6:] += Minv @ f
        return out

    grid = np.arange(int(round(DURATION / DT)) + 1) * DT
    sol = solve_ivp(
        rhs, (0.0, DURATION), np.zeros(12), method="RK45", rtol=rtol, atol=rtol * 1e-3, t_eval=grid
    )
    return float(np.abs(sol.y[1]).max())


def cpu_mhz() -> float:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("cpu mhz"):
                return float(line.split(":")[1])
    except OSError:
        pass
    return float("nan")


def exact_flops_per_step(P) -> int:
    """Floating-point operations per step of the exact path's whole step inside a piece: the state update
    ``x <- Phi x + R_0`` (2 per multiply-add, ``exact.free_step``), the Taylor shift that carries the forced
    response ``R`` (12 (deg + 1)) to the next step, and the peaks (the forcing and its response are rebuilt
    only where a profile piece begins: not counted)."""
    _, deg, _ = exact.augmented(P)
    n, p = P.d.shape[1], P.pts.shape[1]
    update = 2 * 12 * 12 + 12
    shift = 12 * deg * (deg + 1)
    peaks = 30 + p * 30 + n * 40
    return update + shift + peaks


def main(argv: list[str]) -> None:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m benchmarks kernels")
    ap.add_argument("--big", type=int, default=10_000, help="cases in the large batch of lti/exact")
    ap.add_argument("--others", type=int, default=10_000, help="cases in the large batch of the other pairs")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    one = article_batch()
    n_steps = int(round(DURATION / DT))
    print(f"article scene, {DURATION} s at {DT * 1e3:g} ms ({n_steps} steps), one core; median of {a.repeat}")
    print(
        f"{'fidelity':10s} {'integrator':10s} {'cases':>6s} {'ms/case':>9s} {'cases/s':>9s} {'ns/step':>8s}"
    )
    per_case = {}
    ns_step = {}
    for fid, integ in PAIRS:
        simulate(one, fid, integ, DT)  # compile, warm up
        for n in (1, 100, a.big if (fid, integ) == ("lti", "exact") else a.others):
            b = concat([one] * n)
            t = _best(
                lambda b=b, fid=fid, integ=integ: simulate(b, fid, integ, DT), a.repeat if n <= 100 else 1
            )
            per_case[(fid, integ, n)] = t / n
            ns_step[(fid, integ)] = t / n / n_steps * 1e9
            print(
                f"{fid:10s} {integ:10s} {n:6d} {t / n * 1e3:9.3f} {n / t:9.1f} {t / n / n_steps * 1e9:8.0f}"
            )
    # alternatives at equal accuracy, on the LTI level
    P = engine_model.params(one)
    ref = simulate(one, "lti", "reference", DT).peak_displacement[0, 1]
    eng = simulate(one, "lti", "exact", DT).peak_displacement[0, 1]
    err_engine = abs(eng - ref) / ref
    t_np = _best(lambda: numpy_loop(P, n_steps), 1)
    err_np = abs(numpy_loop(P, n_steps) - ref) / ref
    chosen = None
    for rtol in (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11):
        err = abs(rk45(P, rtol) - ref) / ref
        if err <= max(err_engine, 1e-12) * 10 or rtol == 1e-11:
            chosen = (rtol, err)
            break
    t_ivp = _best(lambda: rk45(P, chosen[0]), 1)
    batched = per_case[("lti", "exact", a.big)]
    print()
    print(
        f"peak Y error against the LTI reference: engine lti/exact {err_engine:.1e}, numpy RK4 loop {err_np:.1e}, "
        f"solve_ivp RK45 {chosen[1]:.1e} at rtol {chosen[0]:g}"
    )
    print(
        f"numpy time loop (RK4, one case):  {t_np * 1e3:9.1f} ms/case   batched exact is {t_np / batched:7.0f}x faster"
    )
    print(
        f"scipy solve_ivp RK45 (one case):  {t_ivp * 1e3:9.1f} ms/case   batched exact is {t_ivp / batched:7.0f}x faster"
    )
    print()
    print("targets (largest batch of each pair):")
    for (fid, integ), limit in TARGET_NS.items():
        got = ns_step[(fid, integ)]
        print(
            f"  {fid}/{integ}: {got:6.0f} ns/step  (target <= {limit} ns: {'met' if got <= limit else 'MISSED'})"
        )
    for what, got, want in (("numpy loop", t_np / batched, 50), ("solve_ivp", t_ivp / batched, 200)):
        print(
            f"  batched exact vs {what}: {got:6.0f}x  (target >= {want}x: {'met' if got >= want else 'MISSED'})"
        )
    flops = exact_flops_per_step(P)
    mhz = cpu_mhz()
    achieved = flops * n_steps / batched
    bound = 2.0 * mhz * 1e6  # one multiply-add per cycle
    print(
        f"exact path: about {flops} floating-point operations per step; {achieved / 1e9:.2f} GFLOP/s achieved, "
        f"{achieved / bound * 100:.0f} % of one multiply-add per cycle at {mhz:.0f} MHz "
        f"(within {bound / achieved:.1f}x of that bound)"
    )
    vector = 8 * bound  # eight double multiply-adds a cycle: one AVX-512 FMA (or two AVX2 FMAs)
    print(
        f"  against eight multiply-adds a cycle (the vector units' peak): {flops / (vector / 1e9):.0f} ns/step "
        f"would be the limit; the kernel reaches {achieved / vector * 100:.0f} % of it"
    )
