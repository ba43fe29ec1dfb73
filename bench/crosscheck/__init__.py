"""Cross-check of femubench's linear Drucker-Prager form (K = 1) against OpenSees
(``femubench crosscheck``; results and discussion: ``docs/crosscheck_opensees.md``).

Modules, one job each:

* :mod:`~bench.crosscheck.mapping` — the parameter mapping and OpenSees's model re-derived in numpy
  (pure);
* :mod:`~bench.crosscheck.reference` — femubench's answers, the uniaxial closed form, difference
  measures;
* :mod:`~bench.crosscheck.loader` — importing openseespy (the optional ``crosscheck`` extra);
* :mod:`~bench.crosscheck.opensees_box` — the plate test in OpenSees and its solution strategies;
* :mod:`~bench.crosscheck.single_element`, :mod:`~bench.crosscheck.cube`,
  :mod:`~bench.crosscheck.tangent` — the three comparisons;
* :mod:`~bench.crosscheck.study` — the run writing ``opensees_dp.json``;
  :mod:`~bench.crosscheck.report` — its JSON form and printed tables;
* :mod:`~bench.crosscheck.figures` — the figures, drawn from ``opensees_dp.json`` alone.

Importing any of them does not import openseespy.
"""
