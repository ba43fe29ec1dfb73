"""The experiment side of the bench: how a run's objective is assembled (:mod:`.objective`)."""
