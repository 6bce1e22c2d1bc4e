"""Image files of the bake stage: streamed PNG encoder, TIFF writer, texture reader."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import tifffile
from PIL import Image

from potflat.errors import InvalidInputError
from potflat.io import images
from potflat.io.images import (PngWriter, TiffWriter, read_ahead, read_texture, read_texture_grey,
                               write_png, write_tiff_rows)


def _paeth_reference(raw, prev, bpp):
    out = np.zeros((raw.shape[0], raw.shape[1] + 1), np.uint8)
    for r in range(raw.shape[0]):
        above = prev if r == 0 else raw[r - 1]
        out[r, 0] = 4
        for x in range(raw.shape[1]):
            a = int(raw[r, x - bpp]) if x >= bpp else 0
            b = int(above[x])
            c = int(above[x - bpp]) if x >= bpp else 0
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            pred = a if pa <= pb and pa <= pc else b if pb <= pc else c
            out[r, x + 1] = (int(raw[r, x]) - pred) % 256
    return out


def test_paeth_kernel_matches_reference():
    from potflat.io._kernels.ply_png import paeth_filter

    rng = np.random.default_rng(0)
    raw = rng.integers(0, 256, (5, 24), dtype=np.uint8)
    prev = rng.integers(0, 256, 24, dtype=np.uint8)
    out = np.empty((5, 25), np.uint8)
    paeth_filter(raw, prev, 4, out)
    assert np.array_equal(out, _paeth_reference(raw, prev, 4))


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_png_roundtrip_with_resolution(tmp_path, channels, dtype):
    rng = np.random.default_rng(channels)
    shape = (37, 53) if channels == 1 else (37, 53, channels)
    img = rng.integers(0, np.iinfo(dtype).max, shape).astype(dtype)
    write_png(tmp_path / "a.png", img, px_per_mm=11.811)
    back = cv2.imread(str(tmp_path / "a.png"), cv2.IMREAD_UNCHANGED)
    if channels == 3:
        back = back[..., ::-1]
    elif channels == 4:
        back = cv2.cvtColor(back, cv2.COLOR_BGRA2RGBA)
    if channels == 2:  # OpenCV has no grey+alpha: check the 8-bit case with Pillow
        if dtype == np.uint8:
            assert np.array_equal(np.asarray(Image.open(tmp_path / "a.png")), img)
    else:
        assert back.dtype == dtype and np.array_equal(back, img)
    assert Image.open(tmp_path / "a.png").info["dpi"] == pytest.approx((300.0, 300.0), abs=0.01)


def test_png_written_in_strips_equals_whole(tmp_path):
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (50, 20, 4), dtype=np.uint8)
    with PngWriter(tmp_path / "s.png", 20, 50, 4, px_per_mm=4) as png:
        for r in range(0, 50, 7):
            png.write(img[r:r + 7])
    assert np.array_equal(np.asarray(Image.open(tmp_path / "s.png")), img)


def test_incomplete_png_leaves_no_file(tmp_path):
    with pytest.raises(ValueError, match="rows written"), PngWriter(tmp_path / "x.png", 10, 10, 4, px_per_mm=1) as png:
        png.write(np.zeros((5, 10, 4), np.uint8))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError), PngWriter(tmp_path / "y.png", 10, 10, 4, px_per_mm=1) as png:
        png.write(np.zeros((5, 10, 4), np.uint8))
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_png_rejects_wrong_rows(tmp_path):
    with pytest.raises(ValueError, match="rows must be"), PngWriter(tmp_path / "z.png", 10, 10, 4, px_per_mm=1) as png:
        png.write(np.zeros((5, 9, 4), np.uint8))


@pytest.mark.parametrize("shape", [(40, 30, 3), (300, 520, 3), (513, 10, 4)])
def test_tiff_from_strips(tmp_path, shape):
    rng = np.random.default_rng(2)
    img = rng.random(shape).astype(np.float32)
    write_tiff_rows(tmp_path / "t.tif", (img[r:r + 7] for r in range(0, shape[0], 7)), shape=shape,
                    dtype=np.float32, px_per_mm=4.0, photometric="rgb")
    with tifffile.TiffFile(tmp_path / "t.tif") as tif:
        assert np.array_equal(tif.asarray(), img)
        page = tif.pages[0]
        assert page.tags["ResolutionUnit"].value == 3  # centimetre
        num, den = page.tags["XResolution"].value
        assert num / den == pytest.approx(40.0)


@pytest.mark.parametrize("shape", [(300, 520), (513, 10)])
def test_tiff_written_as_strips_come(tmp_path, shape):
    """The strips handed to a TiffWriter one by one (as the bake renders them) make the image,
    with its description."""
    img = np.random.default_rng(3).integers(0, 65535, shape, dtype=np.uint16)
    with TiffWriter(tmp_path / "t.tif", shape=shape, dtype=np.uint16, px_per_mm=4.0, photometric="minisblack",
                    description="heights") as tif:
        for r in range(0, shape[0], 37):
            tif.write(img[r:r + 37])
    with tifffile.TiffFile(tmp_path / "t.tif") as f:
        assert np.array_equal(f.asarray(), img) and f.pages[0].description == "heights"


def test_tiff_interrupted_leaves_no_file(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with TiffWriter(tmp_path / "t.tif", shape=(600, 40), dtype=np.uint16, px_per_mm=None,
                        photometric="minisblack") as tif:
            tif.write(np.zeros((300, 40), np.uint16))
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_tiff_short_of_rows_leaves_no_file(tmp_path):
    with pytest.raises(ValueError, match="100 of 600 rows"):
        with TiffWriter(tmp_path / "t.tif", shape=(600, 40), dtype=np.uint16, px_per_mm=None,
                        photometric="minisblack") as tif:
            tif.write(np.zeros((100, 40), np.uint16))
    assert list(tmp_path.iterdir()) == []


def test_tiff_refuses_rows_of_another_width(tmp_path):
    with pytest.raises(ValueError, match="do not continue"):
        with TiffWriter(tmp_path / "t.tif", shape=(600, 40), dtype=np.uint16, px_per_mm=None,
                        photometric="minisblack") as tif:
            tif.write(np.zeros((10, 41), np.uint16))
    assert list(tmp_path.iterdir()) == []


def test_read_texture_rgb_order_and_errors(tmp_path):
    img = np.zeros((4, 6, 3), np.uint8)
    img[..., 2] = 255  # red in BGR
    cv2.imwrite(str(tmp_path / "red.png"), img)
    tex = read_texture(tmp_path / "red.png")
    assert tex.shape == (4, 6, 3) and tuple(tex[0, 0]) == (255, 0, 0)
    cv2.imwrite(str(tmp_path / "grey16.png"), np.full((3, 3), 40000, np.uint16))
    g = read_texture(tmp_path / "grey16.png")
    assert g.dtype == np.uint16 and g.shape == (3, 3, 3) and (g == 40000).all()
    with pytest.raises(InvalidInputError, match="not found"):
        read_texture(tmp_path / "missing.png")
    (tmp_path / "bad.png").write_bytes(b"not an image")
    with pytest.raises(InvalidInputError, match="cannot decode"):
        read_texture(tmp_path / "bad.png")


def _noise_png(path, h, w, seed=0):
    cv2.imwrite(str(path), np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8))


def test_reads_inside_a_read_ahead_take_its_decodes(tmp_path):
    _noise_png(tmp_path / "t.png", 64, 48)
    plain, grey = read_texture(tmp_path / "t.png"), read_texture_grey(tmp_path / "t.png")
    with read_ahead(tmp_path / "t.png", grey=True, rgb=True):
        assert len(images._AHEAD) == 2
        with read_ahead(tmp_path / "t.png", rgb=True):  # an inner block leaves the outer one's decode alone
            assert len(images._AHEAD) == 2
        assert len(images._AHEAD) == 2
        assert np.array_equal(read_texture_grey(tmp_path / "t.png"), grey)
        assert np.array_equal(read_texture(tmp_path / "t.png"), plain)
        assert not images._AHEAD  # taken: a second read decodes again
        assert np.array_equal(read_texture(tmp_path / "t.png"), plain)


@pytest.mark.parametrize("width,reduced", [(1000, 1000), (4095, 4095), (4096, 2048), (9000, 2250), (40000, 5000)])
def test_the_grey_texture_keeps_its_detail_up_to_a_size(tmp_path, width, reduced):
    """The seam's grey image: whole up to twice GREY_MIN_SIDE, reduced by 2, 4 or 8 beyond."""
    cv2.imwrite(str(tmp_path / "t.png"), np.full((8, width), 200, dtype=np.uint8))
    grey = read_texture_grey(tmp_path / "t.png")
    assert images.GREY_MIN_SIDE == 2048 and grey.dtype == np.uint8
    assert grey.shape[1] == reduced and (grey == 200).all()


def test_a_read_ahead_not_taken_is_dropped_at_the_block_end(tmp_path):
    _noise_png(tmp_path / "t.png", 16, 16)
    with read_ahead(tmp_path / "t.png", rgb=True):
        assert len(images._AHEAD) == 1
    assert not images._AHEAD
    with read_ahead(None, rgb=True), read_ahead(tmp_path / "missing.png", rgb=True):
        assert not images._AHEAD  # nothing to read ahead: the reader reports a missing file itself


def test_a_texture_changed_after_its_read_ahead_is_read_anew(tmp_path):
    _noise_png(tmp_path / "t.png", 16, 16)
    with read_ahead(tmp_path / "t.png", rgb=True):
        _noise_png(tmp_path / "t.png", 20, 12, seed=1)
        assert read_texture(tmp_path / "t.png").shape == (20, 12, 3)


def test_a_read_ahead_of_a_bad_texture_reports_like_a_plain_read(tmp_path):
    (tmp_path / "bad.png").write_bytes(b"not an image")
    with read_ahead(tmp_path / "bad.png", rgb=True), pytest.raises(InvalidInputError, match="cannot decode"):
        read_texture(tmp_path / "bad.png")
