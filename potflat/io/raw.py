"""What a scan reader gives (:class:`_Raw`: arrays as the file holds them) and the helpers
the readers share."""
from __future__ import annotations

import hashlib
import json
import tempfile
import warnings as _warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError, out_of_memory
from potflat.io.atomic import atomic_path
from potflat.io.images import check_texture_budget


@dataclass
class _Raw:
    """What a format reader found (before validation and welding)."""

    vertices: np.ndarray
    faces: np.ndarray
    texcoords: np.ndarray | None = None
    untextured: np.ndarray | None = None  # (m,) bool: faces without texture coordinates
    texture: Path | None = None
    colors: np.ndarray | None = None
    units: str | None = None
    polygons_triangulated: int = 0
    warnings: list[str] = field(default_factory=list)


def _triangulate(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Fan-triangulate polygons given their corner counts.

    Returns the corner indices (t, 3) into the flat corner arrays, the polygon of each
    triangle, the number of polygons with more than three corners and of those with fewer
    than three (dropped).
    """
    lengths = np.asarray(lengths, dtype=np.int64)
    if (lengths == 3).all():
        m = len(lengths)
        return np.arange(3 * m).reshape(m, 3), np.arange(m), 0, 0
    start = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    ntri = np.maximum(lengths - 2, 0)
    poly = np.repeat(np.arange(len(lengths)), ntri)
    first = np.cumsum(ntri) - ntri
    j = np.arange(len(poly)) - np.repeat(first, ntri) + 1
    c0 = start[poly]
    corners = np.stack([c0, c0 + j, c0 + j + 1], axis=1)
    return corners, poly, int(np.count_nonzero(lengths > 3)), int(np.count_nonzero(lengths < 3))


#: A file read whole takes its bytes and what is parsed from them at once: at least this many
#: times its size.
READ_WHOLE_FACTOR = 2


def memory_limit() -> int | None:
    """Bytes this process may use at most, or None when nothing says: the smallest of its
    address-space and data limits (``ulimit -v``, ``-d``), its control group's memory limit
    (a container's or a cluster job's) and the memory the machine has available now
    (``MemAvailable``: free and reclaimable; more would swap, or wake the kernel's
    out-of-memory killer, which ends the run without a word and may end other jobs)."""
    import resource

    found = []
    for which in (resource.RLIMIT_AS, resource.RLIMIT_DATA):
        soft = resource.getrlimit(which)[0]
        if soft != resource.RLIM_INFINITY:
            found.append(soft)
    for name in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            found.append(int(Path(name).read_text().split()[0]))
        except (OSError, ValueError, IndexError):  # absent, or "max"
            continue
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    return min(found) if found else None


def _gib(n: int) -> str:
    return f"{n / 1024**3:.1f} GiB" if n >= 1024**3 else f"{n / 1024**2:.0f} MiB"


def _check_fits_memory(path: Path, what: str = "a scan", limit: int | None = None) -> None:
    """Refuse, before reading, a file read whole that cannot fit: larger than ``limit`` (what a
    file of its kind ever is), or :data:`READ_WHOLE_FACTOR` times its size more than
    :func:`memory_limit` (a 20 GB file, sparse or not, on a 24 GB machine)."""
    try:
        size = path.stat().st_size
    except OSError:
        return  # the reader says why it cannot read it
    if limit is not None and size > limit:
        raise InvalidInputError(f"{path} is {_gib(size)}, too large for {what} (at most {_gib(limit)}); "
                                "check that it is the right file")
    budget = memory_limit()
    if budget is not None and size * READ_WHOLE_FACTOR > budget:
        raise InvalidInputError(f"{path} is {_gib(size)}; reading {what} takes at least {READ_WHOLE_FACTOR} times "
                                f"its size, more than the {_gib(budget)} of memory potflat may use here; give a "
                                "smaller file (decimate the scan) or run where more memory is available")


def _read_bytes(path: Path, what: str = "a scan", limit: int | None = None) -> bytes:
    """The bytes of a file read whole (``what`` it is, for the messages), after
    :func:`_check_fits_memory`; running out of memory while reading is one line too."""
    _check_fits_memory(path, what, limit)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read {path}: {exc.strerror or exc}; check permissions") from None
    except MemoryError:
        raise out_of_memory(path) from None


def _text(data: bytes) -> str:
    """Names and lines written by other programs: UTF-8, else Latin-1 (older Windows exports)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _colors_to_u8(cols: np.ndarray) -> np.ndarray:
    cols = np.asarray(cols, dtype=np.float64)
    if np.issubdtype(cols.dtype, np.floating) and np.nanmax(cols, initial=0.0) <= 1.0:
        cols = cols * 255.0
    return np.clip(np.nan_to_num(np.rint(cols)), 0, 255).astype(np.uint8)


def _find_file(name: str, *dirs: Path) -> Path:
    """Resolve a file name written by another program: relative to ``dirs[0]``, absolute,
    Windows-style (backslashes, another machine's folders: the base name is looked up in
    ``dirs``), or differing in letter case (exports made on Windows)."""
    name = name.strip().strip('"')
    cand = Path(name.replace("\\", "/"))
    tried = [cand if cand.is_absolute() else dirs[0] / cand]
    tried += [d / cand.name for d in dirs]
    for p in tried:
        if p.is_file():
            return p
    for d in dirs:
        try:
            match = sorted(p for p in d.iterdir() if p.name.lower() == cand.name.lower() and p.is_file())
        except OSError:
            continue
        if match:
            return match[0]
    return tried[0]


def _first_line(exc: BaseException) -> str:
    """What a reader's exception says, in one line (its type when it says nothing): the
    libraries potflat reads with raise many types, with messages of any length."""
    text = str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


@contextmanager
def _decoding(failure: Callable[[str], str]) -> Iterator[None]:
    """Decode images with Pillow without its own pixel limit (the caller has checked its
    limit), what Pillow raises for a corrupt image turned into :class:`InvalidInputError`
    with the message ``failure(reason)``."""
    from PIL import Image

    old = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None
    try:
        yield
    except InvalidInputError:
        raise
    except Exception as exc:  # noqa: BLE001 - Pillow raises many types for corrupt images
        raise InvalidInputError(failure(_first_line(exc))) from None
    finally:
        Image.MAX_IMAGE_PIXELS = old


def _flag_untextured(raw: _Raw, untextured: np.ndarray, why: str) -> None:
    """Record the faces ``untextured`` ((m,) bool) of a textured scan that have no texture
    coordinates (their coordinates are zeros that mean nothing), with the load warning."""
    count = int(untextured.sum())
    if count:
        raw.untextured = untextured
        raw.warnings.append(f"{count} faces {why}; they are drawn as untextured surface (its relief in grey) "
                            "and left out of the painted-zone detection")


def _truncated(path: Path, element: str) -> InvalidInputError:
    return InvalidInputError(f"{path} is truncated ({element} data incomplete); "
                             "the file is cut short: copy or export it again")


#: The way out of a texture problem, in the command line's words (the API's ``texture="ignore"``).
_IGNORE_HINT = "or pass --no-texture to load it untextured"


def _texture_cache() -> Path:
    """Folder for generated textures (packed atlases, images extracted from GLB): private to this
    process (made by :func:`tempfile.mkdtemp`: new, mode 0700, never a pre-existing folder or a
    planted symlink), removed when the process ends. Nothing found there is ever trusted: every
    file in it was written by this process."""
    if not _PRIVATE_CACHE or not _PRIVATE_CACHE[0].is_dir():
        import atexit
        import shutil

        folder = Path(tempfile.mkdtemp(prefix="potflat-textures-"))
        atexit.register(shutil.rmtree, folder, ignore_errors=True)
        _PRIVATE_CACHE[:] = [folder]
    return _PRIVATE_CACHE[0]


def _cached_png(sources: list[Path]) -> Path:
    """Where a PNG made from the image files ``sources`` goes in :func:`_texture_cache`: named by
    their paths, sizes and modification times (so it is made once per process)."""
    key = json.dumps([[str(p), p.stat().st_size, p.stat().st_mtime_ns] for p in sources]).encode()
    return _texture_cache() / (hashlib.sha256(key).hexdigest()[:32] + ".png")


#: Image formats (as Pillow names them) that OpenCV, which decodes the textures, reads: a
#: texture in another format Pillow reads (TGA, DDS, PSD ...) is converted to PNG on loading.
OPENCV_FORMATS = frozenset({"PNG", "JPEG", "MPO", "TIFF", "BMP", "WEBP", "JPEG2000", "PPM", "GIF"})


def _merge_textures(paths: list[Path], which: np.ndarray, uv: np.ndarray, source: Path,
                    max_pixels: int, *, names: list[str] | None = None) -> tuple[Path, np.ndarray, str]:
    """Pack several texture images into one atlas (a grid) and remap the texture coordinates.

    Parameters
    ----------
    paths : list of Path
        The images, in the order of the indices in ``which``.
    which : (m,) int64
        Image of each face, -1 for none (those keep their coordinates).
    uv : (m, 3, 2) float64
        Texture coordinates in each face's own image (OBJ convention, v up).
    names : list of str, optional
        What the report line calls the images (default: their file names).

    Returns
    -------
    atlas : Path
        PNG in :func:`_texture_cache`, named by the sources' paths, sizes
        and modification times (made once per process).
    uv : (m, 3, 2) float64
        Coordinates in the atlas (clipped to each image: tiling cannot be packed).
    note : str
        Report line.
    """
    from PIL import Image

    checked = [_check_texture(p, source, max_pixels) for p in paths]
    paths = [p for p, _ in checked]
    sizes = [size for _, size in checked]
    cols = int(np.ceil(np.sqrt(len(paths))))
    rows = int(np.ceil(len(paths) / cols))
    cw, ch = max(w for w, _ in sizes), max(h for _, h in sizes)
    W, H = cols * cw, rows * ch
    if W * H > max_pixels:
        raise InvalidInputError(f"{source}: its {len(paths)} texture images would make a {W} x {H} atlas, over "
                                f"the limit of {max_pixels} pixels; re-export with one texture {_IGNORE_HINT}")
    target = _cached_png(paths)
    if not target.exists():  # (sizes were checked against max_pixels above)
        with _decoding(lambda why: f"{source}: its texture images cannot be decoded ({why}); restore them "
                                   f"{_IGNORE_HINT}"):
            modes = []
            for p in paths:
                with Image.open(p) as im:
                    modes.append(im.mode)
            mode = "RGBA" if any("A" in m for m in modes) else "RGB"
            atlas = Image.new(mode, (W, H))
            for k, p in enumerate(paths):
                r, c = divmod(k, cols)
                with Image.open(p) as im:
                    atlas.paste(im.convert(mode), (c * cw, r * ch))
            with atomic_path(target) as tmp:
                atlas.save(tmp, format="PNG", compress_level=1)
    out = uv.copy()
    sel = which >= 0
    k = which[sel]
    r, c = np.divmod(k, cols)
    w = np.array([s[0] for s in sizes], float)[k]
    h = np.array([s[1] for s in sizes], float)[k]
    t = np.clip(uv[sel], 0.0, 1.0)
    clipped = int(np.count_nonzero((t != uv[sel]).any(axis=(1, 2))))
    out[sel, :, 0] = (c[:, None] * cw + t[..., 0] * w[:, None]) / W
    out[sel, :, 1] = 1.0 - (r[:, None] * ch + (1.0 - t[..., 1]) * h[:, None]) / H
    names = [p.name for p in paths] if names is None else names
    note = (f"{len(paths)} texture images ({', '.join(names[:4])}{', ...' if len(paths) > 4 else ''}) packed into "
            f"one {W} x {H} atlas")
    if clipped:
        note += f"; {clipped} faces had texture coordinates outside their image (clipped)"
    return target, out, note


def _check_texture(tex: Path, source: Path, max_pixels: int) -> tuple[Path, tuple[int, int]]:
    """Check that ``tex`` is a readable image within ``max_pixels`` (header only); return
    its absolute path (a PNG made from it when OpenCV does not read its format,
    :data:`OPENCV_FORMATS`) and its (width, height)."""
    from PIL import Image

    try:
        tex = tex.resolve()
    except RuntimeError:  # a symlink loop (Python < 3.13 raises it here)
        raise InvalidInputError(f"{source}: texture {tex} is a symbolic link loop; restore the file "
                                f"{_IGNORE_HINT}") from None
    except ValueError:  # a name with a NUL character (a corrupt file)
        raise InvalidInputError(f"{source}: its texture's name {str(tex)!r} is no file name (the file is corrupt); "
                                f"export the scan again {_IGNORE_HINT}") from None
    if not tex.is_file():
        raise InvalidInputError(f"{source}: texture {tex} not found; restore the file {_IGNORE_HINT}")
    # (our own limit below, without Pillow's lower default)
    with _decoding(lambda why: f"{source}: texture {tex.name} is not a readable image ({why}); restore the file "
                               f"{_IGNORE_HINT}"), _warnings.catch_warnings():
        _warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        with Image.open(tex) as im:
            w, h = im.size
            if w <= 0 or h <= 0 or w * h > max_pixels:
                raise InvalidInputError(
                    f"{source}: texture {tex.name} declares {w} x {h} pixels, over the limit of "
                    f"{max_pixels} (a corrupt file or decompression bomb); restore a sane image "
                    f"{_IGNORE_HINT}")
            try:
                check_texture_budget(tex, w, h, im.mode)
            except InvalidInputError as exc:
                raise InvalidInputError(f"{source}: {exc}, {_IGNORE_HINT}") from None
            if im.format == "PNG":
                im.verify()  # chunk CRCs, without decoding pixels
            readable = im.format in OPENCV_FORMATS
    if not readable:
        target = _cached_png([tex])
        if not target.exists():
            with _decoding(lambda why: f"{source}: texture {tex.name} cannot be decoded ({why}); convert it to "
                                       f"PNG or JPEG {_IGNORE_HINT}"), Image.open(tex) as im:
                rgb = im.convert("RGBA" if "A" in im.getbands() else "RGB")
                with atomic_path(target) as tmp:
                    rgb.save(tmp, format="PNG", compress_level=1)
        tex = target
    return tex, (w, h)


_PRIVATE_CACHE: list[Path] = []
