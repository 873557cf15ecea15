"""The kernels' inputs: the fidelity levels' codes and a batch's parameters as one named tuple of arrays.

The kernels work on three named tuples of arrays: ``Params`` (a batch's parameters, filled from a
``SceneBatch`` by ``engine.model.params``), ``Work`` (one case's scratch, ``engine.model.work``) and the
running peaks ``engine.kernels.peaks.Peaks``; they take them as structs (``engine.kernels.structs``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numba.core import types
from numba.extending import intrinsic

LTI, LTV, NONLINEAR = 0, 1, 2
"""Codes of the fidelity levels inside the kernels."""
FIDELITIES = {"lti": LTI, "ltv": LTV, "nonlinear": NONLINEAR}
"""The fidelity levels by name."""


class Params(NamedTuple):
    """A batch's parameters, case dimension first (``C`` cases, ``n`` isolators, ``m`` stages, ``K``
    profile pieces, ``p`` points of interest, ``F`` recorded floor samples, ``B`` feedforward stretches);
    lengths relative to the machine c.g., in the floor frame at the reference state."""

    mass: np.ndarray
    """(C,) the base's mass without the stages, kg."""
    mtot: np.ndarray
    """(C,) the mass of base and stages, kg."""
    inertia: np.ndarray
    """(C, 3, 3) the base's inertia tensor about its c.g., kg m^2."""
    d: np.ndarray
    """(C, n, 3) the isolators' lever arms, m."""
    k: np.ndarray
    """(C, n, 3) the isolators' stiffness along floor X, Y, Z, N/m."""
    cd: np.ndarray
    """(C, n, 3) the isolators' damping, N s/m."""
    sky: np.ndarray
    """(C, n) 1 where a mount's damper acts on the absolute velocity (sky-hook), else 0."""
    f0: np.ndarray
    """(C, n) the static vertical preload, N."""
    sm: np.ndarray
    """(C, m) the stages' masses, kg."""
    rho_h: np.ndarray
    """(C, m, 3) the stages' homes, m."""
    e: np.ndarray
    """(C, m, 3) the stages' unit travel axes (fixed in the machine)."""
    parent: np.ndarray
    """(m,) int64: the stage each stage rides on, -1 for the machine."""
    pt: np.ndarray
    """(C, m, K) the profile pieces' start times, s."""
    ps: np.ndarray
    """(C, m, K) the position at each piece's start, m."""
    pv: np.ndarray
    """(C, m, K) the velocity at each piece's start, m/s."""
    pa: np.ndarray
    """(C, m, K) the acceleration at each piece's start, m/s^2."""
    pj: np.ndarray
    """(C, m, K) each piece's constant jerk, m/s^3."""
    pts: np.ndarray
    """(C, p, 3) the points of interest, m."""
    famp: np.ndarray
    """(C, 3) the sine floor motion's amplitude per axis, m."""
    fomega: np.ndarray
    """(C, 3) its angular frequency, rad/s."""
    fphase: np.ndarray
    """(C, 3) its phase, rad."""
    ft: np.ndarray
    """(F,) the recorded floor motion's sample times, s."""
    fd: np.ndarray
    """(C, 3, F) the recorded floor displacement per axis, m."""
    a21: np.ndarray
    """(C, 6, 6) ``-M^-1 K`` of the linear model with the stages at home, 1/s^2."""
    a22: np.ndarray
    """(C, 6, 6) ``-M^-1 C``, 1/s."""
    minv: np.ndarray
    """(C, 6, 6) the inverse mass matrix with the stages at home (1/kg, 1/(kg m), 1/(kg m^2))."""
    g: float
    """Gravity, m/s^2."""
    gstiff: bool
    """The linear levels include the rocking stiffness of the weights that tilt with the base."""
    ffon: bool
    """Some mount feeds the stages' wrench forward (and there is a stage)."""
    ffg: np.ndarray
    """(C, n) each mount's feedforward gain (0: none)."""
    ffw: np.ndarray
    """(C, n) its low-pass corner, rad/s."""
    fflim: np.ndarray
    """(C, n) its actuator's force limit per axis, N."""
    ffD: np.ndarray
    """(C, n, 3, 6) its share of a wrench ``[F, M]``: actuator force (N) per N and per N m."""
    fftb: np.ndarray
    """(C, B) the start times of the stretches between the profiles' breakpoints, s, padded with +inf."""
    ffA: np.ndarray
    """(C, n, B, 6) the low-pass's free-response amplitude per mount and stretch, N and N m
    (``engine.kernels.feedforward.feedforward_transients``)."""
    ffwt: np.ndarray
    """(C, n) 1 where a mount also feeds the change of the stages' weight moment forward, else 0."""
    pbase: int
    """The nonlinear level's preload convention: 0 vertical in the floor frame, 1 turning with the base,
    2 balancing the weights with the stages at home in every attitude (``engine.kernels.cached_terms``
    ``CC_V``)."""
    orient: bool
    """Some mount acts along its own axes (``qm``), not the floor's."""
    qm: np.ndarray
    """(C, n, 3, 3) each mount's own axes in the floor frame (columns); ``k``, ``cd`` act along them."""
    zA: np.ndarray
    """(C, nz, nz) the extra linear states' own matrix (``z' = zA z + zX x + zQ acc + zS s''``), 1/s; nz = 0
    (the default) when the scene has none (``engine.model.linear_slot``)."""
    zX: np.ndarray
    """(C, nz, 12) ``z'`` per unit base state ``[u, theta, v, w]``."""
    zQ: np.ndarray
    """(C, nz, 6) ``z'`` per unit base acceleration ``[a, alpha]``."""
    zS: np.ndarray
    """(C, nz, m) ``z'`` per unit stage acceleration along its own axis (m/s^2; the known forcing)."""
    zG: np.ndarray
    """(C, 6, nz) the base's generalised force per unit ``z`` (N, N m)."""
    zM: np.ndarray
    """(C, 6, nz) the LTI level's accelerations per unit ``z``: ``minv @ zG``."""
    sM: np.ndarray
    """(C, 6, m) the LTI level's accelerations per unit stage acceleration beyond the stages' own forcing
    (a servo stage's inertial force taken off the base); (C, 6, 0) when no model needs it."""
    zO: np.ndarray
    """(C, 2, nz, 3 p + 3 n) what ``z`` adds to each point's displacement and each mount's deflection
    (row 0, m per unit) and to their rates (row 1, m/s per unit ``z``)."""
    zF: np.ndarray
    """(C, nz, 3 n) what ``z`` adds to each mount's force on the base, by axis of the floor frame (N per unit
    ``z``): a relaxation branch's spring, a levelling valve's share (``SlotBlock.F``)."""
    zdb: np.ndarray
    """(C, nz) each extra linear state's dead band on its rate (its units per second; 0: the row is linear):
    a levelling valve's ``(k_v / tau) d`` (``engine.linear_states.block.SlotBlock.D``)."""
    pr: np.ndarray
    """(C, p) 1 for a material point of the base (it moves by ``u + theta x d``), 0 for a relative point
    or a following error (only ``zO`` moves it; ``pts`` is zero there)."""


