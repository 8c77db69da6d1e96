"""One-off measurements behind figures in the docs; not installed with the package (see README.md here)."""
