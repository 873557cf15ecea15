"""The scene: a machine base on isolators with its stages, points of interest, floor motion, simulation
and criteria; the checks that involve several of its blocks (the stage tree, travels, the stages' weight)."""

from __future__ import annotations

from pydantic import Field, ValidationInfo, field_validator, model_validator

from isolab.engine.linear_states.levelling import (
    DEAD_BAND_INTEGRATORS,
    LEVELLING_INTEGRATORS,
    LEVELLING_LEVELS,
)
from isolab.studies.inputs.block import MAX_TRAVEL, beyond_travel, travel_bound
from isolab.studies.inputs.schema.fields import (
    MAX_POINTS,
    MAX_STAGE_MASS_RATIO,
    MAX_STAGES,
    InputModel,
    Name,
    Position,
)
from isolab.studies.inputs.schema.floor_motion import Floor
from isolab.studies.inputs.schema.machine import Machine
from isolab.studies.inputs.schema.mounts import Isolators
from isolab.studies.inputs.schema.scene_paths import (
    LEVELLING,
    isolator_group,
    mount,
    relative_point,
    stage_entry,
)
from isolab.studies.inputs.schema.simulation import Simulation
from isolab.studies.inputs.schema.stages import Stage, profile_excursion
from isolab.studies.questions.criteria import Criteria
from isolab.studies.questions.tolerances import Tolerances


class RelativeEnds(InputModel):
    """The two ends of a relative point: each the name of a stage (the point it carries at its home c.g.)
    or of a material point of the base."""

    tool: Name = Field(description="a stage (what the tool rides on) or a point of the base")
    work: Name = Field(description="a point of the base (where the work sits) or another stage")


class RelativePoint(InputModel):
    """A point of interest that is the motion of a tool relative to the work as the process sees it: in
    the machine's frame, minus the commanded relative motion (the stages' following errors and the base's
    elastic deflection between them; docs/physics.md, "Relative points")."""

    relative: RelativeEnds


