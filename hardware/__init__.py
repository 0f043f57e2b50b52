"""hardware: the scanning rig (track, slider, rotation, power meter) through PyVISA."""
