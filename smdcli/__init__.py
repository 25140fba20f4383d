"""smd: lumped spring-mass-damper systems, solved exactly where they can be.

Imports nothing (the version only), so `smd --help` stays fast.
"""

__version__ = "0.1.0"
