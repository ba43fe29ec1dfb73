"""Reading and writing: the one JSON encoding of numbers every file of femubench uses (jsonio),
atomic writes (atomic), TOML input files (tomlio)."""
