"""The wire form of a task rule: a declarative TaskDefinition (a background class and regions painted
over it in order), written once. A run carries its definition on the service (or, for a run without
a rule, only a person's instruction); the trainer, the teacher, the labeling UI and the dashboard
all judge and draw from that stored copy (collie.tasks.definition turns it into a Task).

Region kinds and their fields are the same words as collie.tasks regions' `to_dict()`; a task file
(docs/tasks.md) is this model written as TOML or JSON. A class is 0 bad, 1 neutral, 2 good, or
its name.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, FiniteFloat, field_validator, model_validator

CLASS_OF_NAME = {"bad": 0, "neutral": 1, "good": 2}
MAX_REGIONS = 64
MAX_POLYGON_VERTICES = 256
MAX_TOTAL_VERTICES = 1024  # a run's definition travels in every RunRead: keep it a few kB
MAX_TEXT = 2000
MAX_INSTRUCTION = 2000


def _no_nul(text: str) -> str:
    if "\x00" in text:  # PostgreSQL text cannot hold it, and no person means it
        raise ValueError("text must not contain the NUL character (\\u0000)")
    return text


Text = Annotated[str, AfterValidator(_no_nul)]  # free text stored as text: no NUL (collie.schemas uses it too)
TaskName = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:+-]+$")]
MAX_COORDINATE = 1e6  # metres: every arena is tens across; past this, squares overflow float64 (NaN verdicts)
Coordinate = Annotated[FiniteFloat, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Point = Annotated[list[Coordinate], Field(min_length=2, max_length=2, description="[x, y]")]


def _class_value(v: object) -> object:
    """'bad' / 'neutral' / 'good' → 0 / 1 / 2 (task files may name classes); ints pass through."""
    if isinstance(v, str) and v in CLASS_OF_NAME:
        return CLASS_OF_NAME[v]
    if isinstance(v, bool | str):
        raise ValueError(f"a class is 'bad', 'neutral' or 'good' (or 0, 1, 2), got {v!r}")
    return v


class Spec(BaseModel):
    """Strict (no silent coercion) and closed (an unknown key is an error, so a typo is caught)."""

    model_config = ConfigDict(strict=True, extra="forbid")


class RegionBase(Spec):
    desirability: Literal[0, 1, 2] = Field(description="class inside the region: 0 bad, 1 neutral, 2 good")
    name: Text | None = Field(default=None, min_length=1, max_length=64, description="optional, unique in the task")

    @field_validator("desirability", mode="before")
    @classmethod
    def _named_class(cls, v: object) -> object:
        return _class_value(v)


class DiscSpec(RegionBase):
    kind: Literal["disc"]
    centre: Point
    radius: FiniteFloat = Field(gt=0, le=MAX_COORDINATE)


class OutsideDiscSpec(RegionBase):
    kind: Literal["outside_disc"]
    centre: Point
    radius: FiniteFloat = Field(gt=0, le=MAX_COORDINATE)


class WedgeNorthSpec(RegionBase):
    kind: Literal["wedge_north"]
    apex: Point = Field(default_factory=lambda: [0.0, 0.0])


class HalfPlaneSpec(RegionBase):
    kind: Literal["halfplane_left", "halfplane_right"] = Field(description="x < x0, or x > x0")
    x0: Coordinate = 0.0


class PitchLimitSpec(RegionBase):
    kind: Literal["pitch_beyond"]
    limit: FiniteFloat = Field(gt=0, le=math.pi, description="radians: inside where |pitch| > limit")


class PolygonSpec(RegionBase):
    kind: Literal["polygon"]
    vertices: list[Point] = Field(min_length=3, max_length=MAX_POLYGON_VERTICES, description="[x, y] in order")

    @field_validator("vertices")
    @classmethod
    def _some_area(cls, v: list[list[float]]) -> list[list[float]]:
        twice_area = sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(v, v[1:] + v[:1], strict=True))  # shoelace
        if twice_area == 0:
            raise ValueError("the polygon's vertices enclose no area (all on one line)")
        return v


RegionSpec = Annotated[
    DiscSpec | OutsideDiscSpec | WedgeNorthSpec | HalfPlaneSpec | PitchLimitSpec | PolygonSpec,
    Field(discriminator="kind"),
]
REGION_KINDS = ("disc", "outside_disc", "wedge_north", "halfplane_left", "halfplane_right", "pitch_beyond", "polygon")


class TaskMeaning(Spec):
    """One line per class, for a labeler: what a bad / neutral / good state is in this task."""

    bad: Text | None = Field(default=None, max_length=MAX_TEXT)
    neutral: Text | None = Field(default=None, max_length=MAX_TEXT)
    good: Text | None = Field(default=None, max_length=MAX_TEXT)

    def by_class(self) -> dict[int, str]:
        return {CLASS_OF_NAME[k]: v for k, v in self.model_dump().items() if v is not None}


class TaskDefinition(Spec):
    """A task rule as data: `background` everywhere, then each region painted over it in order."""

    name: TaskName
    description: Text = Field(min_length=1, max_length=MAX_TEXT, description="plain language for a labeler")
    meaning: TaskMeaning = Field(default_factory=TaskMeaning)
    background: Literal[0, 1, 2] = 1
    regions: list[RegionSpec] = Field(max_length=MAX_REGIONS)
    source: Text = Field(default="", max_length=256, description="where it came from: builtin, or a file's name")

    @field_validator("background", mode="before")
    @classmethod
    def _named_class(cls, v: object) -> object:
        return _class_value(v)

    @model_validator(mode="after")
    def _unique_names(self) -> TaskDefinition:
        vertices = sum(len(r.vertices) for r in self.regions if isinstance(r, PolygonSpec))
        if vertices > MAX_TOTAL_VERTICES:
            raise ValueError(f"the polygons have {vertices} vertices in all, at most {MAX_TOTAL_VERTICES}")
        seen: dict[str, int] = {}
        for i, region in enumerate(self.regions):
            if region.name is None:
                continue
            if region.name in seen:
                raise ValueError(f"regions[{i}] and regions[{seen[region.name]}] are both named {region.name!r}")
            seen[region.name] = i
        return self

    @property
    def can_be_good(self) -> bool:
        """Whether the rule calls any state good (as Task.can_be_good: a region or the background is)."""
        return 2 in {self.background, *(r.desirability for r in self.regions)}

    def to_json(self) -> dict[str, Any]:
        return self.model_dump(mode="json", exclude_none=True)
