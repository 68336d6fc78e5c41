"""The manifest of an output folder: which of its files ibik wrote, so that a later run replaces
those and nothing else.

The manifest is the output folder's marker file (:data:`MARKER`), a JSON object::

    {"written_by": "ibik_pin", "manifest": 1, "state": "complete",
     "files": {"joints.trc": 48213, ...}, "kept_user_files": ["notes.txt"], "host": "...", "pid": 1234}

`files` maps each path ibik wrote (relative, "/"-separated) to its size in bytes, so that a batch
can tell a complete output from one a user or a crash cut short; `kept_user_files`, the user's
paths a run carried over from the earlier output (never ours: a later run keeps them too).
`state` is "staging" while a run writes into its staging folder (with the writing process's host
and pid, so that a leftover of a killed run can be told from a run still going) and "complete"
once published.

An earlier version wrote the marker as one line of plain text and no list. Such a folder is read
conservatively: only the names ibik's outputs have (:data:`KNOWN_OUTPUTS`, ``overlay_*.mp4``) are
taken as ours; every other file is the user's and is kept.
"""

from __future__ import annotations

import fnmatch
import json
import os
import socket
from dataclasses import dataclass
from pathlib import Path

from ibik_pin.io.files import write_text_atomically

__all__ = ["KNOWN_OUTPUTS", "MARKER", "Manifest", "has_an_output_name", "listed_files", "process_is_gone",
           "read_manifest", "user_paths", "write_manifest"]

#: The file every output folder of ``ibik track`` holds: its manifest, and what tells it apart from
#: the user's folders.
MARKER = ".ibik_output"
MANIFEST_VERSION = 1
WRITTEN_BY = "ibik_pin"
#: Every name `ibik track` may write into OUTDIR (app.outputs, app.video_inputs), and its overlays'.
KNOWN_OUTPUTS = frozenset({"joints.trc", "q.csv", "motion.mot", "motion.bvh", "model.osim", "report.json",
                           "residuals.png", "angles.png", "replay.html", "triangulated.trc",
                           "calibration_refitted.toml", "limb_targets_stack.toml"})
KNOWN_PATTERNS = ("overlay_*.mp4",)


@dataclass
class Manifest:
    """An output folder's marker, read.

    Attributes:
        files: relative path -> size [bytes] of what ibik wrote; None for an old plain-text marker.
        state: "staging" (a run is writing, or was killed while writing) or "complete".
        host, pid: the machine and process that made a staging folder ("" and 0 when not recorded).
    """

    files: dict[str, int] | None
    state: str = "complete"
    host: str = ""
    pid: int = 0


def read_manifest(folder: Path) -> Manifest | None:
    """The manifest of `folder`, or None when it has no marker (not an output of ibik)."""
    path = folder / MARKER
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        return None
    try:
        content = json.loads(text)
    except ValueError:
        content = None
    if not isinstance(content, dict) or content.get("written_by") != WRITTEN_BY:
        return Manifest(files=None)  # the plain-text marker of earlier versions
    files = content.get("files")
    listed = ({str(name): int(size) for name, size in files.items() if isinstance(size, int)}
              if isinstance(files, dict) else None)
    return Manifest(files=listed, state=str(content.get("state", "complete")), host=str(content.get("host", "")),
                    pid=int(content.get("pid", 0)) if isinstance(content.get("pid"), int) else 0)


def write_manifest(folder: Path, state: str, files: dict[str, int] | None = None,
                   kept: list[str] | None = None) -> None:
    """Write `folder`'s marker: in state "staging" with this process's host and pid, or "complete"
    with the files listed, and the user's paths kept from the earlier output (`kept`, not ours)."""
    content: dict = {"written_by": WRITTEN_BY, "manifest": MANIFEST_VERSION, "state": state,
                     "files": dict(sorted((files or {}).items()))}
    if kept:
        content["kept_user_files"] = sorted(kept)
    if state == "staging":
        content |= {"host": socket.gethostname(), "pid": os.getpid()}
    write_text_atomically(folder / MARKER, json.dumps(content, indent=1) + "\n")


def has_an_output_name(relative: str) -> bool:
    """Whether a path in OUTDIR has the name of something ibik writes there (at its top level)."""
    return relative in KNOWN_OUTPUTS or any(fnmatch.fnmatchcase(relative, pattern) for pattern in KNOWN_PATTERNS)


def _entries(folder: Path) -> list[str]:
    """Every file, link and empty folder under `folder` (not following links), relative, "/"-separated."""
    found = []
    for current, folders, files in os.walk(folder):
        here = Path(current)
        for name in list(folders):
            if (here / name).is_symlink():
                files.append(name)  # a link to a folder is kept as a link, never walked
                folders.remove(name)
        found += [(here / name).relative_to(folder).as_posix() for name in files]
        if here != folder and not folders and not files:
            found.append(here.relative_to(folder).as_posix() + "/")
    return sorted(found)


def listed_files(folder: Path) -> dict[str, int]:
    """What a staging folder holds, to list in its manifest: relative path -> size (the marker aside)."""
    return {name: (folder / name).lstat().st_size for name in _entries(folder)
            if name != MARKER and not name.endswith("/")}


def user_paths(folder: Path) -> list[str]:
    """The paths in an output folder that ibik did not write: not listed in its manifest (for an
    old marker, not named as an output); empty folders end with "/"."""
    manifest = read_manifest(folder)
    ours = set() if manifest is None else set(manifest.files or ())
    return [name for name in _entries(folder) if name != MARKER and name not in ours
            and not (manifest is not None and manifest.files is None and has_an_output_name(name))]


def process_is_gone(manifest: Manifest) -> bool:
    """Whether the process that made a staging folder has certainly ended: it ran on this machine
    and no process has its id now (a reused id reads as alive: the folder is then left alone)."""
    if manifest.host != socket.gethostname() or manifest.pid <= 0:
        return False
    try:
        os.kill(manifest.pid, 0)
    except ProcessLookupError:
        return True
    except OSError:  # it exists, owned by another user
        return False
    return False
