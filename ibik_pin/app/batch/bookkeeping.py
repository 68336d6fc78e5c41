"""OUTROOT's bookkeeping: which folder a batch may write, which trials are complete, and the
leftovers of killed runs that it removes.

OUTROOT carries a marker (:data:`BATCH_MARKER`, JSON) written by the first batch into it. A batch
refuses an OUTROOT that is ROOT, lies inside ROOT or holds it (the outputs would be mixed with the
trials, or become trials), or an existing folder without the marker that is not empty: the user's.
An OUTROOT of an earlier version of ibik (no marker, but a summary.csv whose header is the batch's
own) is taken as the batch's and gets the marker.

Leftovers of killed runs beside a trial's OUTDIR are removed by app.outdir.remove_leftovers.
A trial is complete when its OUTDIR's manifest (app.manifest) lists every output the batch expects
and every listed file is there with its size; an old plain-text marker needs the files present.
"""

from __future__ import annotations

import json
from pathlib import Path

from ibik_pin.app.manifest import read_manifest
from ibik_pin.app.outdir import OutputFolderError, remove_leftovers
from ibik_pin.io.files import write_text_atomically

__all__ = ["BATCH_MARKER", "SUMMARY_HEADER_START", "check_outroot", "claim_outroot", "missing_outputs",
           "remove_leftovers"]

BATCH_MARKER = ".ibik_batch"
SUMMARY_HEADER_START = "trial,status,frames,frame_rate_hz,solve_fps"


def _is_ours(outroot: Path) -> bool:
    try:
        content = json.loads((outroot / BATCH_MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(content, dict) and content.get("written_by") == "ibik_pin"


def _earlier_version_outroot(outroot: Path) -> bool:
    try:
        with open(outroot / "summary.csv", encoding="utf-8") as stream:
            return stream.readline().startswith(SUMMARY_HEADER_START)
    except (OSError, UnicodeDecodeError):
        return False


def check_outroot(root: Path, outroot: Path, given: str) -> None:
    """Refuse an OUTROOT (absolute, resolved) that a batch on ROOT must not write.

    Raises:
        OutputFolderError: OUTROOT is ROOT, inside it, holds it, is a file, or is a non-empty folder
            that no batch made.
    """
    if outroot == root:
        raise OutputFolderError(f"--out {given}: must not be ROOT (the outputs would replace the trials)")
    if root in outroot.parents:
        raise OutputFolderError(f"--out {given}: lies inside ROOT {root}, among the trials it would track; "
                                "choose a folder outside ROOT")
    if outroot in root.parents:
        raise OutputFolderError(f"--out {given}: holds ROOT {root}; choose a folder outside it")
    if outroot.exists() and not outroot.is_dir():
        raise OutputFolderError(f"--out {given}: is an existing file, not a folder")
    if outroot.is_dir() and not _is_ours(outroot) and not _earlier_version_outroot(outroot) and any(outroot.iterdir()):
        raise OutputFolderError(f"--out {given}: the folder holds files that no ibik batch wrote (no {BATCH_MARKER} "
                                "in it); choose a new folder or empty this one")


def claim_outroot(outroot: Path, root: Path) -> None:
    """Create OUTROOT if needed and mark it as a batch's (kept when already marked)."""
    try:
        outroot.mkdir(parents=True, exist_ok=True)
        if not _is_ours(outroot):
            write_text_atomically(outroot / BATCH_MARKER, json.dumps(
                {"written_by": "ibik_pin", "batch": 1, "root": str(root)}, indent=1) + "\n")
    except OSError as error:
        raise OutputFolderError(f"--out {outroot}: cannot create it: {error.strerror or error}") from None


def missing_outputs(out: Path, expected: tuple[str, ...]) -> str | None:
    """Why the trial's OUTDIR `out` is not a complete output (a short phrase), or None when it is."""
    manifest = read_manifest(out)
    if manifest is None:
        return "no output"
    if manifest.files is None:  # an earlier version's marker: the files alone
        absent = [name for name in expected if not (out / name).is_file()]
        return f"{absent[0]} is missing" if absent else None
    unlisted = [name for name in expected if name not in manifest.files]
    if unlisted:
        return f"{unlisted[0]} was not written"
    for name, size in manifest.files.items():
        try:
            found = (out / name).lstat().st_size
        except OSError:
            return f"{name} is missing"
        if found != size:
            return f"{name} is {found} bytes, {size} when written"
    return None
