"""Mesh operations shared by the stages: cleaning, distortion measures and their kernels."""
