import importlib

import potflat


def test_every_lazy_export_resolves():
    for name, module in potflat._LAZY.items():
        assert getattr(potflat, name) is getattr(importlib.import_module(module), name)


def test_unknown_attribute_is_an_attribute_error():
    import pytest

    with pytest.raises(AttributeError):
        potflat.no_such_thing  # noqa: B018


def test_stage_modules_are_not_shadowed_by_functions():
    import potflat.rollout

    assert potflat.rollout.rollout is importlib.import_module("potflat.rollout").rollout
    assert "rollout" not in potflat._LAZY


def test_a_face_naming_a_missing_vertex_is_one_clear_error():
    """Face indices are checked where a mesh is made, before any kernel indexes with them."""
    import numpy as np
    import pytest

    from potflat.errors import InvalidInputError
    from potflat.types import Mesh

    V = np.zeros((4, 3))
    for bad, named in (([[0, 1, 2], [1, 3, 4]], "vertex 4"), ([[0, 1, -1]], "vertex -1")):
        with pytest.raises(InvalidInputError, match=f"{named}, but there are 4 vertices") as e:
            Mesh(V, bad, source="scan.ply")
        assert str(e.value).startswith("scan.ply: ") and len(str(e.value).splitlines()) == 1
    assert len(Mesh(V, [[0, 1, 3]]).faces) == 1
    assert len(Mesh(V, np.zeros((0, 3), np.int64)).faces) == 0
