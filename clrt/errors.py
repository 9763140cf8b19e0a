"""The exceptions clrt raises on purpose, and the warnings it gives.

Every error a user can cause (a bad file, a bad option, no OpenCL driver) is a
subclass of :class:`ClrtError`.  The CLI prints ``clrt: <message>`` on one line
and exits with the class's ``exit_code``; anything else is a bug.  A warning
(:class:`ClrtWarning`, through :func:`warnings.warn`) says what clrt went on
without; the CLI prints ``clrt: warning: <message>`` on one line.
"""


class ClrtError(Exception):
    """Base class of all errors clrt raises deliberately."""

    exit_code = 1


class InputError(ClrtError):
    """A value given by the user is out of range or malformed."""

    exit_code = 2


class MeshLoadError(InputError):
    """A mesh file is missing, unreadable, of an unknown format, corrupt or empty."""


class OutputError(InputError):
    """The output cannot be written: an existing file clrt did not write (replace
    it with ``--force``), a missing folder, no permission, a full disk."""


class TooLargeError(InputError):
    """A job needs more host memory than is available; the message gives the size needed."""


class ClrtWarning(UserWarning):
    """Base class of the warnings clrt gives: something was left out, and it went on."""


class MeshLoadWarning(ClrtWarning):
    """A mesh file names a file that is not there (an OBJ's MTL library, a
    material's texture image): the mesh loads without it."""


class DeviceError(ClrtError):
    """No usable OpenCL platform or device, or the device failed."""

    exit_code = 3


class KernelBuildError(DeviceError):
    """An OpenCL program failed to compile; the message carries the build log."""


class DeviceMemoryError(DeviceError):
    """The scene does not fit in the device's memory even with the image split
    into the smallest tiles; the message gives the size needed and the device's."""


class NothingVisibleWarning(ClrtWarning):
    """A frame in which no camera ray hit a triangle: the image is only the
    background (every triangle of zero area, the scene behind the camera or out
    of its view).  ``clrt render`` prints it as one line, ``clrt: warning: ...``,
    and writes the image; ``Frame.visible`` is False."""
