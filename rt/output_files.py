"""Writing output files without losing anything (recordings, CSV exports, reports).

Rules every command that writes a file follows:

* an existing output is refused unless the user passed ``--force``;
* an output that is one of the command's inputs (same file, through any path or link) is
  refused even with ``--force``: ``record export X.mcap --out X.mcap`` must not eat X;
* the data go to a temporary file beside the output, which is renamed over it only once it
  is complete: a failure (a mistyped channel, a full disk, a crash) leaves any previous file
  untouched and no half-written output. Without ``--force`` the final step is a hard link,
  which fails if the name appeared meanwhile, so a file created by someone else in between
  is not overwritten either.
"""
from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from rt.errors import InputError

#: Suffix of the temporary file an output is written to before the rename.
PARTIAL_SUFFIX = ".partial"


class OutputFileError(InputError):
    """An output file cannot be written as asked (exists, is an input, bad directory)."""


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def check_output(out: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]] = (),
                 *, force: bool = False, what: str = "output") -> Path:
    """Refuse ``out`` when it is an input, exists (unless ``force``), or cannot be created.

    Returns it as a Path. Call it before any work, so a refusal changes nothing.
    """
    path = Path(out)
    for source in inputs:
        if source is not None and _same_file(path, Path(source)):
            raise OutputFileError(f"{what} {path} is also an input ({source}): refused, it "
                                  "would destroy the input; choose another file name")
    if path.is_dir():
        raise OutputFileError(f"{what} {path} is a directory")
    if os.path.lexists(path):
        if not force:
            raise OutputFileError(f"{what} {path} exists; refused (pass --force to replace "
                                  "it once the new file is complete)")
        if not path.is_file():
            raise OutputFileError(f"{what} {path} exists and is not a regular file")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise OutputFileError(f"{what} {path}: directory {parent} does not exist")
    return path


def partial_path(out: Path) -> Path:
    """A new empty file beside ``out`` (same directory, so the rename is atomic), named
    ``OUT.<random>.partial`` so that a user finds it next to the output after a crash.
    Created with the usual permissions (mkstemp's 0600 would follow the rename)."""
    while True:
        candidate = out.with_name(f"{out.name}.{secrets.token_hex(4)}{PARTIAL_SUFFIX}")
        try:
            os.close(os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputFileError(f"cannot create a file in {out.parent}: "
                                  f"{exc.strerror or exc}") from None
        return candidate


def commit_output(partial: Path, out: Path, *, force: bool) -> None:
    """Move the complete ``partial`` file to ``out`` (see the module docstring)."""
    try:
        if force:
            os.replace(partial, out)
        else:
            os.link(partial, out)          # fails if ``out`` appeared meanwhile
            os.unlink(partial)
    except FileExistsError:
        raise OutputFileError(f"{out} appeared while it was being written; the new data are "
                              f"kept in {partial}") from None
    except OSError as exc:
        raise OutputFileError(f"cannot move {partial} to {out}: {exc.strerror or exc}; the "
                              f"data are kept in {partial}") from None


@contextlib.contextmanager
def atomic_output(out: str | os.PathLike[str], mode: str = "w", *, force: bool = False,
                  inputs: Iterable[str | os.PathLike[str]] = (), what: str = "output",
                  **open_kwargs: Any) -> Iterator[IO[Any]]:
    """Open a temporary file for writing; on success it becomes ``out``, on error it vanishes.

        with atomic_output(args.out, "w", newline="", force=args.force, inputs=[args.file]):
            ...
    """
    path = check_output(out, inputs, force=force, what=what)
    partial = partial_path(path)
    try:
        with open(partial, mode, **open_kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    commit_output(partial, path, force=force)
