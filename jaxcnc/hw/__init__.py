"""The controller side: the table file format, the player and its sinks.

Nothing here imports JAX or the planning side: a controller that only plays tables needs
NumPy and the standard library.
"""
