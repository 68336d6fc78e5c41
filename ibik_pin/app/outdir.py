"""OUTDIR: refused before any work when writing it could destroy what the user has, written through
a staging folder beside it, and published at the very end.

An output folder carries a manifest (app.manifest: the marker file :data:`MARKER`, listing the
files ibik wrote). A run may write into a new or empty folder, or into an earlier output: then it
replaces only the files that output's manifest lists, and every other file (the user's notes, an
analysis saved there) is carried into the new output as it was, hard-linked (or copied) into the
staging folder before the swap, so that an interrupted run leaves the earlier output whole. Any
other existing path is the user's and is refused, as is an OUTDIR that is, holds or lies inside
one of the inputs, or whose name no file system here can hold.
"""

from __future__ import annotations

import errno
import itertools
import os
import random
import re
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterable, Sequence
from pathlib import Path

from ibik_pin.app.manifest import (
    MARKER,
    has_an_output_name,
    listed_files,
    process_is_gone,
    read_manifest,
    user_paths,
    write_manifest,
)
from ibik_pin.exceptions import InputError

__all__ = ["MARKER", "OutputFolderError", "check_outdir", "file_name_part", "kept_message", "make_staging",
           "overlay_file_names", "previous_prefix", "publish", "remove_leftovers", "staging_prefix"]

# A staging or set-aside folder's name starts with at most this much of OUTDIR's name, so that
# it fits in a file name (255 bytes) whatever OUTDIR's length.
NAME_PART_BYTES = 100
# Room left in a path for the longest name written inside OUTDIR (an overlay video's is cut to it).
LONGEST_OUTPUT_NAME = 120
# An earlier output set aside longer ago than this is a killed publish's, not one in progress.
STALE_SECONDS = 60.0
_UNSAFE_IN_A_NAME = re.compile(r'[/\\\x00-\x1f:*?"<>|]')


class OutputFolderError(InputError):
    """The output folder would destroy or hide the user's files, or cannot be written."""


def _limit(path: Path, name: str, default: int) -> int:
    try:
        return int(os.pathconf(path, name))
    except (OSError, ValueError):
        return default


def _name_part(name: str, limit: int = NAME_PART_BYTES) -> str:
    """The start of `name` within `limit` bytes of UTF-8 (a character is never cut in two)."""
    return name.encode("utf-8", "surrogateescape")[:limit].decode("utf-8", "ignore")


def staging_prefix(out: Path) -> str:
    """How the staging folders of OUTDIR `out` are named (a random part follows)."""
    return f".{_name_part(out.name)}.staging."


def previous_prefix(out: Path) -> str:
    """How an earlier OUTDIR is named while it is set aside by a publish (a random part follows)."""
    return f".{_name_part(out.name)}.previous."


def file_name_part(text: str, limit: int = LONGEST_OUTPUT_NAME - 16) -> str:
    """`text` made usable in a file name: the characters file systems refuse ("/", "\\", control
    characters, and Windows' ``:*?"<>|``) become "_", a leading "." becomes "_", and it is cut to
    `limit` bytes."""
    safe = _name_part(_UNSAFE_IN_A_NAME.sub("_", text), limit) or "_"
    return "_" + safe[1:] if safe.startswith(".") else safe


def _check_name_fits(text: str, resolved: Path) -> None:
    """Refuse a name or path longer than the file system takes, checked on the text alone (a
    stat of such a path fails with ENAMETOOLONG)."""
    parent = resolved.parent
    while not os.path.lexists(parent):  # False, not an error, for a path too long
        parent = parent.parent
    name_max = _limit(parent, "PC_NAME_MAX", 255)
    for part in resolved.relative_to(parent).parts:
        if len(part.encode("utf-8", "surrogateescape")) > name_max:
            raise OutputFolderError(f"--out {text}: the name {_name_part(part, 40)}... is "
                                    f"{len(part.encode('utf-8', 'surrogateescape'))} bytes long, more than a "
                                    f"file name can hold here ({name_max}); choose a shorter name")
    path_max = _limit(parent, "PC_PATH_MAX", 4096)
    if len(os.fsencode(resolved)) + 1 + LONGEST_OUTPUT_NAME >= path_max:
        raise OutputFolderError(f"--out {text}: the path is {len(os.fsencode(resolved))} bytes long; with the "
                                f"outputs' names in it, it would pass the {path_max} bytes a path can have here")


