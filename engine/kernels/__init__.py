"""The engine's Numba kernels: the equations of motion and the running peaks, arrays in and arrays out.

Every function here is compiled by Numba (``cache=True``) or prepares arrays for one that is: the named tuples
the kernels work on (``params``; ``Peaks`` in ``peaks``) and the structs they take them as (``structs``),
vectors and rotations (``rotations``), what shakes the base (``excitation``), the isolators (``mounts``) and
the feedforward actuators (``feedforward``), the terms kept per case and per time (``cached_terms``), the
accelerations of each level (``dynamics``), and what is observed of the motion (``peaks``, its extrema
between output times in ``between_steps``). The integrators (``engine.integrators``) step them and observe
the linear levels through their output map (``engine.integrators.output_map``); ``engine.simulate`` runs a
batch.
"""
