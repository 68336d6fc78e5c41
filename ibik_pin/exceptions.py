"""The error hierarchy of ibik_pin: every error the package raises derives from IbikError."""


class IbikError(Exception):
    """Base class of every error raised by ibik_pin."""


class InputError(IbikError, ValueError):
    """A user-supplied value, array or file content is not what was expected.

    Attributes:
        parameter: the name of the API parameter the error is about, which starts the message
            ("names: unknown camera name(s) ..."), or None; a program that takes the value under
            another name (the `ibik` command's options) puts its own name there instead.
    """

    def __init__(self, message: str = "", *, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter


class FileFormatError(InputError):
    """A file (TRC, MOT, BVH, ASF/AMC, calibration TOML, image, video) cannot be read."""


class UnreconciledViewsError(InputError):
    """The cameras' detections do not agree on a person (a wrong calibration, unsynchronised videos,
    or people the detector mixes): refused rather than fit to a mixture."""


class UnknownNameError(InputError, KeyError):
    """A frame, joint, keypoint or camera name that does not exist; the message lists the known ones."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class SolverError(IbikError, RuntimeError):
    """A numerical solver cannot produce a result: an IK step from non-finite task rows (NaN or
    infinity) or a failed factorisation, a calibration's least squares that failed.

    A QP backend's failure on one level of the hierarchical QP is a QPBackendError.
    """


class QPBackendError(SolverError):
    """A QP backend found no answer to a level of the hierarchical QP.

    The solver reports it in the level's LevelReport (status "failed", `detail` the backend's own
    status) and goes on, or raises it (HierarchicalQPSolver's raise_on_failure).

    Attributes:
        backend: the backend's name ("proxsuite", "daqp", ...).
        status: the backend's own status, e.g. "PROXQP_MAX_ITER_REACHED after 1000 iterations".
        level: the level's index.
    """

    def __init__(self, backend: str, status: str, level: int = -1) -> None:
        super().__init__(f"QP backend {backend!r} found no answer to level {level}: {status}")
        self.backend = backend
        self.status = status
        self.level = level


class IbikWarning(UserWarning):
    """Base class of the warnings ibik_pin emits (degraded but usable input)."""


class EmptySilhouetteWarning(IbikWarning):
    """A view's silhouette is empty: the image term is disabled for that view."""
