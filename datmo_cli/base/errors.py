"""Errors datmo raises on bad input; the CLI prints them as one line and exits non-zero."""


class DatmoError(Exception):
    """A problem the user can fix: bad input, missing file, refused overwrite."""

    exit_code = 1


class InputError(DatmoError):
    """An input file is missing, unreadable, empty, truncated or of the wrong kind."""


class OutputError(InputError):
    """An output cannot be written there: a folder, FIFO or device in the way, a missing or read-only folder,
    a name too long, the output is an input, the disk full (an InputError: the output path is input too)."""


class OutputExistsError(DatmoError):
    """The output exists and --force was not given."""


class MissingChannelError(DatmoError):
    """The log lacks a channel a command needs; the message names the command to run first."""


class ConfigError(DatmoError):
    """A parameter or configuration file is invalid; the message names the key."""


class DeviceError(DatmoError):
    """A serial device is missing, silent or talks garbage."""


class GeometryError(InputError):
    """A log's scan geometry changes mid-run."""
