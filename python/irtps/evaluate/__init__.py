"""Errors against ground truth, and the comparison table."""
