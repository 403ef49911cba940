"""The lowest layer: what every other layer may import, and which imports nothing else of steplab.

- :mod:`.registry`: :class:`~.registry.Registry`, the one kind of registry (integrators,
  forces, detectors, collision methods, broadphase methods, engines, scenes, studies), each
  with its entry-point group ``steplab.<kind>``;
- :mod:`.records`: the atomic writer every record and figure goes through;
- :mod:`.timing`: the one timer of the studies and the bench.
"""
