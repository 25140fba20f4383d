"""Solutions in closed form and by the matrix exponential: linear scenes exactly, sample to sample (linear.py),
in modal coordinates (modal.py), by the exponential's action (action.py), harmonic steady states (harmonic.py),
the 1-DOF free response (closed_form.py), and the exact flow of one linear mode (flow.py) the event solver steps on.

Must not import: sweep, io, plots, commands, cli.
"""
