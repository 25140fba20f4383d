"""Analyses on top of the solvers: functions that take a record, a Model or a Result and return arrays.

Must not import: commands, io, plots, cli.
"""
