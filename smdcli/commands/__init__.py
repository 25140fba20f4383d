"""Commands: the library entry points behind each `smd` command (simulate, sweep, compare, phase, draw,
animate, diff): validate everything first, run, write. cli.py parses arguments and calls these.

Must not import: cli.
"""