def check_outdir(out: str | os.PathLike[str], inputs: Iterable[Path | None]) -> Path:
    """The output folder as a Path, once writing it can destroy nothing of the user's.

    Args:
        out: the folder as the user gave it.
        inputs: every input path of the run (files and folders; None for the ones not given).

    Raises:
        OutputFolderError: the name is empty, ``.`` or ``..``, or too long for the file system; it
            is a symbolic link; it is, holds or lies inside an input; it is an existing file, or a
            folder that is neither empty nor an earlier output (no :data:`MARKER`); an earlier
            output holds a file of the user's under a name ibik writes; or its parent folder
            cannot be written.
    """
    text = os.fspath(out)
    path = Path(text)
    if not text.strip() or path.name in ("", ".", ".."):
        raise OutputFolderError(f"--out {text!r}: name the output folder itself (a new folder, or an earlier "
                                "output of ibik), not the current or a parent folder")
    _check_name_fits(text, Path(os.path.abspath(text)))
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
        clashing = [name for name in user_paths(path) if has_an_output_name(name)]
        if clashing:
            raise OutputFolderError(f"--out {text}: {clashing[0]} is not listed among the files ibik wrote there "
                                    f"({MARKER}), but ibik may write a file of that name; move or rename it")
    parent = resolved.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise OutputFolderError(f"--out {text}: {parent} is a file, so no folder can be made in it")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputFolderError(f"--out {text}: cannot write in {parent} (permission denied)")
    return path


def make_staging(out: Path) -> Path:
    """A new empty folder beside OUTDIR (created with its parents) with a manifest in state
    "staging", where the run writes; its permissions are those of a folder made by the user (not
    mkdtemp's 0700). What killed runs into the same OUTDIR left beside it goes first
    (remove_leftovers)."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        remove_leftovers(out)
        staging = Path(tempfile.mkdtemp(prefix=staging_prefix(out), dir=out.parent))
        umask = os.umask(0)
        os.umask(umask)
        staging.chmod(0o777 & ~umask)
        write_manifest(staging, "staging")
    except (OSError, InputError) as error:
        reason = error.strerror if isinstance(error, OSError) and error.strerror else error
        raise OutputFolderError(f"--out {out}: cannot create it: {reason}") from None
    return staging


def _carry(kept: Sequence[str], source: Path, staging: Path, racing: bool) -> list[str]:
    """The user's paths of an earlier output put into the staging folder as they are: files
    hard-linked (copied where links are not possible), links as links, empty folders made; returns
    the ones carried. `racing`: `source` may be replaced meanwhile by another run, so a path that
    vanished or clashes is skipped (it is looked at again once the folder is set aside)."""
    carried = []
    for name in kept:
        origin, destination = source / name.rstrip("/"), staging / name.rstrip("/")
        try:
            if os.path.lexists(destination):
                if racing:
                    continue
                raise OutputFolderError(f"--out {source}: {name} is the user's, and this run wrote a file of "
                                        "that name; move or rename it and run again")
            destination.parent.mkdir(parents=True, exist_ok=True)
            if name.endswith("/"):
                destination.mkdir()
            elif origin.is_symlink():
                os.symlink(os.readlink(origin), destination)
            else:
                try:
                    os.link(origin, destination)
                except FileNotFoundError:
                    raise
                except OSError:
                    shutil.copy2(origin, destination)
        except FileNotFoundError:
            if racing:
                continue
            raise
        carried.append(name)
    return carried


def publish(staging: Path, out: Path, patience_s: float = 60.0) -> list[str]:
    """Move the finished staging folder to OUTDIR; returns the user's paths kept from an earlier
    OUTDIR (see the module docstring).

    The staging folder's manifest lists what the run wrote; the user's paths of the earlier OUTDIR
    are carried into it; then the earlier OUTDIR is moved aside under a name of its own, the
    staging folder takes its place, and the earlier one is removed. When another run publishes
    into the same OUTDIR in between, the move is tried again, for up to `patience_s` seconds: the
    last run to finish wins, and neither fails nor leaves a backup behind."""
    written = listed_files(staging)
    kept: list[str] = []
    give_up = time.monotonic() + patience_s
    for attempt in itertools.count():
        if attempt:  # another run published in between: a random pause keeps two runs from meeting again
            if time.monotonic() > give_up:
                break
            time.sleep(random.uniform(0.0, 0.001 * min(attempt, 10)))
        previous = None
        if out.exists():
            if read_manifest(out) is not None:  # else another run is replacing it right now
                kept += _carry([name for name in user_paths(out) if name not in kept], out, staging, racing=True)
            previous = out.with_name(f"{previous_prefix(out)}{uuid.uuid4().hex[:12]}")
            try:
                os.replace(out, previous)
            except FileNotFoundError:  # another run moved it aside first
                continue
            try:  # set aside, the earlier output is ours alone: what changed since is carried now
                kept += _carry([name for name in user_paths(previous) if name not in kept], previous, staging,
                               racing=False)
            except BaseException:
                os.replace(previous, out)
                raise
        write_manifest(staging, "complete", written, kept)
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
        return sorted(kept)
    raise OutputFolderError(f"--out {out}: other runs kept replacing it; the outputs are left in {staging}")


def kept_message(out: Path, kept: Sequence[str]) -> str:
    """The one line that says an earlier output's own files were kept."""
    return (f"--out {out}: kept {len(kept)} file{'s' if len(kept) != 1 else ''} that ibik did not write there "
            f"(e.g. {kept[0].rstrip('/')}) beside the new outputs; ibik replaced only the files its {MARKER} lists")


