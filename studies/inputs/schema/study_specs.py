"""What a study file adds to its scene: the parameters it varies (their values or ranges) and the design
that draws its cases. The study model itself is :class:`studies.inputs.study.Study`."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, StrictFloat, StrictInt, StrictStr, model_validator

from isolab.studies.inputs.schema.fields import InputModel, Name

Value = StrictFloat | StrictInt | StrictStr
MAX_LIST_ENTRIES = 10_000_000
"""Most entries of a parameter's ``values`` or a list design's ``cases``: the most cases a design holds
(:data:`studies.questions.designs.GRID_LIMIT`). A service refuses lists longer than its case limit
(``ISOLAB_MAX_CASES``) before parsing (:func:`studies.inputs.definitions.long_lists`)."""


MIN_SALTELLI_SAMPLES = 2
"""Fewest base samples of a saltelli design (one sample gives no variance to split into indices)."""


class RangeSpec(InputModel):
    """A continuous range; ``num`` levels for a grid (sampled designs draw from it)."""

    start: Value
    stop: Value
    num: int | None = Field(None, ge=1, le=100_000)
    scale: Literal["linear", "log"] = "linear"


class ParameterSpec(InputModel):
    """One varied input: a path into the scene and its ``values`` or ``range`` (units allowed)."""

    name: Name | None = None
    path: str = Field(min_length=1, max_length=200)
    values: list[Value] | None = Field(None, min_length=1, max_length=MAX_LIST_ENTRIES)
    range: RangeSpec | None = None

    @model_validator(mode="after")
    def _values_or_range(self) -> ParameterSpec:
        if self.values is not None and self.range is not None:
            raise ValueError("give values or range, not both")
        return self


MAX_ROBUST_SAMPLES = 10_000
"""Most draws a robust design judges each candidate on."""


class RobustSpec(InputModel):
    """An optimize design's ``robust`` block: each candidate judged on ``samples`` draws of the study's
    tolerances (the same draws for every candidate), the objective on a statistic of them and the
    constraints as a chance constraint (:mod:`studies.run.robust`)."""

    samples: int = Field(ge=2, le=MAX_ROBUST_SAMPLES, description="draws of the tolerances per candidate")
    require: Value = Field(
        description="the least probability of meeting every constraint of the design, e.g. 95 % or 0.95"
    )
    statistic: Literal["mean", "quantile"] = Field(
        "mean", description="what the objective is over each candidate's draws: mean or quantile"
    )
    quantile: Value | None = Field(
        None, description="statistic quantile: its share, e.g. 90 % (default 90 %)"
    )
    sampling: Literal["sobol", "random"] = Field(
        "sobol", description="the draws: a scrambled Sobol' sequence (sobol) or independent (random)"
    )


class DesignSpec(InputModel):
    """How cases are drawn: full factorial ``grid``, ``lhs``, ``sobol``, ``random``, ``saltelli`` (Sobol'
    indices: ``samples`` is the base sample N and the study runs N (D + 2) cases, N (2D + 2) with
    ``second_order``, times ``replicates``), explicit ``list``, or ``optimize`` (a pymoo optimiser picks
    the cases generation by generation within ``budget``: :mod:`studies.run.optimisation`), or
    ``monte_carlo`` (``samples`` cases drawn from the study's ``tolerances``:
    :mod:`studies.questions.tolerances`)."""

    type: Literal["grid", "lhs", "sobol", "random", "saltelli", "list", "optimize", "monte_carlo"] = "grid"
    samples: int | None = Field(None, ge=1, le=10_000_000)
    seed: int = Field(0, ge=0)
    second_order: bool | None = Field(
        None, description="saltelli only: also run the cases pairwise (second-order) indices need; default no"
    )
    replicates: int | None = Field(
        None,
        ge=1,
        le=1000,
        description="saltelli only: independent replicates of the design, each of `samples` base samples on "
        "its own scrambled Sobol' sequence (the study runs replicates x samples x (D + 2) cases); the "
        "indices' 95 % intervals come from their spread (a t interval): 8 is a good choice; default 1 (one "
        "design, bootstrap intervals)",
    )
    cases: list[dict[str, Value]] | None = Field(None, max_length=MAX_LIST_ENTRIES)
    sampling: Literal["sobol", "random"] | None = Field(
        None,
        description="monte_carlo only: draw the tolerances along a scrambled Sobol' sequence (sobol, the "
        "default) or independently (random)",
    )
    # optimize only (see studies.run.optimisation and studies.questions.goals, which check them against the
    # outputs)
    objective: str | list[str] | None = Field(
        None,
        description="optimize: 'minimize <quantity>' or 'maximize <quantity>', or a list of them "
        "(multi-objective), e.g. 'minimize settling_time.tool'",
    )
    constraints: list[str] | None = Field(
        None,
        max_length=100,
        description="optimize: 'criteria' (every criterion of the study's criteria block is met) or "
        "'<quantity> <= <value>' / '<quantity> >= <value>' with units, e.g. 'min_isolator_load >= 0 N'",
    )
    algorithm: str | None = Field(
        None,
        description="optimize: a pymoo algorithm (ga, de, pso, nelder-mead, pattern, nsga2); default "
        "ga for one objective, nsga2 for several",
    )
    budget: int | None = Field(None, ge=1, le=1_000_000, description="optimize: total cases to evaluate")
    population: int | None = Field(
        None, ge=2, le=10_000, description="optimize: cases per generation (default 40, at most the budget)"
    )
    plateau: Value | None = Field(
        None,
        description="optimize: the designs answered beside the best: feasible and with the first objective "
        "within this share of the best's (default 1 %)",
    )
    stall: int | None = Field(
        None,
        ge=1,
        le=10_000,
        description="optimize: stop once this many generations in a row improve the best feasible objective "
        "by less than 0.1 % (default: run the whole budget)",
    )

    robust: RobustSpec | None = Field(
        None,
        description="optimize: judge each candidate on its tolerance cloud (samples, require, statistic, "
        "quantile); needs a tolerances block",
    )

    @model_validator(mode="after")
    def _fields_of_its_type(self) -> DesignSpec:
        if self.type == "saltelli" and self.samples is not None and self.samples < MIN_SALTELLI_SAMPLES:
            raise ValueError(
                f"design.samples: a saltelli design needs at least {MIN_SALTELLI_SAMPLES} base samples "
                f"(its indices compare the samples with one another), got {self.samples}"
            )
        if self.replicates is not None and self.type != "saltelli":
            raise ValueError(f"design.replicates: only a saltelli design takes it (type: {self.type})")
        if self.type == "optimize":
            given = [k for k in ("samples", "second_order", "cases") if getattr(self, k) is not None]
            if given:
                raise ValueError(
                    f"design.{given[0]}: an optimize design does not take it (its budget sets the cases)"
                )
        return self
