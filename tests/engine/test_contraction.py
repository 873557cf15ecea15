"""The nonlinear level's RK4 driver contracts multiply-adds into fused ones (numba's
``fastmath={"contract"}``, which keeps NaN and infinity as they are). Numba compiles a kernel that states
no ``fastmath`` of its own with the flags of the first kernel that calls it, and caches it so: every kernel
such a driver may call without inlining it states its own, so that no other pair's results depend on which
pair compiled first."""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterator
from typing import Any

from numba.core.registry import CPUDispatcher

import isolab.engine.kernels as kernels
from isolab.engine.integrators import euler, rk4, stepping


def _kernels() -> Iterator[tuple[str, Any]]:
    """Every numba kernel defined in ``engine.kernels`` and the stepped methods' modules."""
    modules = [
        importlib.import_module(m.name)
        for m in pkgutil.iter_modules(kernels.__path__, "isolab.engine.kernels.")
    ]
    for module in [*modules, rk4, euler]:
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == module.__name__:
                yield f"{module.__name__}.{name}", value


def test_every_kernel_not_inlined_states_its_fastmath() -> None:
    found = list(_kernels())
    assert len(found) > 30
    unstated = [
        name
        for name, kernel in found
        if kernel.targetoptions.get("inline", "never") != "always" and "fastmath" not in kernel.targetoptions
    ]
    assert not unstated


def test_only_the_nonlinear_rk4_driver_contracts() -> None:
    for (method, level), drivers in stepping.ENTRIES.items():
        for driver in drivers:
            contracts = bool(driver.targetoptions.get("fastmath", False))
            assert contracts == ((method, level) == ("rk4", "nonlinear")), (method, level)
