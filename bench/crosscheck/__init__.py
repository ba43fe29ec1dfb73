"""Cross-checks of femubench's FE model and materials against other codes (scripts, not tests)."""
