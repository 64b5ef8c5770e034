"""Iterative ray tracing photometric stereo: the loop, its passes, the paper's estimator, reconstruct."""
