"""Scenes with nonsmooth elements, event to event: which method takes them (drivers.py); the scene in one mode and
its guards (scene.py, smooth_scene.py); the decisions at an event (decisions.py); the exact event-driven solver
(piecewise.py, batches.py, crossings.py, record.py); the integrators stepped mode by mode (integrated.py,
compiled_modes.py); the Newmark family's return mapping (return_mapping.py).

Must not import: sweep, io, plots, commands, cli.
"""
