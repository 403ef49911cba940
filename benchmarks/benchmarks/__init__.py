"""steplab's asv benchmarks, one module per topic (the numpy/scipy layout).

- :mod:`.integrators` — the cost of one step, every fixed-step integrator x bodies x backend;
  the per-step cost of the compiled loop on one oscillator;
- :mod:`.forces` — force evaluation per force model: a scene pays only for what it declares;
- :mod:`.broadphase` — pair finding, method x n x distribution (time and peak memory);
- :mod:`.collisions` — a run with collisions, detector x scene;
- :mod:`.accuracy` — ``track_`` benchmarks: global error, fitted order, energy drift, so an
  accuracy regression shows in asv's history next to a speed one;
- :mod:`.ratios` — ``track_`` benchmarks: ``steplab bench``'s ratios (steplab / peer, both timed in
  the same run), one class per section, so a regression against a peer shows in asv's history
  (the cloth, rotation, stacking and crowded-pit ratios are in their own modules).

A JAX benchmark times one compiled call and nothing else: its inputs are device arrays made in
``setup``, where it is also compiled and run once, and the timed call waits for the result
with ``block_until_ready``. A combination
that cannot run (a module another part of steplab has not delivered yet, implicit Euler's
dense Jacobian at 10^5 bodies) raises ``NotImplementedError`` in ``setup``, which asv
records as skipped.
"""
