"""Layer 1: what users write: components, the Model builder, sub-models and shapes."""
