"""Synthetic painted vessels with known geometry, for tests, samples and benchmarks.

Installed as ``potflat_synthetic`` (the folder ``synthetic/``); the library (``potflat``) never imports it.
"""
