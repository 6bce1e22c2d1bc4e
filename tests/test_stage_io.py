import dataclasses

import numpy as np
import pytest

from potflat.errors import InvalidInputError
from potflat.io.flat_ply import as_stored, read_flat_ply, write_flat_ply
from potflat.types import FlatMesh, Mesh


def _flat(tmp_path, with_texture=True, with_colors=False, stress=False):
    rng = np.random.default_rng(0)
    V = rng.normal(size=(5, 3))
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    tex = None
    tc = None
    if with_texture:
        from PIL import Image

        tex = tmp_path / "src" / "atlas.png"
        tex.parent.mkdir()
        Image.new("RGB", (4, 4), (10, 20, 30)).save(tex)
        tc = rng.uniform(size=(3, 3, 2))
    colors = rng.integers(0, 255, size=(5, 3)) if with_colors else None
    mesh = Mesh(V, F, texcoords=tc, texture_path=tex, vertex_colors=colors, units="cm")
    return FlatMesh(mesh, rng.normal(size=(5, 2)), stress=rng.uniform(size=5) if stress else None)


@pytest.mark.parametrize("with_texture,with_colors,stress", [(True, False, False), (False, True, True)])
def test_round_trip(tmp_path, with_texture, with_colors, stress):
    flat = _flat(tmp_path, with_texture, with_colors, stress)
    out = tmp_path / "out" / "x.rollout.ply"
    write_flat_ply(out, flat, comments=("made by test",))
    back = read_flat_ply(out)
    np.testing.assert_array_equal(back.mesh.vertices, flat.mesh.vertices)
    np.testing.assert_array_equal(back.uv, flat.uv)
    np.testing.assert_array_equal(back.mesh.faces, flat.mesh.faces)
    assert back.mesh.units == "cm"
    if with_texture:
        np.testing.assert_allclose(back.mesh.texcoords, flat.mesh.texcoords, atol=1e-7)
        assert back.mesh.texture_path == (out.parent / "x.texture.png").resolve()  # NAME.texture.EXT
        assert back.mesh.texture_path.read_bytes() == flat.mesh.texture_path.read_bytes()
    if with_colors:
        np.testing.assert_array_equal(back.mesh.vertex_colors, flat.mesh.vertex_colors)
    if stress:
        np.testing.assert_array_equal(back.stress, flat.stress)
    assert "made by test" in back.comments
    assert not list(out.parent.glob("*.part"))


@pytest.mark.parametrize("with_texture,with_colors,stress", [(True, False, False), (False, True, True)])
def test_as_stored_is_what_the_file_reads_back(tmp_path, with_texture, with_colors, stress):
    flat = _flat(tmp_path, with_texture, with_colors, stress)
    importance = np.linspace(0.0, 1.0, len(flat.uv)) if stress else None
    flat = flat.replace(comments=("from the scan", ""), importance=importance)
    out = tmp_path / "out" / "x.rollout.ply"
    write_flat_ply(out, flat, comments=("made by test", "two\nlines"))
    back, stored = read_flat_ply(out), as_stored(flat, out, comments=("made by test", "two\nlines"))
    for name in ("vertices", "faces", "texcoords", "vertex_colors"):
        a, b = getattr(back.mesh, name), getattr(stored.mesh, name)
        assert (a is None and b is None) or (a.dtype == b.dtype and np.array_equal(a, b)), name
    assert back.uv.tobytes() == stored.uv.tobytes()
    assert (back.stress is None) == (stored.stress is None)
    if stress:
        assert back.stress.tobytes() == stored.stress.tobytes()
        assert back.importance.tobytes() == stored.importance.tobytes()
    assert (back.importance is None) == (stored.importance is None)
    assert {f.name for f in dataclasses.fields(FlatMesh)} == {"mesh", "uv", "stress", "comments", "importance"}
    assert (back.mesh.texture_path, back.mesh.units, back.mesh.source) == (
        stored.mesh.texture_path, stored.mesh.units, stored.mesh.source)
    assert back.comments == stored.comments == ("from the scan", "", "made by test")


def test_as_stored_shares_texture_coordinates_already_at_the_files_precision(tmp_path):
    flat = _flat(tmp_path, True)
    (tmp_path / "out").mkdir()
    first = as_stored(flat, tmp_path / "out" / "x.rollout.ply")  # rounded to float32: a new array
    assert first.mesh.texcoords is not flat.mesh.texcoords
    assert not np.array_equal(first.mesh.texcoords, flat.mesh.texcoords)
    second = as_stored(first, tmp_path / "out" / "x.relaxed.ply")  # nothing to round: the same array
    assert second.mesh.texcoords is first.mesh.texcoords


def test_float32_exactness_matches_numpy():
    from potflat.io._kernels.ply_png import float32_exact

    rng = np.random.default_rng(2)
    stored = rng.random(50).astype(np.float32).astype(np.float64)
    for extra in ([], [np.inf, -np.inf, 0.0, -0.0, 1e-40], [0.1], [np.nan], [1e300], [1e-46], [2.0 ** -149]):
        values = np.concatenate([stored, extra])
        with np.errstate(over="ignore"):  # (1e300 -> inf)
            want = np.array_equal(values.astype(np.float32).astype(np.float64), values)
        assert float32_exact(values) == want, extra


def test_truncated_file_is_rejected(tmp_path):
    out = tmp_path / "x.rollout.ply"
    write_flat_ply(out, _flat(tmp_path))
    out.write_bytes(out.read_bytes()[:-10])
    with pytest.raises(InvalidInputError, match="truncated"):
        read_flat_ply(out)


def test_not_a_ply_is_rejected(tmp_path):
    bad = tmp_path / "x.rollout.ply"
    bad.write_text("hello")
    with pytest.raises(InvalidInputError, match="not a PLY"):
        read_flat_ply(bad)


def test_failed_write_leaves_previous_file(tmp_path, monkeypatch):
    out = tmp_path / "x.rollout.ply"
    write_flat_ply(out, _flat(tmp_path))
    before = out.read_bytes()
    flat = _flat(tmp_path / "b" if (tmp_path / "b").mkdir() is None else tmp_path)

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr("os.fsync", boom)
    with pytest.raises(RuntimeError):
        write_flat_ply(out, flat)
    assert out.read_bytes() == before
    assert not list(tmp_path.glob("*.part"))


def test_outputs_get_normal_permissions(tmp_path):
    import os
    import stat

    out = tmp_path / "x.rollout.ply"
    write_flat_ply(out, _flat(tmp_path))
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~mask
