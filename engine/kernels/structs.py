"""The kernels' view of their named tuples: ``Params``, ``Work`` and ``Peaks`` as structs passed by reference.

A kernel that takes a named tuple of arrays copies every array's descriptor into each call, and counts a
reference to every array on the way in and out: the tuple's size in atomic adds at every call of a small
kernel (a fixed step on the article scene took 4 to 10 times as long). A struct is one pointer. Small
cached kernels build the structs (:func:`kernel_struct`): numba's own constructor of a struct proxy is
compiled anew in every process (1.7 s at the start of every command and every Dask worker), while a cached
kernel that calls it is loaded from the cache with the others.
"""

from __future__ import annotations

from typing import Any

from numba import njit
from numba.core import types
from numba.experimental import structref

from isolab.engine.kernels.params import Params, Work
from isolab.engine.kernels.peaks import Peaks


class _UnliteralFields(types.StructRef):
    """A struct whose fields are typed as their values' plain types (``True`` a boolean, not a literal)."""

    def preprocess_fields(self, fields: Any) -> tuple[tuple[str, types.Type], ...]:
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@structref.register
class ParamsType(_UnliteralFields):
    """The numba type of a ``Params`` struct."""


@structref.register
class WorkType(_UnliteralFields):
    """The numba type of a ``Work`` struct."""


@structref.register
class PeaksType(_UnliteralFields):
    """The numba type of a ``Peaks`` struct."""


class KernelParams(structref.StructRefProxy):
    """``Params`` as the kernels take it: passed by reference."""


class KernelWork(structref.StructRefProxy):
    """``Work`` as the kernels take it."""


class KernelPeaks(structref.StructRefProxy):
    """``Peaks`` as the kernels take it."""


structref.define_proxy(KernelParams, ParamsType, list(Params._fields))
structref.define_proxy(KernelWork, WorkType, list(Work._fields))
structref.define_proxy(KernelPeaks, PeaksType, list(Peaks._fields))


@njit(cache=True, fastmath=False)
def _params_struct(P):
    return KernelParams(*P)


@njit(cache=True, fastmath=False)
def _work_struct(W):
    return KernelWork(*W)


@njit(cache=True, fastmath=False)
def _peaks_struct(O):
    return KernelPeaks(*O)


_BUILDERS = {Params: _params_struct, Work: _work_struct, Peaks: _peaks_struct}


def kernel_struct(nt: Params | Work | Peaks) -> Any:
    """The kernel view of a ``Params``, ``Work`` or ``Peaks`` named tuple: its arrays shared, not copied (a
    kernel writes into them in place)."""
    return _BUILDERS[type(nt)](nt)
