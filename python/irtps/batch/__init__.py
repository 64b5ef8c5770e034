"""Many data sets on a Dask cluster."""
