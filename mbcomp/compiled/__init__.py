"""Layer 5: the compiled model and its numeric kernel."""
