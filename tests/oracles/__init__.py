"""Independent numpy implementations the compiled kernels are tested against."""
