"""OUTDIR: refused before any work when writing it could destroy what the user has, written through
a staging folder beside it, and replaced only when it is an earlier output of ours.

An output folder carries a marker file (:data:`MARKER`). A run may replace a folder with the marker,
or an empty one; any other existing path is the user's and is refused, as is an OUTDIR that is,
holds or lies inside one of the inputs.
"""

from __future__ import annotations

import errno
import os
import shutil
import tempfile
import uuid
from collections.abc import Iterable
from pathlib import Path

from ibik_pin.exceptions import InputError

__all__ = ["MARKER", "OutputFolderError", "check_outdir", "make_staging", "publish"]

#: The file every output folder of ``ibik track`` holds: what tells it apart from the user's folders.
MARKER = ".ibik_output"


class OutputFolderError(InputError):
    """The output folder would destroy or hide the user's files, or cannot be written."""


def check_outdir(out: str | os.PathLike[str], inputs: Iterable[Path | None]) -> Path:
    """The output folder as a Path, once writing it can destroy nothing of the user's.

    Args:
        out: the folder as the user gave it.
        inputs: every input path of the run (files and folders; None for the ones not given).

    Raises:
        OutputFolderError: the name is empty, ``.`` or ``..``; it is a symbolic link; it is, holds
            or lies inside an input; it is an existing file, or a folder that is neither empty nor
            an earlier output (no :data:`MARKER`); or its parent folder cannot be written.
    """
    text = os.fspath(out)
    path = Path(text)
    if not text.strip() or path.name in ("", ".", ".."):
        raise OutputFolderError(f"--out {text!r}: name the output folder itself (a new folder, or an earlier "
                                "output of ibik), not the current or a parent folder")
    if path.is_symlink():
        raise OutputFolderError(f"--out {text}: is a symbolic link; name the folder it points to, or a new one")
    resolved = path.resolve()
    for given in inputs:
        if given is None:
            continue
        source = Path(given).resolve()
        if resolved == source or resolved in source.parents:
            raise OutputFolderError(f"--out {text}: it {'is' if resolved == source else 'holds'} the input "
                                    f"{given}, which the outputs would replace; choose another folder")
        if source in resolved.parents and source.is_dir():
            raise OutputFolderError(f"--out {text}: it lies inside the input folder {given}; choose a folder "
                                    "outside the inputs")
    if path.exists():
        if not path.is_dir():
            raise OutputFolderError(f"--out {text}: is an existing file, not a folder; choose a folder name")
        if not (path / MARKER).is_file() and any(path.iterdir()):
            raise OutputFolderError(f"--out {text}: the folder holds files that are not an output of ibik "
                                    f"(no {MARKER} in it); choose a new folder or empty this one")
    parent = resolved.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise OutputFolderError(f"--out {text}: {parent} is a file, so no folder can be made in it")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputFolderError(f"--out {text}: cannot write in {parent} (permission denied)")
    return path


def make_staging(out: Path) -> Path:
    """A new empty folder beside OUTDIR (created with its parents) with the marker, where the run
    writes; its permissions are those of a folder made by the user (not mkdtemp's 0700)."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
        umask = os.umask(0)
        os.umask(umask)
        staging.chmod(0o777 & ~umask)
        (staging / MARKER).write_text("written by ibik track; a later run may replace this folder\n")
    except OSError as error:
        raise OutputFolderError(f"--out {out}: cannot create it: {error.strerror or error}") from None
    return staging


def publish(staging: Path, out: Path, attempts: int = 20) -> None:
    """Move the finished staging folder to OUTDIR. An earlier OUTDIR (checked by check_outdir) is
    moved aside under a name of its own first, then removed. When another run publishes into the
    same OUTDIR in between, the move is tried again: the last run to finish wins, and neither fails
    nor leaves a backup behind."""
    for _ in range(attempts):
        previous = None
        if out.exists():
            previous = out.with_name(f".{out.name}.previous.{uuid.uuid4().hex[:12]}")
            try:
                os.replace(out, previous)
            except FileNotFoundError:  # another run moved it aside first
                continue
        try:
            os.replace(staging, out)
        except OSError as error:
            if error.errno not in (errno.ENOTEMPTY, errno.EEXIST):  # not another run's output in the way
                if previous is not None and not out.exists():
                    os.replace(previous, out)  # put the earlier output back
                raise
            continue
        finally:
            if previous is not None and previous.exists():
                shutil.rmtree(previous, ignore_errors=True)
        return
    raise OutputFolderError(f"--out {out}: other runs kept replacing it; the outputs are left in {staging}")