class Work(NamedTuple):
    """Scratch arrays for one case at a time (``m`` stages, ``n`` isolators, ``K`` profile pieces). They keep
    terms of the ``Params`` they serve (packed per case, per time: ``engine.kernels.cached_terms``), so one
    ``Work`` serves one ``Params``."""

    rho: np.ndarray
    """(m, 3) the stages' positions relative to the c.g., m (``engine.kernels.excitation.stage_state``)."""
    vr: np.ndarray
    """(m, 3) their velocities relative to the machine, m/s."""
    ar: np.ndarray
    """(m, 3) their relative accelerations, m/s^2."""
    jr: np.ndarray
    """(m, 3) their relative jerks, m/s^3."""
    xf: np.ndarray
    """(3,) the floor's displacement, m."""
    vf: np.ndarray
    """(3,) the floor's velocity, m/s."""
    acc: np.ndarray
    """(6,) the base's accelerations, m/s^2 and rad/s^2 (the rotation, rad, while the peaks are observed)."""
    f: np.ndarray
    """(6,) the LTI level's generalised force, N and N m."""
    R: np.ndarray
    """(3, 3) the base's rotation matrix, body to floor."""
    F: np.ndarray
    """(n, 3) the isolators' dynamic forces, N."""
    Fa: np.ndarray
    """(n, 3) the feedforward actuators' forces, N."""
    ffx: np.ndarray
    """(8, 6) the stages' reversed inertial wrench and weight moment, with their time derivatives
    (``engine.kernels.feedforward.stage_wrench``)."""
    ffy: np.ndarray
    """(6,) the low-passed wrench, N and N m."""
    ffs: np.ndarray
    """(24,) the exact integrator's feedforward ramp and the forcing it saves."""
    key: np.ndarray
    """(4 + m,) the key of the time-only terms in ``tc``: case, level, time, mass matrix positive definite,
    pieces (case -1: none yet)."""
    tc: np.ndarray
    """(21, 3) the time-only terms (``engine.kernels.cached_terms``)."""
    cc: np.ndarray
    """(22,) the packed case: its index first (-1: none yet)."""
    cs: np.ndarray
    """(m, 8 + 5 K) the packed stages."""
    cm: np.ndarray
    """(n, 11) the packed mounts; (n, 20) when some mount has its own axes (``Params.qm``, row-major)."""
    cK: np.ndarray
    """(12, 6) the LTV level's mount operator: the mounts' generalised force per unit state."""
    sw: np.ndarray
    """(m, 9) the stages' positions, velocities and accelerations relative to the c.g."""


