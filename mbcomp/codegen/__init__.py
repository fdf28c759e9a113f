"""Layer 4: generated code: printers, the C templates (c/), compilers and the code cache."""