def overlay_file_names(camera_names: Sequence[str]) -> dict[str, str]:
    """Each camera's overlay video's file name: overlay_<name>.mp4, the name made usable in a file
    name (file_name_part) and numbered where two cameras would share one."""
    names: dict[str, str] = {}
    for camera in camera_names:
        stem = f"overlay_{file_name_part(camera)}"
        candidate, number = f"{stem}.mp4", 2
        while candidate in names.values():
            candidate, number = f"{stem}_{number}.mp4", number + 1
        names[camera] = candidate
    return names


def remove_leftovers(out: Path) -> list[Path]:
    """Remove what killed runs into OUTDIR `out` left beside it, where it can be proven
    theirs; returns what was removed or put back.

    - a staging folder (named by app.outdir.staging_prefix, its manifest in state "staging") whose
      process ran on this machine and is gone;
    - an earlier output set aside by a publish that was killed (named by previous_prefix, a
      complete manifest, set aside more than STALE_SECONDS ago: a publish moves in microseconds):
      put back as OUTDIR when OUTDIR is missing, else removed.
    Anything else, and the staging folders of runs still going or on other machines, stay.
    """
    handled: list[Path] = []
    staging, previous = staging_prefix(out), previous_prefix(out)
    try:
        candidates = sorted(path for path in out.parent.iterdir() if path.name.startswith((staging, previous)))
    except OSError:  # no parent folder yet
        return handled
    for path in candidates:
        try:  # another run may rename or remove any of these meanwhile: then it is not a leftover
            if path.is_symlink() or not path.is_dir():
                continue
            manifest = read_manifest(path)
            if manifest is None:
                continue
            if path.name.startswith(staging) and manifest.state == "staging" and process_is_gone(manifest):
                shutil.rmtree(path)
                handled.append(path)
            elif (path.name.startswith(previous) and manifest.state == "complete"
                  and time.time() - path.stat().st_ctime > STALE_SECONDS):  # a rename sets st_ctime
                if not os.path.lexists(out):
                    os.replace(path, out)
                else:
                    shutil.rmtree(path)
                handled.append(path)
        except OSError:
            continue
    return handled
