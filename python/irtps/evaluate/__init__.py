"""The comparison table of methods against ground truth (the errors themselves: `irtps.model.metrics`)."""
