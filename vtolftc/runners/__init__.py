"""Layer 4, the runners: what wires an autopilot to a vehicle and flies it.

:mod:`.scenario` (in-process flights), :mod:`.sitl` and :mod:`.processes` (the two SITL
processes), :mod:`.mission_run` / :mod:`.mission_sitl` (missions), :mod:`.campaign` (fault
envelopes on a pool or Dask) and :mod:`.certify` (``vtolftc certify``).
"""
