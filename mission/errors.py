"""The project's own error hierarchy.

Foreign errors (pymavlink ``None`` returns, socket errors, zenoh exceptions, pydantic
validation errors) are translated into these at the module boundary, so callers catch
one family. The CLI maps them to exit codes; library code never prints or exits.
"""
from __future__ import annotations


class MarsupialError(Exception):
    """Base of every error raised on purpose by this package."""

    exit_code = 1


class ConfigError(MarsupialError):
    """A configuration field is invalid. The message names the field, the value and the rule."""

    exit_code = 2

    def __init__(self, field: str, value: object, rule: str) -> None:
        self.field, self.value, self.rule = field, value, rule
        super().__init__(f"{field} = {value!r}: {rule}")


class AssumptionError(ConfigError):
    """The scenario geometry violates an assumption of the paper (refuse to start)."""


class LinkError(MarsupialError):
    """The MAVLink link failed (socket error, vehicle not found, heartbeat lost)."""

    exit_code = 3


class LinkTimeout(LinkError):
    """An expected message (heartbeat, ACK, telemetry) did not arrive before its deadline."""


class CommandRejected(LinkError):
    """The vehicle answered a COMMAND_LONG with a non-ACCEPTED result.

    ``result`` is the MAV_RESULT code; ``reason`` is the vehicle's latest STATUSTEXT, if any.
    """

    def __init__(self, command: int, result: int, reason: str = "") -> None:
        self.command, self.result, self.reason = command, result, reason
        text = f"command {command} rejected with MAV_RESULT {result}"
        super().__init__(text + (f": {reason}" if reason else ""))


class BusError(MarsupialError):
    """The Zenoh session could not be opened or a key expression is invalid."""

    exit_code = 4


class PortInUse(MarsupialError):
    """A local port this command must bind is taken; the message names it and its holder."""

    exit_code = 6


class LinkPortInUse(PortInUse, LinkError):
    """The MAVLink endpoint's port is taken (a :class:`LinkError` too; exit code 6)."""


class BusPortInUse(PortInUse, BusError):
    """A Zenoh listen endpoint's port is taken (a :class:`BusError` too; exit code 6)."""


class MissionAborted(MarsupialError):
    """The mission ended in ABORT; ``reason`` says why (a phases.AbortReason value)."""

    exit_code = 5

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason, self.detail = reason, detail
        super().__init__(f"mission aborted: {reason}" + (f" ({detail})" if detail else ""))
