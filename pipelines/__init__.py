"""Pipeline stages, one module each; they depend on `assets` only."""
