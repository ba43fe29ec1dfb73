"""femubench.problems: the forward model (FE cube test, materials), measurement, DIC and the
objective.

Units everywhere: N, mm, MPa (stress), s. Angles of material parameters in degrees.
"""
