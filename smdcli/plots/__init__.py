"""Figures from results, one module per figure family: response (time and phase portraits), compare
(work-precision, stability), sweep (overlays, metrics, heat maps, frequency responses), schematic.

Plot functions return a Figure; only common.save_figure touches disk. Must not import: commands, cli.
"""
