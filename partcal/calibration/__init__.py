"""Kinematic calibration: the robot's parameters identified from measurements of any type.

The parameter table (:mod:`.parameters`), the chain's derivatives (:mod:`.chain`), what the data can identify
(:mod:`.identifiability`), the fit (:mod:`.fit`), priors, joint errors, experiment design, and the measurement
types (one module each, their table in :mod:`.registry`) identified together (:mod:`.stacked`).
"""