def _view_without_owner(typingctx: Any, array: types.Array) -> Any:
    """``borrowed(array)``: a view of ``array`` (any numba array) whose references numba does not count,
    for a kernel's hot loop: the same data, shape and strides, no owner. Numba counts a reference (an atomic
    add and subtract, dearer than the arithmetic of a small kernel) at every binding of an array, every
    slice and every call that passes one, and drops a pair only where no other release lies between; on a
    view without owner it drops them all. The view must not outlive the call that made it (the caller's
    array keeps the memory alive)."""
    if not isinstance(array, types.Array):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        src = context.make_array(array)(context, builder, value=args[0])
        out = context.make_array(array)(context, builder)
        for name in ("nitems", "itemsize", "data", "shape", "strides"):
            setattr(out, name, getattr(src, name))
        out.meminfo = context.get_constant_null(types.MemInfoPointer(array.dtype))
        out.parent = context.get_constant_null(types.pyobject)
        return out._getvalue()

    return array(array), codegen


borrowed: Any = intrinsic(_view_without_owner)
"""A view of a numba array whose references are not counted (:func:`_view_without_owner`); kernels only."""


CACHE_LINE = 64
"""Bytes in a cache line of the processors the kernels run on (x86-64)."""
LINE_FLOATS = CACHE_LINE // 8
"""Float64 elements in a cache line."""


@njit(cache=True, inline="always")
def whole_lines(n):
    """``n`` elements (float64) rounded up to whole cache lines (:data:`LINE_FLOATS`)."""
    return (n + LINE_FLOATS - 1) // LINE_FLOATS * LINE_FLOATS


@njit(cache=True, inline="always")
def line_aligned_zeros(n):
    """``n`` zeros (float64) whose first element starts a cache line (:data:`CACHE_LINE` bytes): a view
    of an array one line longer. Numba aligns what it allocates at 32 bytes only, so wherever the
    allocator hands out an address half-way into a line, every 64-byte vector load and store of a loop
    over the rows of a scratch allocated as such spans two lines."""
    buf = np.zeros(n + LINE_FLOATS)
    address = np.int64(buf.ctypes.data)
    skip = (CACHE_LINE - address % CACHE_LINE) % CACHE_LINE // 8
    return buf[skip : skip + n]