class Scene(InputModel):
    """A machine base on isolators with its stages, points of interest, floor motion and simulation."""

    machine: Machine
    isolators: Isolators
    stages: list[Stage] = Field(default_factory=list, max_length=MAX_STAGES)
    points: dict[Name, Position | RelativePoint] = Field(
        default_factory=dict,
        max_length=MAX_POINTS,
        description="material points of the machine, m, or relative points ({relative: {tool, work}})",
    )
    floor: Floor | None = None
    simulation: Simulation = Field(default_factory=Simulation)
    criteria: Criteria | None = Field(
        None, description="limits at the points of interest and on the mounts (studies.questions.criteria)"
    )
    tolerances: Tolerances | None = Field(
        None,
        description="parameter path -> its spread about the nominal value (studies.questions.tolerances): "
        "what a monte_carlo design draws from",
    )

    @field_validator("stages")
    @classmethod
    def _stage_tree_and_travel(cls, stages: list[Stage], info: ValidationInfo) -> list[Stage]:
        names = [s.name for s in stages]
        index: dict[str, int] = {}
        for i, s in enumerate(stages):
            if s.name in index:
                raise ValueError(
                    f"{stage_entry(i)}.name: {s.name!r} is already the name of {stage_entry(index[s.name])}"
                )
            index[s.name] = i
        for i, s in enumerate(stages):
            if s.parent is None:
                continue
            if s.parent == s.name:
                raise ValueError(f"{stage_entry(i)}.parent: stage {s.name!r} cannot ride on itself")
            if s.parent not in index:
                raise ValueError(
                    f"{stage_entry(i)}.parent: no stage named {s.parent!r} (stages: {', '.join(names)})"
                )
            if index[s.parent] > i:
                chain: list[str] = [s.name]
                cur: str | None = s.parent
                while cur is not None and cur not in chain:
                    chain.append(cur)
                    cur = stages[index[cur]].parent
                if cur is not None:
                    raise ValueError(f"{stage_entry(i)}.parent: cycle {' -> '.join([*chain, cur])}")
                raise ValueError(
                    f"{stage_entry(i)}.parent: {s.parent!r} must be listed before {s.name!r} "
                    "(parents come first)"
                )
        machine = info.data.get("machine")
        block = machine.block if machine is not None else None
        for i, s in enumerate(stages):
            bound = float(travel_bound(s.axis, block.size if block is not None else None))
            if block is not None:
                where = f"the base's {bound:.6g} m extent along the stage axis"
            else:
                where = f"{MAX_TRAVEL:g} m"
            far = profile_excursion(s.profile)
            if beyond_travel(far, bound):
                raise ValueError(
                    f"{stage_entry(i)}.profile.travel: the stage would travel {far:.6g} m from home, "
                    f"more than {where}"
                )
        return stages

    @model_validator(mode="after")
    def _stage_mass(self) -> Scene:
        """Stages heavier than the base are refused. What only the assembled scene shows (mounts that
        cannot carry the weight, moves off the base) is the check step's,
        :func:`studies.inputs.scenes.check_scene`:
        parsing builds nothing."""
        stages = sum(s.mass for s in self.stages)
        base = self.machine.properties()[0]
        if stages > MAX_STAGE_MASS_RATIO * base * (1.0 + 1e-12):
            raise ValueError(
                f"stages: together they weigh {stages:.6g} kg, more than {MAX_STAGE_MASS_RATIO:g} times the "
                f"machine base ({base:.6g} kg); stages are point masses, and a base lighter than its stages "
                "leaves the machine almost without rotational inertia"
            )
        return self

    @model_validator(mode="after")
    def _relative_points(self) -> Scene:
        """Each end of a relative point names a stage or a material point, and the two ends differ."""
        stages = [s.name for s in self.stages]
        material = [n for n, v in self.points.items() if not isinstance(v, RelativePoint)]
        for name, value in self.points.items():
            if not isinstance(value, RelativePoint):
                continue
            ends = value.relative
            for key in ("tool", "work"):
                end = getattr(ends, key)
                if end in stages and end in material:
                    raise ValueError(
                        f"{relative_point(name)}.{key}: {end!r} is both a stage and a point; rename one"
                    )
                if end not in stages and end not in material:
                    raise ValueError(
                        f"{relative_point(name)}.{key}: no stage or material point named {end!r} (stages: "
                        f"{', '.join(stages) or 'none'}; points: {', '.join(material) or 'none'})"
                    )
            if ends.tool == ends.work:
                raise ValueError(f"{relative_point(name)}: tool and work are both {ends.tool!r}")
        return self

    @model_validator(mode="after")
    def _levelling_simulation(self) -> Scene:
        """Levelling valves are stepped at lti and ltv by rk4 or exact (a dead band by rk4 alone: the engine
        refuses it at exact, and the accuracy chooser leaves exact out)."""
        iso = self.isolators
        blocks = [(f"{isolator_group(LEVELLING)}", iso.levelling)] + [
            (f"{mount(j)}.{LEVELLING}", m.levelling) for j, m in enumerate(iso.listed)
        ]
        given = [(where, b) for where, b in blocks if b is not None]
        if not given:
            return self
        sim = self.simulation
        where = given[0][0]
        if sim.fidelity not in (None, *LEVELLING_LEVELS):
            raise ValueError(
                f"simulation.fidelity: levelling valves ({where}) are modelled at the "
                f"{' and '.join(LEVELLING_LEVELS)} levels, not {sim.fidelity!r}"
            )
        if sim.integrator not in (None, *LEVELLING_INTEGRATORS):
            raise ValueError(
                f"simulation.integrator: levelling valves ({where}) are integrated by "
                f"{' or '.join(LEVELLING_INTEGRATORS)}, not {sim.integrator!r}"
            )
        if self.floor is not None and (self.floor.sine is not None or self.floor.recorded is not None):
            raise ValueError(
                f"floor: levelling valves ({where}) are not modelled together with a floor motion in time "
                "(sine or recorded) yet; give the floor as a spectrum, or leave the valves out"
            )
        if self.machine.flexible is not None:
            raise ValueError(
                f"machine.flexible: levelling valves ({where}) are not modelled together with a flexible "
                "base yet (the valve would sense and push the base's modes at its mounts); leave one out"
            )
        banded = [w for w, b in given if b.dead_band > 0]
        if banded and sim.integrator is not None and sim.integrator not in DEAD_BAND_INTEGRATORS:
            raise ValueError(
                f"{banded[0]}.dead_band: a dead band is a nonlinearity that the {sim.integrator!r} "
                "integrator (linear maps) does not step; integrate with "
                f"{' or '.join(DEAD_BAND_INTEGRATORS)}, or give a dead band of 0"
            )
        return self

    def material_points(self) -> dict[str, tuple[float, float, float]]:
        """The points of interest that are material points of the base, name -> position (m)."""
        return {n: v for n, v in self.points.items() if not isinstance(v, RelativePoint)}

    @model_validator(mode="after")
    def _criteria_points(self) -> Scene:
        if self.floor is not None:
            self.floor.check_mounts(self.isolators.count)
        if self.criteria is not None:
            self.criteria.check_points(self.points, self.has_floor_spectrum())
        return self

    def has_floor_spectrum(self) -> bool:
        """Whether the floor's vibration is given as a spectrum (what a velocity criterion judges)."""
        return self.floor is not None and (
            self.floor.spectrum is not None or self.floor.per_mount is not None
        )

    def total_mass(self) -> float:
        """Machine plus all stages, kg."""
        return float(self.machine.properties()[0] + sum(s.mass for s in self.stages))
