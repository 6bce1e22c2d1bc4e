"""Image files of the bake stage: texture reading, streamed PNG and TIFF writing with resolution.

PNGs are written by a small streaming encoder (Paeth filter, deflate by zlib-ng, ``pHYs``
chunk in pixels per metre) so an image of several hundred megapixels never has to sit in
memory twice: Pillow can only save a whole image at once. zlib-ng deflates the distortion
maps 2.5x faster than zlib at the same level, into files of the same size (its bytes differ
from zlib's; the version is recorded in every sidecar's provenance). Files are read back
with Pillow in the tests. TIFFs are written by :mod:`tifffile` from a row iterator. All
writes are atomic.
"""
from __future__ import annotations

import contextlib
import os
import struct
import threading
import zlib
from collections.abc import Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Self

import numpy as np
from zlib_ng import zlib_ng

from potflat.errors import InvalidInputError
from potflat.io._kernels.ply_png import paeth_filter
from potflat.io.atomic import atomic_path

#: Deflate level of the PNG encoder (6 is libpng's default; 9 is much slower for ~2% less).
PNG_COMPRESSION = 6
#: Deflate level above :data:`PNG_LARGE_PIXELS`. The seven images of a 6.8 MP bake (1M-vertex
#: benchmark vessel, 178 MB filtered), zlib-ng: level 6 in 2.5 s of CPU for 22.3 MB, level 3 in
#: 0.9 s for 23.6 MB (+6%), level 1 in 0.5 s for 39.6 MB (zlib itself: 8.3 s at level 6).
PNG_COMPRESSION_LARGE = 3
PNG_LARGE_PIXELS = 4_000_000
#: Filtered row blocks a PNG writer may queue for its compression thread.
PNG_QUEUE = 2

_PNG_COLOR_TYPE = {1: 0, 2: 4, 3: 2, 4: 6}  # channels -> grey, grey+alpha, RGB, RGBA


#: Memory a decoded texture may take (RGB, 8 or 16 bits per channel): 2 GiB, a 26k x 26k
#: 8-bit image. Larger textures are refused before decoding, with their size and the fix.
TEXTURE_BUDGET_BYTES = 2 * 1024**3


def check_texture_budget(path: str | os.PathLike, width: int, height: int, mode: str) -> None:
    """Refuse a texture whose decoded RGB image would exceed :data:`TEXTURE_BUDGET_BYTES`.

    Parameters
    ----------
    path : path-like
        The image (for the message).
    width, height : int
        Its size in pixels, from the file's header.
    mode : str
        Its Pillow mode (``"RGB"``, ``"I;16"``...): 16-bit modes take two bytes per channel.
    """
    depth = 2 if ("16" in mode or mode in ("I", "F")) else 1
    need = width * height * 3 * depth
    if need > TEXTURE_BUDGET_BYTES:
        side = int((TEXTURE_BUDGET_BYTES / (3 * depth)) ** 0.5) // 1024 * 1024
        raise InvalidInputError(
            f"texture {Path(path).name} is {width} x {height} pixels ({need / 1024**3:.1f} GiB decoded), over the "
            f"{TEXTURE_BUDGET_BYTES / 1024**3:.0f} GiB memory budget for a texture; downsample it to at most "
            f"{side} x {side} pixels")


def read_texture(path: str | os.PathLike) -> np.ndarray:
    """Read a texture image as RGB, within :data:`TEXTURE_BUDGET_BYTES`.

    Inside a :func:`read_ahead` block of the same file (unchanged since), the image decoded
    ahead in the background is taken (waiting for it if need be) instead of decoding it again.

    Parameters
    ----------
    path : path-like
        Any image OpenCV reads (PNG, JPEG, TIFF, ...), 8 or 16 bits per channel.

    Returns
    -------
    (h, w, 3) uint8 or uint16
        Row 0 is the top of the image. An alpha channel is dropped; grey is expanded to RGB.
        Decoded straight to three channels: the peak memory is the returned image.

    Raises
    ------
    InvalidInputError
        When the file is missing, over the budget or not an image.
    """
    ahead = _take_ahead("rgb", path)
    return ahead.result() if ahead is not None else _decode_texture(path)


def check_texture_file(path: str | os.PathLike) -> None:
    """Raise :class:`InvalidInputError` when the texture a stage PLY names is not a file."""
    if not Path(path).is_file():
        raise InvalidInputError(f"texture {path} not found; put the texture image beside the stage PLY")


