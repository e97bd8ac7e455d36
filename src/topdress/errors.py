"""The one error hierarchy of topdress.

Every error a user or a device can cause derives from TopdressError.
"""


class TopdressError(Exception):
    """Base of every topdress error."""


class ConfigError(TopdressError):
    """Invalid configuration; the message names the key."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}")
        self.key = key


class ProtocolError(TopdressError):
    """A CAN frame that does not decode (unknown id, wrong length, out of range)."""


class NmeaError(TopdressError):
    """An NMEA sentence that is malformed, truncated or fails its checksum."""


class SensorError(TopdressError):
    """A crop sensor line that is malformed or out of range."""


class DeviceError(TopdressError):
    """A device (serial port, CAN interface) that cannot be opened or vanished."""


class EcuError(TopdressError):
    """The ECU core returned an error code."""

    def __init__(self, code: int, what: str) -> None:
        super().__init__(f"{what}: ECU error {code}")
        self.code = code


class LogError(TopdressError):
    """The session log cannot be written or read."""


class EcuParamError(TopdressError):
    """The ECU refused or did not acknowledge a parameter pushed at start-up."""

    def __init__(self, name: str, value: float, message: str) -> None:
        super().__init__(f"ECU parameter {name} = {value:g}: {message}")
        self.name = name
        self.value = value


class MapError(TopdressError):
    """A map file (prescription, boundary, ISOXML) or an export that cannot be made; the
    message names the file and, where there is one, the feature."""


class OutputError(TopdressError):
    """An output file that would destroy an input, or cannot be written."""


class OfficeError(TopdressError):
    """The farm office's database refused or could not be reached; `exit_code` tells a cron
    job which (see docs/office.md)."""

    #: exit codes: 2 bad input or setting, 3 the office cannot be reached or is not writable
    #: now (try again later), 4 a session that conflicts with the office's copy
    exit_code = 2


class OfficeUnavailable(OfficeError):
    exit_code = 3


class OfficeConflict(OfficeError):
    exit_code = 4
