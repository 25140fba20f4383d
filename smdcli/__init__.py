"""smd: lumped spring-mass-damper systems, solved exactly where they can be."""

__version__ = "0.1.0"
