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