#: Textures :func:`check_texture_image` decoded, by (file, its mtime, its size).
_DECODED: set[tuple] = set()


def check_texture_image(path: str | os.PathLike) -> None:
    """Raise :class:`InvalidInputError` unless the texture at ``path`` is an image that decodes
    (within :data:`TEXTURE_BUDGET_BYTES`): checked before a texture is copied beside a stage
    file, so nothing but an image is ever copied. The decode is OpenCV's reduced read (an eighth
    of the size, in grey: a JPEG is decoded at that size) for an image of at least 64 pixels a
    side; a file once decoded, unchanged since, is not decoded again in this process.
    """
    import cv2
    from PIL import Image

    check_texture_file(path)
    key = _ahead_key("decoded", path)
    if key in _DECODED:
        return
    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None  # the budget below is the limit
        with Image.open(path) as im:
            width, height, mode = *im.size, im.mode
    except Exception:  # noqa: BLE001 - Pillow raises many types for what is not an image
        raise InvalidInputError(f"texture {path} is not an image; put the scan's texture image (PNG, JPEG...) "
                                "beside the stage PLY") from None
    finally:
        Image.MAX_IMAGE_PIXELS = old
    check_texture_budget(path, width, height, mode)
    try:
        img = cv2.imread(str(path), cv2.IMREAD_REDUCED_GRAYSCALE_8 if min(width, height) >= 64 else
                         cv2.IMREAD_GRAYSCALE)
    except cv2.error:
        img = None
    if img is None or not img.size:
        raise InvalidInputError(f"texture {path} does not decode as an image (corrupt or cut short); restore "
                                "the scan's texture image")
    _DECODED.add(key)


def _decode_texture(path: str | os.PathLike) -> np.ndarray:
    """:func:`read_texture` without the read-ahead."""
    import cv2
    from PIL import Image

    path = Path(path)
    check_texture_file(path)
    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None  # the budget below is the limit
        with Image.open(path) as im:
            width, height, mode = *im.size, im.mode
    except Exception:  # noqa: BLE001 - not an image Pillow knows: OpenCV may still read it
        width = height = 0
        mode = "RGB"
    finally:
        Image.MAX_IMAGE_PIXELS = old
    check_texture_budget(path, width, height, mode)
    try:
        img = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_ANYDEPTH)
    except cv2.error:  # e.g. a header declaring more than CV_IO_MAX_IMAGE_PIXELS (decompression bomb)
        raise InvalidInputError(f"texture {path} declares an absurd size or is corrupt (OpenCV refused it); "
                                "restore a sane image") from None
    if img is None:
        raise InvalidInputError(f"cannot decode texture {path}; convert it to PNG or JPEG")
    if img.dtype not in (np.uint8, np.uint16):
        img = np.clip(img, 0.0, 1.0) * 65535.0 if img.dtype.kind == "f" else img
        img = img.astype(np.uint16)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    else:
        cv2.cvtColor(img, cv2.COLOR_BGR2RGB, dst=img)
    return np.ascontiguousarray(img)


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


