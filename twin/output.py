"""Output folders a user can trust: twin replaces only what it wrote, and only once the new output is complete.

Each output folder carries a manifest (`.twin-output.json`) listing the files twin wrote there. A
later build into the same folder stages its files in a temporary folder beside it, and only when
everything is written does it swap them in: the files of the previous manifest and those it is about
to replace are set aside, the new ones moved in, and the set-aside ones removed last (or moved back if
the swap fails). Files twin did not write are never touched. A folder that is neither empty nor a twin
output is refused unless the user passes --force, which lets twin write beside what is there; a file of
the user's that bears one of the names twin would write stops the swap before anything moves.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

MANIFEST = ".twin-output.json"
MANIFEST_SCHEMA = "twin.output/1"
_LEGACY_FILES = ("asset.json", "report.html", "meshes")
"""What an output written before the manifest existed holds besides its asset.json's `files`."""


INTERRUPTED = threading.Event()
"""Set by the command line's Ctrl-C/SIGTERM handler. Python only prints an interrupt raised inside a callback
(a weak reference's, an import lock's), so the build may run on; this flag still keeps its output out."""


class OutputError(ValueError):
    """OUT cannot be written safely; the message names it and says what to do."""


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def written_by_twin(out: Path, made_by: str = "build") -> tuple[str, ...] | None:
    """The relative paths `twin <made_by>` wrote into `out`, or None when `out` is not such an output.

    A folder is ours when it holds our manifest naming that command, or (outputs from before the manifest)
    an asset.json of our schema, whose `files` and the fixed names around them are what a build wrote. A
    sample made by `twin synth` is a build's input, never an output a build may replace.
    """
    manifest = out / MANIFEST
    if manifest.is_file():
        try:
            doc = json.loads(manifest.read_text())
            if (doc.get("schema") == MANIFEST_SCHEMA and doc.get("made_by", "build") == made_by
                    and all(isinstance(f, str) for f in doc["files"])):
                return tuple(doc["files"])
            return None
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass
    asset = out / "asset.json"
    if asset.is_file():
        try:
            doc = json.loads(asset.read_text())
        except (OSError, ValueError):
            return None
        if isinstance(doc, dict) and doc.get("schema") == "twin.asset/1":
            files = doc.get("files") if isinstance(doc.get("files"), dict) else {}
            return tuple(sorted({*_LEGACY_FILES, *(v for v in files.values() if isinstance(v, str))}))
    return None


def check_output(out: Path, force: bool = False, replace_own: bool = True, made_by: str = "build") -> Path:
    """The absolute OUT, or OutputError when it cannot be written without losing a user's file.

    Decided before any work starts: OUT must be a folder (or not exist), its parent writable, and an
    existing non-empty folder either a twin output (when `replace_own`) or accepted with --force.
    """
    out = Path(os.path.abspath(out))
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder; -o needs a folder to write the outputs into")
    if out.is_dir():
        if not os.access(out, os.W_OK | os.X_OK):
            raise OutputError(f"{out}: folder is not writable")
        if not force and any(out.iterdir()) and not replace_own:
            raise OutputError(f"{out}: folder exists and is not empty; choose a new folder, or pass --force to "
                              f"replace what twin wrote there (nothing else is removed)")
        if not force and any(out.iterdir()) and written_by_twin(out, made_by) is None:
            raise OutputError(f"{out}: folder holds files twin did not write; choose an empty or new folder, "
                              f"or pass --force to write beside them (nothing of yours is removed)")
    ancestor = out.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    try:  # a real write, not os.access: root passes access() where the filesystem still refuses (/proc)
        os.rmdir(tempfile.mkdtemp(prefix=".twin-probe-", dir=ancestor))
    except OSError as exc:
        raise OutputError(f"{out}: cannot create it ({ancestor} is not a writable folder: "
                          f"{exc.strerror or exc})") from None
    if out == out.parent:
        raise OutputError(f"{out}: the filesystem root cannot be an output folder")
    return out


@contextmanager
def staged_output(out: Path, force: bool = False, replace_own: bool = True, made_by: str = "build"):
    """Yields a temporary folder beside `out` to write into; on success its files replace twin's own in
    `out` (see the module docstring). The temporary folder is removed on every exit, error or interrupt."""
    out = check_output(out, force, replace_own, made_by)
    out.parent.mkdir(parents=True, exist_ok=True, mode=0o777)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.twin-", dir=out.parent))
    try:
        tmp.chmod(0o777 & ~_umask())  # mkdtemp makes it private; the output should follow the user's umask
        yield tmp
        if INTERRUPTED.is_set():
            raise KeyboardInterrupt
        _swap_in(tmp, out, force, made_by)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() or p.is_symlink())


def _swap_in(tmp: Path, out: Path, force: bool, made_by: str) -> None:
    new = _files(tmp)
    (tmp / MANIFEST).write_text(json.dumps({"schema": MANIFEST_SCHEMA, "made_by": made_by, "files": new},
                                           indent=1) + "\n")
    if not out.exists():
        tmp.rename(out)
        return
    previous = written_by_twin(out, made_by)
    if previous is None and any(out.iterdir()) and not force:  # something appeared since the check
        raise OutputError(f"{out}: folder now holds files twin did not write; nothing was changed")
    clashes = [rel for rel in [*new, MANIFEST] if (out / rel).exists() or (out / rel).is_symlink()
               if not _owned(rel, previous)]
    if clashes:  # even --force never replaces a file of the user's that bears one of twin's names
        raise OutputError(f"{out / clashes[0]}: exists and twin did not write it; nothing was changed "
                          f"(move it, or choose another folder)")
    aside = Path(tempfile.mkdtemp(prefix=f".{out.name}.twin-old-", dir=out.parent))
    moved: list[str] = []
    try:
        for rel in sorted({*(previous or ()), *new, MANIFEST}):
            src = out / rel
            if (src.exists() or src.is_symlink()) and _inside(src, out):
                (aside / rel).parent.mkdir(parents=True, exist_ok=True)
                src.rename(aside / rel)
                moved.append(rel)
        for rel in [*new, MANIFEST]:
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            (tmp / rel).rename(out / rel)
    except BaseException:
        for rel in [*new, MANIFEST]:
            if (out / rel).exists() and not (tmp / rel).exists():
                (out / rel).rename(tmp / rel)
        for rel in moved:
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            (aside / rel).rename(out / rel)
        raise
    finally:
        shutil.rmtree(aside, ignore_errors=True)
    _remove_empty_dirs(out, previous or ())


def _owned(rel: str, previous: tuple[str, ...] | None) -> bool:
    """Whether `rel` is (or lies in a folder that is) one of the files the previous output listed."""
    if previous is None:
        return False
    return rel == MANIFEST or any(rel == p or rel.startswith(p.rstrip("/") + "/") for p in previous)


def _inside(path: Path, root: Path) -> bool:
    """A manifest entry such as '../x' or an absolute path must never reach outside the output."""
    try:
        Path(os.path.abspath(path)).relative_to(root)
        return True
    except ValueError:
        return False


def _remove_empty_dirs(out: Path, previous: tuple[str, ...]) -> None:
    """Folders twin made for its previous files (meshes/) go when nothing is left in them."""
    parents = {(out / rel).parent for rel in previous} | {out / rel for rel in previous}
    for folder in sorted(parents, key=lambda p: len(p.parts), reverse=True):
        if folder != out and folder.is_dir() and _inside(folder, out) and not any(folder.iterdir()):
            folder.rmdir()
