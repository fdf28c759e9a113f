"""Layer 9: the public System facade."""
