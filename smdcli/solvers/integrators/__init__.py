"""Step-by-step methods: the compiled Runge-Kutta, Rosenbrock, Radau and BDF families (compiled.py), scipy's classes
driven from Python (scipy_driven.py, stiff23.py), the fixed-step structural family (fixed_step.py), the Taylor
series (taylor_series.py) and Newmark on sparse matrices (sparse_newmark.py).

Must not import: sweep, io, plots, commands, cli.
"""
