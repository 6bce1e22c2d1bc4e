"""Numba kernels of the file formats: arrays in, arrays out, no I/O. Private to potflat."""
