"""Layer 0: plain data and helpers without model knowledge (errors, rotations, parameters, Result, limits, names, tolerances)."""
