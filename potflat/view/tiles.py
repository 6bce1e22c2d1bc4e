"""Deep-zoom tiles of a run's images: the painting and each distortion map, as Deep Zoom
(DZI) pyramids made on demand in memory from the bake's PNGs (nothing is written).

Level ``L`` of a DZI pyramid is the image scaled by ``2 ** (L - top)``, ``top`` the level at
full size (``ceil(log2(longest side))``); each level is cut into :data:`TILE` pixel tiles.
A distortion map's PNG holds its legend below the image: the tiles take the image's rows,
:meth:`Layer.legend` the rest.
"""
from __future__ import annotations

import io
import math
import threading
from pathlib import Path

#: Side of a tile, pixels.
TILE = 512
#: Longest side of the image the 3D view wraps around the vessel: an overview (the flat view
#: has every pixel); a smaller texture is decoded and uploaded sooner on a software renderer.
TEXTURE_PX = 2048
#: Longest side of the scan's own texture in the 3D view (a scan's atlas is finer than the
#: flattening's overview: its pixels are spread over the whole scan, in charts).
SCAN_TEXTURE_PX = 4096


class Layer:
    """One image of a run (``NAME.png`` or ``NAME.<map>.png``) cut into tiles.

    Parameters
    ----------
    path : Path
        The PNG.
    width, height : int
        The image's size (the bake's grid); rows below it (a map's legend) are the legend.
    """

    def __init__(self, path: Path, width: int, height: int):
        self.path, self.width, self.height = Path(path), int(width), int(height)
        self.top = max(0, math.ceil(math.log2(max(self.width, self.height, 1))))
        self._levels: dict[int, object] = {}
        self._legend = None
        self._texture: bytes | None = None
        self._lock = threading.Lock()

    def _full(self):
        from PIL import Image

        with Image.open(self.path) as img:
            img.load()
            full = img.convert("RGBA")
        if full.height > self.height:
            self._legend = full.crop((0, self.height, full.width, full.height))
        return full.crop((0, 0, self.width, self.height)) if full.size != (self.width, self.height) else full

    def level(self, level: int):
        """The image at pyramid ``level`` (a PIL image), made from the next finer level."""
        from PIL import Image

        with self._lock:
            if not self._levels:
                self._levels[self.top] = self._full()
            finer = max(k for k in self._levels if k >= level)
            img = self._levels[finer]
            for k in range(finer - 1, level - 1, -1):
                if k not in self._levels:
                    self._levels[k] = img.resize((max(1, math.ceil(img.width / 2)), max(1, math.ceil(img.height / 2))),
                                                 Image.Resampling.BOX)
                img = self._levels[k]
            return img

    def dzi(self) -> str:
        """The DZI descriptor (XML)."""
        return ('<?xml version="1.0" encoding="UTF-8"?>'
                f'<Image xmlns="http://schemas.microsoft.com/deepzoom/2008" Format="png" Overlap="0" '
                f'TileSize="{TILE}"><Size Width="{self.width}" Height="{self.height}"/></Image>')

    def tile(self, level: int, column: int, row: int) -> bytes | None:
        """The PNG bytes of one tile, None when there is no such tile."""
        if not 0 <= level <= self.top:
            return None
        img = self.level(level)
        x0, y0 = column * TILE, row * TILE
        if column < 0 or row < 0 or x0 >= img.width or y0 >= img.height:
            return None
        return _png(img.crop((x0, y0, min(x0 + TILE, img.width), min(y0 + TILE, img.height))))

    def legend(self) -> bytes | None:
        """The PNG bytes of the legend below a map (None for the painting)."""
        self.level(self.top)
        return None if self._legend is None else _png(self._legend)

    def texture(self) -> bytes:
        """The image at most :data:`TEXTURE_PX` on its longest side, as JPEG on white (the 3D
        view's texture; made once)."""
        if self._texture is not None:
            return self._texture
        level = self.top - max(0, math.ceil(math.log2(max(self.width, self.height) / TEXTURE_PX)))
        self._texture = _jpeg(self.level(level))
        return self._texture


def texture_jpeg(path: Path, longest: int = SCAN_TEXTURE_PX) -> bytes:
    """A scan's texture image (:func:`potflat.io.images.read_texture`) at most ``longest``
    pixels on its longest side, as JPEG (the whole scan's texture in the 3D view)."""
    import cv2
    import numpy as np
    from PIL import Image

    from potflat.io.images import read_texture

    rgb = read_texture(path)
    if rgb.dtype == np.uint16:
        rgb = (rgb >> 8).astype(np.uint8)
    scale = longest / max(rgb.shape[:2])
    if scale < 1.0:
        rgb = cv2.resize(rgb, (max(1, round(rgb.shape[1] * scale)), max(1, round(rgb.shape[0] * scale))),
                         interpolation=cv2.INTER_AREA)
    return _jpeg(Image.fromarray(np.ascontiguousarray(rgb)).convert("RGBA"))


def _jpeg(img) -> bytes:
    """JPEG bytes of an RGBA image over white."""
    from PIL import Image

    flat = Image.new("RGB", img.size, (255, 255, 255))
    flat.paste(img, mask=img.getchannel("A"))
    buf = io.BytesIO()
    flat.save(buf, format="JPEG", quality=90)
    return buf.getvalue()


def _png(img) -> bytes:
    buf = io.BytesIO()
    img.save(buf, format="PNG", compress_level=1)
    return buf.getvalue()
