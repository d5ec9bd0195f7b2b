"""Import-time JAX configuration of the planning side: float64 everywhere.

Planning needs float64: a 1 h job at 100 kHz has 3.6e8 ticks and µm positions on metre-long
axes. Every planning module imports this module before using JAX. The player side
(:mod:`jaxcnc.hw`) never imports it.
"""

import jax

jax.config.update("jax_enable_x64", True)

__all__ = ["jax"]
