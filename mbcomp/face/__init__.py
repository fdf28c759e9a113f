"""Layer 10: what people see: the command line, plots, animations and the 3D viewer."""
