"""Numba kernels: arrays in, arrays out, no I/O. Private to potflat."""
