"""Models of the extra linear states the linear levels carry beside the base's 12
(``engine.model.linear_slot``, docs/engine.md "Extra linear states"): each returns its block of the state
equations, ``block.SlotBlock``. ``flexible_base``: a flexible base's elastic modes; ``servo``: the
following errors of stages on a servo; ``mount_branches``: the mounts' relaxation branches;
``levelling``: the forces air mounts' levelling valves add."""
