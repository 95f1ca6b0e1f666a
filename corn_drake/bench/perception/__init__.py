"""The perception benchmarks: frames/s of the camera chain and ICP tracking error."""
