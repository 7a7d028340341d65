"""Identification of the rig's damper models from recorded runs.

Modules: :mod:`.kernels` (compiled simulators), :mod:`.data` (records and their checks),
:mod:`.rig_models` (per-model parameters, bounds, regressors), :mod:`.fit` (global + local
stages, two-stage option, uncertainties), :mod:`.report` (tables, parameter file, plots),
:mod:`.synthetic` (drop tests from the simulated rig), :mod:`.boucwen_benchmark`
(Noel & Schoukens 2016 oscillator) and :mod:`.friction` (the friction damper of seed 000).
"""