class PngWriter:
    """Write a PNG row strip by row strip (8 or 16 bits, 1-4 channels), atomically.

    Use as a context manager; the file appears under its final name only when all rows
    were written and the block exits without error. Rows are Paeth-filtered and deflated
    in a background thread (zlib-ng releases the GIL), so several writers fed strip by strip
    compress in parallel with the rendering.

    Parameters
    ----------
    path : path-like
    width, height : int
    channels : int
        1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA).
    px_per_mm : float or None
        Resolution stored in the ``pHYs`` chunk (pixels per metre), read by GIMP,
        Inkscape, QGIS and Pillow (as ``info["dpi"]``).
    bits : int
        8 or 16.
    """

    def __init__(self, path, width: int, height: int, channels: int, *, px_per_mm: float | None, bits: int = 8):
        if channels not in _PNG_COLOR_TYPE or bits not in (8, 16):
            raise ValueError("PNG needs 1-4 channels and 8 or 16 bits")
        self.path = Path(path)
        self.width, self.height, self.channels, self.bits = int(width), int(height), channels, bits
        self.px_per_mm = px_per_mm
        self._rows = 0
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> Self:
        tmp = self._stack.enter_context(atomic_path(self.path))
        self._fh = self._stack.enter_context(open(tmp, "wb"))
        large = self.width * self.height > PNG_LARGE_PIXELS
        self._z = zlib_ng.compressobj(PNG_COMPRESSION_LARGE if large else PNG_COMPRESSION)
        self._pool = self._stack.enter_context(ThreadPoolExecutor(1))
        self._pending = []
        self._prev = np.zeros(self.width * self.channels * self.bits // 8, np.uint8)
        ihdr = struct.pack(">IIBBBBB", self.width, self.height, self.bits, _PNG_COLOR_TYPE[self.channels], 0, 0, 0)
        head = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
        if self.px_per_mm:
            ppm = round(self.px_per_mm * 1000.0)
            head += _chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1))
        self._fh.write(head)
        return self

    def write(self, rows: np.ndarray) -> None:
        """Append rows: ``(k, width, channels)`` (or ``(k, width)`` for grey) uint8/uint16."""
        rows = np.asarray(rows)
        want = np.uint16 if self.bits == 16 else np.uint8
        if rows.dtype != want or rows.shape[1] != self.width or rows.reshape(len(rows), self.width, -1).shape[2] != self.channels:
            raise ValueError(f"rows must be (k, {self.width}, {self.channels}) {np.dtype(want).name}")
        if self._rows + len(rows) > self.height:
            raise ValueError("more rows than the image height")
        if not len(rows):
            return
        raw = rows.reshape(len(rows), -1)
        if self.bits == 16:
            raw = raw.astype(">u2").view(np.uint8).reshape(len(rows), -1)

        raw = np.require(raw, requirements=["C", "W"])  # one kernel signature (read-only rows: copied)
        filtered = np.empty((raw.shape[0], raw.shape[1] + 1), np.uint8)
        paeth_filter(raw, self._prev, self.channels * self.bits // 8, filtered)
        self._prev = raw[-1].copy()
        self._pending.append(self._pool.submit(self._z.compress, filtered))
        while len(self._pending) > PNG_QUEUE or (self._pending and self._pending[0].done()):
            self._write_idat(self._pending.pop(0).result())
        self._rows += len(rows)

    def _write_idat(self, data: bytes) -> None:
        if data:
            self._fh.write(_chunk(b"IDAT", data))

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            try:
                if self._rows != self.height:
                    raise ValueError(f"PNG {self.path}: {self._rows} of {self.height} rows written")
                for job in self._pending:
                    self._write_idat(job.result())
                self._write_idat(self._z.flush())
                self._fh.write(_chunk(b"IEND", b""))
                self._fh.flush()
                os.fsync(self._fh.fileno())
            except BaseException as err:
                self._stack.__exit__(type(err), err, err.__traceback__)
                raise
        return self._stack.__exit__(exc_type, exc, tb)


def write_png(path, image: np.ndarray, *, px_per_mm: float | None) -> Path:
    """Write a whole image as PNG with its resolution.

    Parameters
    ----------
    path : path-like
    image : (h, w) or (h, w, c) uint8 or uint16
    px_per_mm : float or None

    Returns
    -------
    Path
    """
    image = np.asarray(image)
    channels = 1 if image.ndim == 2 else image.shape[2]
    bits = 16 if image.dtype == np.uint16 else 8
    with PngWriter(path, image.shape[1], image.shape[0], channels, px_per_mm=px_per_mm, bits=bits) as png:
        step = max(1, (1 << 22) // max(1, image.shape[1] * channels))
        for r in range(0, image.shape[0], step):
            png.write(image[r:r + step])
    return Path(path)


def write_tiff_rows(path, rows: Iterable[np.ndarray], *, shape: tuple[int, ...], dtype, px_per_mm: float | None,
                    photometric: str, description: str | None = None) -> Path:
    """Write a TIFF (zlib-compressed) from an iterator of row strips, atomically.

    Parameters
    ----------
    path : path-like
    rows : iterable of (k, w[, c]) arrays
        Strips in top-to-bottom order, ``k`` rows each (any ``k``).
    shape : tuple
        ``(h, w)`` or ``(h, w, c)`` of the whole image.
    dtype : numpy dtype
    px_per_mm : float or None
        Stored as X/Y resolution in pixels per centimetre.
    photometric : str
        ``"rgb"`` or ``"minisblack"``.
    description : str, optional
        The ImageDescription tag (what the values mean, their scale).

    Returns
    -------
    Path
    """
    import tifffile

    tile = 256

    def tiles():
        # tifffile wants whole tiles in row-major order: regroup the strips into bands of
        # ``tile`` rows (incomplete edge tiles are zero-padded by tifffile)
        pending, have, done = [], 0, 0
        for strip in rows:
            pending.append(np.asarray(strip, dtype=dtype))
            have += len(pending[-1])
            while have >= tile or (have and done + have == shape[0]):
                band = np.concatenate(pending)
                head, rest = band[:tile], band[tile:]
                for c in range(0, shape[1], tile):
                    yield head[:, c:c + tile]
                done += len(head)
                pending, have = [rest], len(rest)

    kwargs = {}
    if px_per_mm:
        kwargs = {"resolution": (px_per_mm * 10.0, px_per_mm * 10.0), "resolutionunit": "CENTIMETER"}
    extrasamples = {"extrasamples": ("unassalpha",)} if photometric == "rgb" and len(shape) == 3 and shape[2] == 4 else {}
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, tiles(), shape=shape, dtype=dtype, photometric=photometric, tile=(tile, tile),
                         compression="zlib", compressionargs={"level": 1}, description=description,
                         metadata=None, **extrasamples, **kwargs)
    return Path(path)


class _Abandoned(Exception):
    """Raised into a :class:`TiffWriter`'s writing thread when the block around it failed."""


class TiffWriter:
    """Write a TIFF strip by strip as the strips come (:func:`write_tiff_rows` in a thread fed
    by :meth:`write`), atomically: the file appears under its final name only when all rows
    were written and the block exits without error.

    Parameters
    ----------
    path : path-like
    shape, dtype, px_per_mm, photometric, description
        As :func:`write_tiff_rows` takes them.
    """

    def __init__(self, path, *, shape: tuple[int, ...], dtype, px_per_mm: float | None, photometric: str,
                 description: str | None = None):
        self.path = Path(path)
        self._args = {"shape": tuple(shape), "dtype": dtype, "px_per_mm": px_per_mm, "photometric": photometric,
                      "description": description}
        self._rows = 0

    def __enter__(self) -> Self:
        import queue

        self._queue = queue.Queue(maxsize=PNG_QUEUE)
        self._pool = ThreadPoolExecutor(1)
        self._job = self._pool.submit(write_tiff_rows, self.path, self._strips(), **self._args)
        return self

    def _strips(self):
        while (item := self._queue.get()) is not None:
            if item is _Abandoned:
                raise _Abandoned
            yield item

    def _put(self, item) -> None:
        import queue

        while True:
            if self._job.done():  # the writer has all rows (the end needs no telling), or it failed
                self._job.result()
                if item is None:
                    return
                raise ValueError(f"TIFF {self.path}: the writer stopped after {self._rows} rows")
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def write(self, rows: np.ndarray) -> None:
        """Append rows ``(k, w[, c])`` (converted to the TIFF's dtype)."""
        rows = np.asarray(rows, dtype=self._args["dtype"])
        if rows.shape[1:] != self._args["shape"][1:] or self._rows + len(rows) > self._args["shape"][0]:
            raise ValueError(f"TIFF {self.path}: rows of shape {rows.shape} do not continue a {self._args['shape']} image")
        self._put(rows)
        self._rows += len(rows)

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if exc_type is None:
                if self._rows != self._args["shape"][0]:
                    self._abandon()
                    raise ValueError(f"TIFF {self.path}: {self._rows} of {self._args['shape'][0]} rows written")
                self._put(None)
                self._job.result()
            else:
                self._abandon()
        finally:
            self._pool.shutdown(wait=True)
        return False

    def _abandon(self) -> None:
        """Stop the writing thread (its temporary file is removed) and wait for it; its own
        error, if it had one, is not the one to report."""
        import queue

        while not self._job.done():
            try:
                self._queue.put(_Abandoned, timeout=0.1)
                break
            except queue.Full:
                continue
        try:
            self._job.result()
        except Exception:  # noqa: BLE001 - the block's error (or the row count) is reported
            pass


def read_mask(path: str | Path) -> np.ndarray:
    """A mask image as importance in [0, 1]: grey level times alpha (white opaque = 1).

    Returns
    -------
    (h, w) float32
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"importance mask {path} not found; give the PNG you painted (white = important)")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if img is None:
        raise InvalidInputError(f"cannot read importance mask {path}; save it as PNG")
    scale = 65535.0 if img.dtype == np.uint16 else 255.0 if img.dtype == np.uint8 else 1.0
    img = img.astype(np.float32) / scale
    if img.ndim == 2:
        return np.clip(img, 0.0, 1.0)
    grey = img[..., :3].mean(axis=2)
    if img.shape[2] == 4:
        grey = grey * img[..., 3]
    return np.clip(grey, 0.0, 1.0)


#: The grey image of a texture read for the seam keeps at least this many pixels along its
#: longer side: a texture up to twice as long is read whole, a longer one reduced by 2, 4 or 8
#: (OpenCV's reduced reads, which JPEG decodes at that size directly).
GREY_MIN_SIDE = 2048


def read_texture_grey(path: str | os.PathLike) -> np.ndarray | None:
    """A texture in grey levels, (h, w) uint8 reduced to keep at least :data:`GREY_MIN_SIDE`
    pixels along its longer side, or None when it cannot be read; taken from a
    :func:`read_ahead` of the same file when there is one."""
    ahead = _take_ahead("grey", path)
    return ahead.result() if ahead is not None else _decode_grey(path)


def _decode_grey(path: str | os.PathLike) -> np.ndarray | None:
    import cv2
    from PIL import Image

    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None  # only the header is read
        with Image.open(path) as im:
            side = max(im.size)
    except Exception:  # noqa: BLE001 - not an image Pillow knows: read it reduced as far as allowed
        side = 8 * GREY_MIN_SIDE
    finally:
        Image.MAX_IMAGE_PIXELS = old
    reduce = 1
    while reduce < 8 and side // (2 * reduce) >= GREY_MIN_SIDE:
        reduce *= 2
    flag = {1: cv2.IMREAD_GRAYSCALE, 2: cv2.IMREAD_REDUCED_GRAYSCALE_2, 4: cv2.IMREAD_REDUCED_GRAYSCALE_4,
            8: cv2.IMREAD_REDUCED_GRAYSCALE_8}[reduce]
    try:
        return cv2.imread(str(path), flag)
    except cv2.error:  # an absurd declared size: the texture's own read says so
        return None


_DECODERS = {"grey": _decode_grey, "rgb": _decode_texture}
#: Decodes started by :func:`read_ahead` and not taken yet, by (kind, file, its mtime, its size).
_AHEAD: dict[tuple, Future] = {}
_AHEAD_LOCK = threading.Lock()


def _ahead_key(kind: str, path: str | os.PathLike) -> tuple | None:
    try:
        stat = os.stat(path)
    except (OSError, TypeError, ValueError):  # missing: the reader itself says so, in the caller's thread
        return None
    return kind, os.path.realpath(path), stat.st_mtime_ns, stat.st_size


def _take_ahead(kind: str, path: str | os.PathLike) -> Future | None:
    if not _AHEAD:
        return None
    key = _ahead_key(kind, path)
    with _AHEAD_LOCK:
        return _AHEAD.pop(key, None)


@contextlib.contextmanager
def read_ahead(path: str | os.PathLike | None, *, grey: bool = False, rgb: bool = False):
    """Decode a texture in a background thread while the block does other work.

    The block's later :func:`read_texture_grey` (``grey``) and
    :func:`read_texture` (``rgb``) of the same, unchanged file take the decoded images
    instead of decoding (the decoders release the GIL, so the decoding runs beside the
    block's own work on a second core). The two are decoded one after the other, in that
    order; what the block did not take is dropped at its end (a decode still running
    finishes in its thread, and its result is freed). A decode already ahead for the file
    (an enclosing block) is left to that block. Errors reach the reader that takes the
    decode, as if it had decoded itself.

    Parameters
    ----------
    path : path-like or None
        The texture; None: nothing is read ahead.
    grey, rgb : bool
        Which reads to decode ahead.
    """
    wanted = [kind for kind, want in (("grey", grey), ("rgb", rgb)) if want and path is not None]
    keys = [key for key in (_ahead_key(kind, path) for kind in wanted) if key is not None]
    worker = None
    with _AHEAD_LOCK:
        keys = [key for key in keys if key not in _AHEAD]
        if keys:
            worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="potflat-read-ahead")
            for key in keys:
                _AHEAD[key] = worker.submit(_DECODERS[key[0]], path)
    try:
        yield
    finally:
        if worker is not None:
            with _AHEAD_LOCK:
                for key in keys:
                    _AHEAD.pop(key, None)
            worker.shutdown(wait=False, cancel_futures=True)
