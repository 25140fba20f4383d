"""Writers: atomic files (atomic.py, the one helper every writer uses), output folders, HDF5 layouts.

Writers only read results. Must not import: commands, cli.
"""
