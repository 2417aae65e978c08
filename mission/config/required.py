"""What a flight must state in its own file: no default stands in for the target or for a speed
or acceleration limit (``marsupial run``, ``marsupial carrier``).

The schema's defaults suit the simulator's paper runs, where the unsaturated law is the point
(``marsupial simulate`` says when it flies it). A flight on them would go to a target nobody
chose, and without ``[safety]`` limits the law commanded 5.8e20 m/s after separation. So these
two commands refuse, before anything is opened, a file that does not state each field below
(exit 2, naming the first one missing).
"""
from __future__ import annotations

from pydantic import BaseModel

from mission.errors import ConfigError

#: Fields ``marsupial run`` needs stated: the target, the passenger's limits, and the carrier's
#: (its feed gate checks carrier states against them).
RUN_FIELDS = ("scenario.target", "safety.passenger_max_speed_m_s", "safety.passenger_max_accel_m_s2",
              "safety.carrier_max_speed_m_s", "safety.carrier_max_accel_m_s2")
#: Fields ``marsupial carrier`` needs stated: the target and the carrier's own limits.
CARRIER_FIELDS = ("scenario.target", "safety.carrier_max_speed_m_s", "safety.carrier_max_accel_m_s2")


def stated(cfg: BaseModel, dotted: str) -> bool:
    """Whether the file (or a command-line override) set ``dotted`` (e.g. ``"safety.z_max_m"``)
    to a value, rather than leaving it to its default or to None."""
    node: object = cfg
    for part in dotted.split("."):
        if not isinstance(node, BaseModel) or part not in node.model_fields_set:
            return False
        node = getattr(node, part)
    return node is not None


def require_stated(cfg: BaseModel, fields: tuple[str, ...], command: str) -> None:
    """Raise :class:`ConfigError` naming the first of ``fields`` that ``cfg`` does not state."""
    for field in fields:
        if stated(cfg, field):
            continue
        section = field.split(".")[0]
        missing = (f"the file has no [{section}] section" if section not in cfg.model_fields_set
                   else f"not set in [{section}]")
        raise ConfigError(field, None, f"{missing}: `marsupial {command}` flies only on a target and speed and "
                          f"acceleration limits the file states ({', '.join(fields)}); a default would fly to a "
                          "target nobody chose or on the unsaturated law")
