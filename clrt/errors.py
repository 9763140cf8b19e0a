"""The exceptions clrt raises on purpose.

Every error a user can cause (a bad file, a bad option, no OpenCL driver) is a
subclass of :class:`ClrtError`.  The CLI prints ``clrt: <message>`` on one line
and exits with the class's ``exit_code``; anything else is a bug.
"""


class ClrtError(Exception):
    """Base class of all errors clrt raises deliberately."""

    exit_code = 1


class InputError(ClrtError):
    """A value given by the user is out of range or malformed."""

    exit_code = 2


class MeshLoadError(InputError):
    """A mesh file is missing, unreadable, of an unknown format, corrupt or empty."""


class DeviceError(ClrtError):
    """No usable OpenCL platform or device, or the device failed."""

    exit_code = 3


class KernelBuildError(DeviceError):
    """An OpenCL program failed to compile; the message carries the build log."""
