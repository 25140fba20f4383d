"""Compiled arithmetic (numba): forces, right-hand sides, Jacobians and integrators over the arrays of
smdcli.kernels.arrays. Importing this package imports nothing; each module imports numba itself.

Must not import: solvers, sweep, io, plots, commands, cli.
"""
