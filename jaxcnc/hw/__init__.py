"""The controller side: the player and its sinks; tables are read with :mod:`jaxcnc.format`.

Nothing here imports JAX, SciPy, matplotlib or the planning side: a controller that only plays
tables needs NumPy and the standard library (``docs/player.md``: the player-only install).
"""
