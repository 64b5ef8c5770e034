"""Light calibration: each light's direction and strength from a capture of a mirror (chrome)
sphere and a matte sphere (`irtps.calibrate.lights.calibrate_lights`, ``irtps calibrate``)."""
