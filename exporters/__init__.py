"""One writer per format: URDF, MJCF, USD."""
