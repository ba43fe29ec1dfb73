"""Standard test problems as user problems (:mod:`problems.user`): BBOB through ``cocoex``
(:mod:`problems.benchmarks.bbob`) and NIST StRD nonlinear regression."""
