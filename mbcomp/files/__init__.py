"""Layer 3: model files (TOML, URDF) read and written, and the library of models."""
