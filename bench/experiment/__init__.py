"""The experiment side of the bench: what a run is (:mod:`.spec`), how its objective is assembled
(:mod:`.objective`), running it (:mod:`.identify`, :mod:`.user_problems`, the surrogate track
:mod:`.surrogate_track`), suites of runs (:mod:`.suite`), running a suite (:mod:`.runner`) and
its records (:mod:`.store`). The report reads the records through :mod:`.store` only."""
