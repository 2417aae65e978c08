"""The scenario's geometry: ``[scenario]``, where the carrier, the passenger and the target(s) are
at t = 0 and the obstacles. Part of the schema in :mod:`mission.config.schema`."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from pydantic import Field, model_validator

from mission.config.fields import Coord, Section
from mission.errors import ConfigError

if TYPE_CHECKING:  # the schema imports no law: the converter below imports it when called
    from mission.core.safety import Obstacles


class ObstacleSection(Section):
    center: list[Coord] = Field(description="[m] obstacle centre (dim components)")
    radius: float = Field(gt=0, le=100_000, description="[m] obstacle radius")


MAX_TARGETS = 100  # scenario.targets


class ScenarioSection(Section):
    """Geometry: where the carrier, passenger and target are at t = 0 [m]."""

    dim: Literal[2, 3] = Field(3, description="[-] 2 (planar) or 3; a flight needs 3")
    frame: Literal["local_ned", "xyz"] = Field("local_ned",
        description="[-] `local_ned` (PX4's local NED, z down; plots show altitude) or `xyz` (plots only)")
    carrier_start: list[Coord] = Field([0.0, 0.0, 0.0],
        description="[m] carrier position at t = 0 (dim components; the carrier simulator starts here)")
    target: list[Coord] = Field([20.0, 15.0, -4.0],
        description=("[m] target position (dim components); in 3D with a planar carrier at most b c above the "
                     "carrier's plane"))
    targets: list[list[Coord]] | None = Field(None,
        description=("[m] several targets, visited in order, one leg each (ride, separate, target, return, dock, ride "
                     "on); `target` is then the first of them; needs mission.final_action = `return` for more than one"))
    passenger_start: list[Coord] | None = Field(None,
        description=("[m] passenger start for `simulate` (default: docked on the carrier, Assumption 2); `run` uses "
                     "the vehicle's real position"))
    planar_carrier: bool = Field(True,
        description="[-] the carrier moves in its horizontal plane (u_c projected onto it) in 3D")
    eta: float | None = Field(None, gt=0, le=10_000_000,
        description="[m] Assumption 1 lower bound, b c < eta <= |e_tc(0)| (default |e_tc(0)|)")
    carrier_mode: Literal["stop", "remark1"] = Field("stop",
        description=("[-] after separation the carrier `stop`s, or keeps its own plan (`remark1`: its velocity of the "
                     "separation instant, CBF-filtered)"))
    obstacles: list[ObstacleSection] = Field([], max_length=1000,
        description=("[-] list of `{ center = [m], radius = m }` circles (2D) or spheres (3D); the carrier avoids "
                     "their planar circles"))

    @model_validator(mode="before")
    @classmethod
    def _first_target(cls, data: Any) -> Any:
        """With ``targets``, ``target`` is the first of them (and may be left out)."""
        if isinstance(data, dict) and isinstance(data.get("targets"), list):
            if not 1 <= len(data["targets"]) <= MAX_TARGETS:
                raise ConfigError("scenario.targets", data["targets"], f"must list 1 to {MAX_TARGETS} targets")
            first = data["targets"][0]
            if "target" in data and data["target"] != first:
                raise ConfigError("scenario.target", data["target"], f"differs from scenario.targets[0] = {first}: "
                                  "give one of them")
            data = {**data, "target": first}
        return data

    def target_field(self) -> str:
        """How the file named its targets: ``scenario.targets``, or ``scenario.target`` alone."""
        return "scenario.target" if self.targets is None else "scenario.targets"

    def legs(self) -> list[list[float]]:
        """The targets in the order they are visited (one leg each)."""
        return [list(t) for t in self.targets] if self.targets is not None else [list(self.target)]

    @model_validator(mode="after")
    def _dims(self) -> "ScenarioSection":
        for name in ("carrier_start", "target", "passenger_start"):
            v = getattr(self, name)
            if v is not None and len(v) != self.dim:
                raise ConfigError(f"scenario.{name}", v, f"must have {self.dim} components (scenario.dim)")
        for i, t in enumerate(self.targets or []):
            if len(t) != self.dim:
                raise ConfigError(f"scenario.targets[{i}]", t, f"must have {self.dim} components (scenario.dim)")
        for i, ob in enumerate(self.obstacles):
            if len(ob.center) != self.dim:
                raise ConfigError(f"scenario.obstacles[{i}].center", ob.center, f"must have {self.dim} components")
        return self

    def obstacle_set(self) -> Obstacles:
        from mission.core.safety import Obstacles

        return Obstacles.of([(o.center, o.radius) for o in self.obstacles], self.dim)
