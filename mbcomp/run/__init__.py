"""Layer 7: time stepping, contact events, sweeps and derived series."""
