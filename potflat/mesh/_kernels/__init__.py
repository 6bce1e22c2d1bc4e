"""Numba kernels of the mesh operations: arrays in, arrays out, no I/O. Private to potflat."""
