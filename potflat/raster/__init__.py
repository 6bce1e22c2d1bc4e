"""The rasteriser and texture sampler: a flattening drawn in a true-scale pixel grid, strip
by strip (its painting, coverage and any per-vertex or per-face field), below the stages that
draw (the painted zone's detection in the rollout, the bake)."""
