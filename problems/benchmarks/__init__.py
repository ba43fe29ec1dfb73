"""Standard problem families with certified or community reference answers (NIST StRD, ...)."""
