"""Atomic file writing: nothing is ever half-written under its final name."""
from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator

from potflat.errors import InvalidInputError, InvalidOptionError


@contextlib.contextmanager
def atomic_path(final: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``final``; rename it to ``final`` on success.

    The temporary file lives in the same directory (same file system), so the
    rename is atomic. On any exception the temporary file is removed and ``final``
    is left as it was.
    """
    final = Path(final)
    directory = final.parent
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".part", dir=directory)
    except OSError as exc:
        raise InvalidInputError(
            f"cannot write to {directory}: {exc.strerror or exc}; choose a writable output directory"
        ) from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        # mkstemp creates 0600; give the file the permissions a plain open() would
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, final)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and exc.filename is None and exc.strerror:  # e.g. disk full: name the file
            raise OSError(exc.errno, exc.strerror, str(final)) from exc
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically and return the path."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Write ``obj`` as indented, key-sorted JSON to ``path`` atomically.

    Strict JSON has no infinity or NaN: non-finite floats (e.g. the anisotropy of a face
    flattened to a segment) are written as ``null``.
    """
    text = json.dumps(_finite(obj), indent=2, sort_keys=True, allow_nan=False, default=_json_default)
    return write_bytes_atomic(path, (text + "\n").encode("utf-8"))


def _finite(obj: Any) -> Any:
    """``obj`` with non-finite floats (also NumPy scalars) replaced by None, recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    import numpy as np

    if isinstance(obj, np.floating):
        return _finite(float(obj))
    if isinstance(obj, np.ndarray) and obj.dtype.kind == "f":
        return _finite(obj.tolist())
    return obj


def _json_default(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in JSON")


#: The lock file of an output folder (:func:`output_lock`).
LOCK_NAME = ".potflat.lock"
#: Names a scan's outputs may not take: the batch summary, manifest and error log live beside or
#: inside the scan folders (a scan named ``summary.json`` would take the summary's place).
RESERVED_NAMES = ("summary.json", "summary.csv", "manifest.json", "error.log")
#: Device names Windows reserves whatever the extension (a share mounted from Windows).
DEVICE_NAMES = ("con", "prn", "aux", "nul", *(f"com{i}" for i in range(1, 10)), *(f"lpt{i}" for i in range(1, 10)))
#: Longest output name (file systems allow 255 bytes for a whole file name, suffixes included).
MAX_NAME_BYTES = 200


def check_output_name(name: str, *, what: str = "name") -> str:
    """Return ``name`` if it is a safe output stem, else raise :class:`InvalidOptionError`.

    Safe: plain text without folder separators, control characters (a newline), a leading dot
    (``..``, hidden files) or a reserved name (:data:`RESERVED_NAMES`, :data:`DEVICE_NAMES`; without case),
    at most :data:`MAX_NAME_BYTES` bytes in UTF-8.
    """

    shown = repr(name)
    if not isinstance(name, str) or not name.strip():
        raise InvalidOptionError(f"{what} {shown} must be a plain file name (text); e.g. 'hydria-a'")
    if "/" in name or "\\" in name or name.startswith("."):
        raise InvalidOptionError(f"{what} {shown} must be a plain file name without folders or a leading dot; "
                                 "e.g. 'hydria-a'")
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        raise InvalidOptionError(f"{what} {shown} contains a control character (a newline?); rename the file "
                                 "or give a plain name")
    if name.casefold() in RESERVED_NAMES or name.split(".")[0].casefold() in DEVICE_NAMES:
        raise InvalidOptionError(f"{what} {shown} is reserved (potflat or the system uses it); give another name")
    if len(name.encode("utf-8", "surrogateescape")) > MAX_NAME_BYTES:
        raise InvalidOptionError(f"{what} is {len(name.encode('utf-8', 'surrogateescape'))} bytes long, over "
                                 f"{MAX_NAME_BYTES}; give a shorter name")
    return name


@contextlib.contextmanager
def output_lock(folder: str | os.PathLike, *, what: str = "potflat") -> Iterator[Path]:
    """Hold an exclusive lock on the output ``folder`` (created if needed) while writing.

    A second potflat process writing into the same folder is refused with one line
    (:class:`InvalidOptionError`). The lock is a ``flock`` on ``.potflat.lock`` in the folder,
    so a killed run never leaves the folder locked; the file is removed on release (and the
    folder too if this call created it and nothing was written).
    """
    import fcntl

    folder = Path(folder)
    lock = folder / LOCK_NAME
    created = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise InvalidInputError(f"cannot write to {folder}: {exc.strerror or exc}; choose a writable output "
                                "folder (-o)") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.fstat(fd).st_ino != os.stat(lock).st_ino:  # the holder removed it as we opened it
                raise OSError("lock file replaced")
        except OSError:
            try:
                holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
            except OSError:
                holder = ""
            raise InvalidOptionError(f"{folder} is in use by another potflat run{f' ({holder})' if holder else ''}; "
                                     "wait for it to finish or choose another output folder (-o)") from None
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{what} pid {os.getpid()}".encode(), 0)
        try:
            yield folder
        finally:
            with contextlib.suppress(OSError):
                lock.unlink()  # still holding the lock: a process that opened it sees a new inode
            if created:
                with contextlib.suppress(OSError):
                    folder.rmdir()  # only if empty
    finally:
        os.close(fd)


def own_subfolder(root: str | os.PathLike, folder: str | os.PathLike, *, create: bool) -> Path:
    """Check that ``folder``, a folder potflat writes in below the output folder ``root``, is
    potflat's to write in: a real folder (not a symbolic link) whose real path lies inside
    ``root``'s, or missing (then made here, without following links, if ``create``).

    Returns
    -------
    Path
        ``folder``.

    Raises
    ------
    InvalidInputError
        For a symbolic link (planted: it would send the outputs elsewhere), a file, or a folder
        outside ``root``: one line naming it and the fix.
    """
    import stat

    root, folder = Path(root), Path(folder)
    try:
        if create and not os.path.lexists(folder):
            os.mkdir(folder)  # the folder in which it is made was checked by the caller
        st = os.lstat(folder)
    except FileNotFoundError:
        return folder
    except OSError as exc:
        raise InvalidInputError(f"cannot write to {folder}: {exc.strerror or exc}; choose a writable output "
                                "folder (-o)") from None
    if stat.S_ISLNK(st.st_mode):
        raise InvalidInputError(f"{folder} is a symbolic link (to {os.readlink(folder)}); potflat writes only into "
                                "folders of its own under the output folder: remove the link or choose another "
                                "output folder (-o)")
    if not stat.S_ISDIR(st.st_mode):
        raise InvalidInputError(f"{folder} is not a folder; remove it or choose another output folder (-o)")
    if folder.resolve().parent != root.resolve():
        raise InvalidInputError(f"{folder} lies outside {root}; choose another output folder (-o)")
    return folder


def remove_stale_parts(folder: str | os.PathLike) -> int:
    """Remove the hidden ``.NAME.*.part`` temporaries a killed run left in ``folder``.

    Call it only while holding :func:`output_lock` (no other potflat process writes there).
    Returns how many were removed.
    """
    folder = Path(folder)
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return 0
    for entry in entries:
        if entry.name.startswith(".") and entry.name.endswith(".part") and entry.is_file(follow_symlinks=False):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)
                removed += 1
    return removed
