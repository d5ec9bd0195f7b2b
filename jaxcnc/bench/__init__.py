"""The benchmarks behind ``jaxcnc bench``: each suite prints its figures beside its peers, measured in the same run."""
