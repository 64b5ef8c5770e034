"""Photometric stereo: the fit, its robust statistics, the images' agreement with it."""
