"""femubench.solvers: one interface over local, global and sampling methods."""
