"""The error hierarchy of ibik_pin: every error the package raises derives from IbikError."""


class IbikError(Exception):
    """Base class of every error raised by ibik_pin."""


class InputError(IbikError, ValueError):
    """A user-supplied value, array or file content is not what was expected."""


class FileFormatError(InputError):
    """A file (TRC, MOT, BVH, ASF/AMC, calibration TOML, image, video) cannot be read."""


class UnknownNameError(InputError, KeyError):
    """A frame, joint, keypoint or camera name that does not exist; the message lists the known ones."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class SolverError(IbikError, RuntimeError):
    """A numerical solver cannot produce a result: an IK step from non-finite task rows (NaN or
    infinity) or a failed factorisation, a calibration's least squares that failed.

    A proxsuite failure on one level of the hierarchical QP is recoverable and raises nothing: that
    level is skipped for the step and reported "failed" (solvers.LevelReport).
    """


class IbikWarning(UserWarning):
    """Base class of the warnings ibik_pin emits (degraded but usable input)."""


class EmptySilhouetteWarning(IbikWarning):
    """A view's silhouette is empty: the image term is disabled for that view."""
