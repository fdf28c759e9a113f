"""Layer 2: a model made into its flat copy, topology, symbolic program and layouts."""
